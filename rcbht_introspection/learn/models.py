"""Sub-task classifiers (SVM as in the paper, our Mondrian forest) and their safe model files.

A model file is a NumPy .npz read with allow_pickle=False: a JSON header (format version,
classifier, encoding with its fitted parameters, class names, taxonomy profile, SHA-256 of all
content) and plain arrays. The SVM pipeline is stored with skops and loaded with an explicit
trusted-type list, the Mondrian forest as its node arrays. Loading never executes code.
"""

from __future__ import annotations

import hashlib
import json
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.axes import AxisMemo
from rcbht_introspection.grammar.encoding.cache import SampleCache
from rcbht_introspection.grammar.encoding.compact import CompactEncoding
from rcbht_introspection.grammar.encoding.paper import PaperEncoding
from rcbht_introspection.grammar.encoding.registry import encoding_from_state, make_encoding
from rcbht_introspection.grammar.split import SubtaskSample, prefix_sample
from rcbht_introspection.io.trial import SUBTASKS
from rcbht_introspection.learn import CLASSIFIERS
from rcbht_introspection.learn.mondrian import (
    FEATURE_DTYPE,
    NO_NODE,
    MondrianForestClassifier,
    _NodePool,
)

FORMAT = "rcbht-subtask-model"
FORMAT_VERSION = 1
TUNING_GRID: dict[str, list[float]] = {
    "C": [0.1, 1.0, 10.0, 100.0],
    "gamma_factor": [0.1, 1.0, 10.0],
}
"""svm-tuned: C and a multiple of the 'scale' gamma, chosen by trial-grouped CV on training data."""
SVM_TRUSTED_TYPES: tuple[str, ...] = (
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.svm._classes.SVC",
)
"""The only types a stored SVM pipeline may contain (checked before skops builds anything)."""


def make_svm(random_state: int = 0) -> Pipeline:
    """The paper's classifier: standardised features, RBF SVC, C=1, one-vs-one, Platt probabilities."""
    return Pipeline(
        [
            ("scale", StandardScaler()),
            (
                "svc",
                SVC(
                    kernel="rbf",
                    C=1.0,
                    decision_function_shape="ovo",
                    probability=True,
                    random_state=random_state,
                ),
            ),
        ]
    )


def svm_predict_proba(estimator: Any, X: np.ndarray) -> np.ndarray:
    """estimator.predict_proba(X), without sklearn's per-call input checks for our SVM pipeline.

    Those checks cost ~0.5 ms per live window; the arithmetic is the pipeline's own
    (StandardScaler's in-place centring and scaling, then SVC's libsvm call), so the result is
    identical. Any other estimator, or input the checks would reject, takes the checked path.
    """
    steps = getattr(estimator, "steps", None)
    if (
        not isinstance(estimator, Pipeline)
        or len(steps) != 2
        or type(steps[0][1]) is not StandardScaler
        or type(steps[1][1]) is not SVC
    ):
        return estimator.predict_proba(X)
    scaler, svc = steps[0][1], steps[1][1]
    if (
        not isinstance(X, np.ndarray)
        or X.ndim != 2
        or X.dtype != np.float64
        or X.shape[1] != getattr(scaler, "n_features_in_", -1)
        or getattr(svc, "_sparse", True)
        or svc.kernel not in ("rbf", "linear", "poly", "sigmoid")
        or getattr(svc, "_probA", np.empty(0)).size == 0
        or svc.n_support_.sum() != svc.support_vectors_.shape[0]
        or not np.isfinite(X).all()
    ):
        return estimator.predict_proba(X)
    Xt = np.array(X, dtype=np.float64, order="C", copy=True)
    if scaler.with_mean:
        Xt -= scaler.mean_
    if scaler.with_std:
        Xt /= scaler.scale_
    return svc._dense_predict_proba(Xt)


def _fit_svm(estimator: Pipeline, X: np.ndarray, y: Sequence[str]) -> Pipeline:
    """Fit, silencing only sklearn 1.9's deprecation of SVC(probability=True) (the paper's setting)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*probability.*", category=FutureWarning)
        return estimator.fit(X, list(y))


@dataclass
class SubtaskModel:
    """A fitted encoding + classifier mapping sub-task samples to sub-task probabilities."""

    classifier: str
    encoder: PaperEncoding | CompactEncoding
    estimator: Any
    taxonomy_profile: str = "reference"
    random_state: int = 0
    training: dict[str, Any] = field(default_factory=dict)
    """How it was trained, stored in the header (e.g. live_augment settings, learn/live.py)."""
    live: SubtaskModel | None = None
    """Optional head for running (unfinished) windows, trained with live-like windows
    (learn/live.py); final verdicts on finished sub-tasks always use this model itself."""
    takes_axis_memo: ClassVar[bool] = True
    """Its predict calls take `memo=` (an AxisMemo): the belief tracker passes the one it owns
    for its running windows (other models it is given need not)."""

    def head(self, final: bool) -> SubtaskModel:
        """The model for a finished sub-task (final) or a running window (the live head if any)."""
        return self if final or self.live is None else self.live

    @property
    def encoding(self) -> str:
        """Name of the encoding ('paper' or 'compact')."""
        return self.encoder.name

    @property
    def classes_(self) -> list[str]:
        """Sub-task names in the column order of predict_proba_samples."""
        return [str(c) for c in self.estimator.classes_]

    def features(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """The encoded samples; `memo`: they are running windows of the memo owner's stream."""
        return self.encoder.transform(samples, memo)

    def predict_proba_samples(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> np.ndarray:
        """(n, k) class probabilities, columns in classes_ order."""
        return svm_predict_proba(self.estimator, self.features(samples, memo))

    def predict_samples(
        self, samples: Sequence[SubtaskSample], memo: AxisMemo | None = None
    ) -> list[str]:
        """The predicted sub-task of each sample."""
        return [str(c) for c in self.estimator.predict(self.features(samples, memo))]

    def partial_fit_samples(self, samples: Sequence[SubtaskSample]) -> SubtaskModel:
        """Online update with a mini-batch (Mondrian only; the encoding stays as fitted)."""
        if self.classifier != "mondrian":
            raise InputError(f"partial_fit needs the mondrian classifier, not {self.classifier}")
        self.estimator.partial_fit(self.features(samples), [s.subtask for s in samples])
        return self


def train_model(
    samples: Sequence[SubtaskSample],
    classifier: str = "svm",
    encoding: str = "compact",
    random_state: int = 0,
    taxonomy_profile: str = "reference",
    n_estimators: int = 100,
    augment_prefixes: Sequence[float] = (),
    cache: SampleCache | None = None,
) -> SubtaskModel:
    """Fit the encoding and the classifier on `samples` (training data only).

    `augment_prefixes` (e.g. (0.25, 0.5, 0.75)) also trains on those first fractions of every
    sub-task, so a live classifier is not surprised by a sub-task that has only just begun.
    `cache`: a SampleCache shared by models trained on the same samples (else the encoding's own).
    """
    if classifier not in CLASSIFIERS:
        raise InputError(f"unknown classifier {classifier!r} (known: {', '.join(CLASSIFIERS)})")
    if not samples:
        raise InputError("no training samples")
    samples = list(samples) + [prefix_sample(s, f) for f in augment_prefixes for s in samples]
    encoder = make_encoding(encoding, cache).fit(samples)
    X = encoder.transform(samples)
    y = [s.subtask for s in samples]
    if classifier in ("svm", "svm-tuned"):
        if len(set(y)) < 2:
            raise InputError("the SVM needs samples of at least two sub-tasks")
        svm = make_svm(random_state)
        if classifier == "svm-tuned":
            svm.set_params(**tune_svm(X, y, [s.trial for s in samples], random_state))
        estimator: Any = _fit_svm(svm, X, y)
    else:
        classes = sorted(set(SUBTASKS) | set(y))
        estimator = MondrianForestClassifier(n_estimators=n_estimators, random_state=random_state)
        estimator.partial_fit(X, y, classes=classes)
    return SubtaskModel(classifier, encoder, estimator, taxonomy_profile, random_state)


def tune_svm(
    X: np.ndarray, y: Sequence[str], groups: Sequence[str], random_state: int = 0
) -> dict[str, Any]:
    """Inner, trial-grouped 3-fold CV over TUNING_GRID on the training data only.

    Returns pipeline parameters (svc__C, svc__gamma); the paper's C=1, gamma='scale' when there
    are fewer than 3 training trials to cross-validate over.
    """
    from sklearn.model_selection import GroupKFold, cross_val_score

    if len(set(groups)) < 3:
        return {"svc__C": 1.0, "svc__gamma": "scale"}
    scaled = StandardScaler().fit_transform(X)
    scale_gamma = 1.0 / (X.shape[1] * max(float(scaled.var()), 1e-12))
    best, best_score = {"svc__C": 1.0, "svc__gamma": "scale"}, -1.0
    for c in TUNING_GRID["C"]:
        for factor in TUNING_GRID["gamma_factor"]:
            candidate = Pipeline(
                [("scale", StandardScaler()), ("svc", SVC(C=c, gamma=factor * scale_gamma))]
            )
            score = cross_val_score(
                candidate, X, list(y), groups=list(groups), cv=GroupKFold(3)
            ).mean()
            if score > best_score + 1e-12:
                best, best_score = {"svc__C": c, "svc__gamma": factor * scale_gamma}, score
    return best


# ------------------------------------------------------------------------------ model files
def _forest_arrays(
    forest: MondrianForestClassifier,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Parameters and arrays that fully describe a fitted forest (including online state)."""
    pool, size = forest._pool, forest._pool.size
    leaves = [i for i in range(size) if pool.points[i] is not None]
    offsets = np.zeros(len(leaves) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(pool.points[i]) for i in leaves])
    flat = np.concatenate([pool.points[i] for i in leaves]) if leaves else np.empty(0, np.int64)
    params = {
        "n_estimators": int(forest.n_estimators),
        "discount_factor": float(forest.discount_factor),
        "random_state": forest.random_state if isinstance(forest.random_state, int) else None,
        "n_features_in": int(forest.n_features_in_),
        "rng_state": forest._rng.bit_generator.state,
    }
    arrays = {
        "mf_classes": np.asarray(forest.classes_).astype(str),
        "mf_roots": forest._roots,
        "mf_left": pool.left[:size],
        "mf_right": pool.right[:size],
        "mf_parent": pool.parent[:size],
        "mf_feature": pool.feature[:size],
        "mf_threshold": pool.threshold[:size],
        "mf_tau": pool.tau[:size],
        "mf_lower": pool.lower[:size],
        "mf_upper": pool.upper[:size],
        "mf_counts": pool.counts[:size],
        "mf_X": forest._X,
        "mf_y": forest._y.astype(np.int64),
        "mf_leaf_nodes": np.asarray(leaves, dtype=np.int64),
        "mf_leaf_offsets": offsets,
        "mf_leaf_points": flat.astype(np.int64),
    }
    return params, arrays


def _forest_from_arrays(
    params: dict[str, Any], arrays: dict[str, np.ndarray]
) -> MondrianForestClassifier:
    """Rebuild a forest from _forest_arrays output; inconsistent arrays raise ValueError."""
    forest = MondrianForestClassifier(
        n_estimators=int(params["n_estimators"]),
        discount_factor=float(params["discount_factor"]),
        random_state=params["random_state"],
    )
    classes = arrays["mf_classes"]
    size = len(arrays["mf_left"])
    n_features = int(params["n_features_in"])
    forest.classes_ = classes
    forest.n_features_in_ = n_features
    forest._rng = np.random.default_rng()
    forest._rng.bit_generator.state = params["rng_state"]
    pool = _NodePool(n_features, len(classes), capacity=max(size, 1))
    pool.size = size
    for name in (
        "left",
        "right",
        "parent",
        "feature",
        "threshold",
        "tau",
        "lower",
        "upper",
        "counts",
    ):
        value = arrays[f"mf_{name}"]
        target = getattr(pool, name)
        if value.shape != target[:size].shape:
            raise ValueError(f"array mf_{name} has shape {value.shape}")
        target[:size] = value
    links = np.concatenate(
        [pool.left[:size], pool.right[:size], pool.parent[:size], arrays["mf_roots"]]
    )
    if size == 0 or links.max() >= size or links.min() < NO_NODE:
        raise ValueError("node links point outside the node arrays")
    offsets, flat = arrays["mf_leaf_offsets"], arrays["mf_leaf_points"]
    n_points = len(arrays["mf_y"])
    if len(flat) and (flat.max() >= n_points or flat.min() < 0):
        raise ValueError("leaf points point outside the stored data")
    for k, node in enumerate(arrays["mf_leaf_nodes"]):
        pool.points[int(node)] = flat[offsets[k] : offsets[k + 1]].astype(np.intp)
    forest._pool = pool
    forest._roots = arrays["mf_roots"].astype(np.int32)
    if len(forest._roots) != forest.n_estimators:
        raise ValueError("number of roots differs from n_estimators")
    forest._X = arrays["mf_X"].astype(FEATURE_DTYPE)
    forest._y = arrays["mf_y"].astype(np.intp)
    forest.gamma_ = forest.discount_factor * n_features
    forest._update_posterior()
    return forest


def _checksum(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over the header (without its checksum) and every array's name, dtype, shape, bytes."""
    digest = hashlib.sha256()
    digest.update(
        json.dumps({k: v for k, v in header.items() if k != "checksum"}, sort_keys=True).encode()
    )
    for name in sorted(arrays):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def save_model(model: SubtaskModel, path: Path | str) -> Path:
    """Write `model` as a safe .npz model file (no pickled objects)."""
    path = Path(path)
    header, arrays = _model_parts(model)
    if model.live is not None:
        header["live"], live_arrays = _model_parts(model.live)
        arrays.update({LIVE_PREFIX + k: v for k, v in live_arrays.items()})
    header["checksum"] = _checksum(header, arrays)
    payload = {"header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays}
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as handle:
        np.savez_compressed(handle, **payload)
    return path


LIVE_PREFIX = "live__"
"""Array-name prefix of the live head's arrays in a model file."""


def _model_parts(model: SubtaskModel) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Header fields and arrays of one model (without checksum)."""
    header: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "classifier": model.classifier,
        "encoding": model.encoder.to_state(),
        "classes": model.classes_,
        "taxonomy_profile": model.taxonomy_profile,
        "random_state": model.random_state,
    }
    if model.training:
        header["training"] = model.training
    if model.classifier in ("svm", "svm-tuned"):
        import skops.io as sio

        arrays = {"svm_skops": np.frombuffer(sio.dumps(model.estimator), dtype=np.uint8)}
    else:
        header["mondrian"], arrays = _forest_arrays(model.estimator)
    return header, arrays


def load_model(path: Path | str, expect_encoding: str | None = None) -> SubtaskModel:
    """Read a model file; a corrupt, tampered, foreign or wrong-version file is a one-line InputError."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except FileNotFoundError:
        raise InputError("model file not found", path) from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"not a readable model file ({type(exc).__name__})", path) from None
    if "header" not in arrays:
        raise InputError("not an rcbht model file (no header)", path)
    try:
        header = json.loads(arrays.pop("header").tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError("model header is not valid JSON", path, field="header") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise InputError("not an rcbht sub-task model file", path, field="format")
    if header.get("format_version") != FORMAT_VERSION:
        raise InputError(
            f"model format version {header.get('format_version')!r} is not supported "
            f"(this version reads {FORMAT_VERSION}); retrain with `rcbht train`",
            path,
            field="format_version",
        )
    if header.get("checksum") != _checksum(header, arrays):
        raise InputError(
            "checksum mismatch: the model file is corrupt or was modified", path, field="checksum"
        )
    main = {k: v for k, v in arrays.items() if not k.startswith(LIVE_PREFIX)}
    model = _model_from_parts(header, main, path, expect_encoding)
    if isinstance(header.get("live"), dict):
        live = {k[len(LIVE_PREFIX) :]: v for k, v in arrays.items() if k.startswith(LIVE_PREFIX)}
        model.live = _model_from_parts(header["live"], live, path, expect_encoding)
    return model


def _model_from_parts(
    header: dict[str, Any], arrays: dict[str, np.ndarray], path: Path, expect_encoding: str | None
) -> SubtaskModel:
    """One model from its header fields and arrays (the checksum is already verified)."""
    encoder = encoding_from_state(header.get("encoding") or {})
    if expect_encoding is not None and encoder.name != expect_encoding:
        raise InputError(
            f"model uses the {encoder.name!r} encoding, expected {expect_encoding!r}",
            path,
            field="encoding",
        )
    classifier = header.get("classifier")
    try:
        if classifier in ("svm", "svm-tuned"):
            import skops.io as sio

            data = arrays["svm_skops"].tobytes()
            untrusted = [
                t for t in sio.get_untrusted_types(data=data) if t not in SVM_TRUSTED_TYPES
            ]
            if untrusted:
                raise InputError(f"SVM holds untrusted types {untrusted}", path, field="svm_skops")
            estimator: Any = sio.loads(data, trusted=list(SVM_TRUSTED_TYPES))
        elif classifier == "mondrian":
            estimator = _forest_from_arrays(header["mondrian"], arrays)
        else:
            raise InputError(f"unknown classifier {classifier!r}", path, field="classifier")
    except InputError:
        raise
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(
            f"inconsistent model content: {exc}", path, field=str(classifier)
        ) from None
    if [str(c) for c in estimator.classes_] != header.get("classes"):
        raise InputError("class names differ from the header", path, field="classes")
    return SubtaskModel(
        classifier,
        encoder,
        estimator,
        str(header.get("taxonomy_profile", "reference")),
        int(header.get("random_state", 0)),
        dict(header.get("training") or {}),
    )


def model_summary(path: Path | str) -> dict[str, Any]:
    """Header of a model file (for `rcbht train` output and diagnostics)."""
    model = load_model(path)
    return {
        "classifier": model.classifier,
        "encoding": model.encoding,
        "classes": model.classes_,
        "taxonomy_profile": model.taxonomy_profile,
        "n_features": model.encoder.n_features,
        "training": model.training,
    }


__all__ = [
    "FORMAT_VERSION",
    "SubtaskModel",
    "load_model",
    "make_svm",
    "save_model",
    "train_model",
]


def load_subtask_model(path: str, expected_profile: str = "") -> tuple[object | None, str]:
    """(model, '') for a usable sub-task model file, else (None, why it cannot be used)."""
    if not path:
        return None, "no model file given (parameter model_file)"
    try:
        model = load_model(path)
    except InputError as exc:
        return None, str(exc)
    except OSError as exc:
        return None, f"{path}: cannot read: {exc.strerror}"
    classes = [str(c) for c in getattr(model, "classes_", [])]
    if not classes or not set(classes) <= set(SUBTASKS):
        return None, f"{path}: model classes {classes} are not sub-tasks {list(SUBTASKS)}"
    profile = str(getattr(model, "taxonomy_profile", ""))
    if expected_profile and profile != expected_profile:
        return None, (
            f"{path}: model was trained with taxonomy profile {profile!r}, "
            f"the segmenter uses {expected_profile!r}"
        )
    return model, ""
