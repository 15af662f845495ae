"""The safe sub-task model file: loading never executes code.

A model file is a safe file (io/safe_file.py): a JSON header (format version, classifier,
encoding with its fitted parameters, class names, the taxonomy profile's name, digest and values,
SHA-256 of all content) and plain arrays. The SVM pipeline is stored with skops and loaded with an
explicit trusted-type list, the Mondrian forest as its node arrays (mondrian_state.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import skops.io as sio

from rcbht_introspection.errors import InputError
from rcbht_introspection.grammar.encoding.registry import encoding_from_state
from rcbht_introspection.io.safe_file import read_checked, write_safe_npz
from rcbht_introspection.learn.forest import ForestHead
from rcbht_introspection.learn.models import SubtaskModel
from rcbht_introspection.learn.mondrian_state import forest_arrays, forest_from_arrays
from rcbht_introspection.learn.vote import SvmForestClassifier
from rcbht_introspection.task import Task, task_of_names
from rcbht_introspection.taxonomy.config import (
    TaxonomyConfig,
    default_config,
    taxonomy_digest,
    taxonomy_from_document,
    taxonomy_values,
)

FORMAT = "rcbht-subtask-model"
FORMAT_VERSION = 1
SVM_TRUSTED_TYPES: tuple[str, ...] = (
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.svm._classes.SVC",
)
"""The only types a stored SVM pipeline may contain (checked before skops builds anything)."""
FOREST_PREFIX = "forest__"
"""Array-name prefix of the vote's packed forest (learn/forest.py) in a model file."""
HEADS = ("live", "window")
"""The optional heads for running windows (SubtaskModel.live, .window): each stored under its
name in the header and with the array-name prefix 'NAME__'."""


def save_model(model: SubtaskModel, path: Path | str, compress: bool = True) -> Path:
    """Write `model` as a safe .npz model file (no pickled objects).

    Atomic: written to a temporary file beside `path`, then renamed over it, so a reader (a node
    restarting while a taught model is saved) finds the old file or the new one, never a part.
    `compress=False`: the teach file, rewritten at every teach and read by the live node."""
    path = Path(path)
    header, arrays = _model_parts(model)
    for name, head in zip(HEADS, (model.live, model.window), strict=True):
        if head is not None:
            header[name], head_arrays = _model_parts(head)
            arrays.update({f"{name}__{k}": v for k, v in head_arrays.items()})
    write_safe_npz(path, header, arrays, compress)
    return path


def _model_parts(model: SubtaskModel) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Header fields and arrays of one model (without checksum)."""
    header: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "classifier": model.classifier,
        "encoding": model.encoder.to_state(),
        "classes": model.classes_,
        "taxonomy_profile": model.taxonomy_profile,
        "taxonomy_sha256": model.taxonomy_sha256,
        "random_state": model.random_state,
        "task": model.task.to_dict(),
    }
    if model.taxonomy is not None:
        header["taxonomy"] = taxonomy_values(model.taxonomy)
    if model.training:
        header["training"] = model.training
    if model.classifier in ("svm", "svm-tuned"):
        arrays = {"svm_skops": np.frombuffer(sio.dumps(model.estimator), dtype=np.uint8)}
    elif model.classifier == "forest":
        header["forest"] = {"n_estimators": int(model.estimator.n_estimators)}
        arrays = _forest_arrays(model.estimator)
    elif model.classifier == "svm-forest":
        vote = model.estimator
        header["vote"] = vote.get_params()
        arrays = {"svm_skops": np.frombuffer(sio.dumps(vote.svm_), dtype=np.uint8)}
        arrays.update(_forest_arrays(vote.forest_))
    else:
        header["mondrian"], arrays = forest_arrays(model.estimator)
    return header, arrays


def load_model(path: Path | str, expect_encoding: str | None = None) -> SubtaskModel:
    """Read a model file; a corrupt, tampered, foreign or wrong-version file is a one-line InputError."""
    path = Path(path)
    header, arrays = read_checked(path, "model", FORMAT, FORMAT_VERSION, "rcbht train")
    prefixes = tuple(f"{name}__" for name in HEADS)
    main = {k: v for k, v in arrays.items() if not k.startswith(prefixes)}
    model = _model_from_parts(header, main, path, expect_encoding)
    for name in HEADS:
        if isinstance(header.get(name), dict):
            own = {k[len(name) + 2 :]: v for k, v in arrays.items() if k.startswith(f"{name}__")}
            setattr(model, name, _model_from_parts(header[name], own, path, expect_encoding))
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
            estimator: Any = _svm(arrays, path)
        elif classifier == "forest":
            estimator = _forest(header["forest"], header["classes"], arrays)
        elif classifier == "svm-forest":
            estimator = _vote(header, arrays, path)
        elif classifier == "mondrian":
            estimator = forest_from_arrays(header["mondrian"], arrays)
        else:
            raise InputError(f"unknown classifier {classifier!r}", path, field="classifier")
    except InputError:
        raise
    except (KeyError, ValueError, TypeError, IndexError, OverflowError) as exc:
        raise InputError(
            f"inconsistent model content: {exc}", path, field=str(classifier)
        ) from None
    if [str(c) for c in estimator.classes_] != header.get("classes"):
        raise InputError("class names differ from the header", path, field="classes")
    name, sha256 = _recorded_profile(header)
    return SubtaskModel(
        classifier,
        encoder,
        estimator,
        name,
        int(header.get("random_state", 0)),
        dict(header.get("training") or {}),
        task=_task_of_header(header, path),
        taxonomy_sha256=sha256,
        taxonomy=_embedded_taxonomy(header, path),
    )


def _recorded_profile(header: dict[str, Any]) -> tuple[str, str]:
    """The name and digest of the taxonomy profile a header records ('' digest: older files)."""
    return str(header.get("taxonomy_profile", "reference")), str(header.get("taxonomy_sha256", ""))


def _embedded_taxonomy(header: dict[str, Any], path: Path) -> TaxonomyConfig | None:
    """The profile a header embeds (None in older files), checked as a profile file is and
    against the recorded digest: a bad value or an altered profile is a one-line InputError."""
    if header.get("taxonomy") is None:
        return None
    name, sha256 = _recorded_profile(header)
    taxonomy = taxonomy_from_document(header, name, path=path, section=("taxonomy",))
    digest = taxonomy_digest(taxonomy)
    if digest != sha256:
        raise InputError(
            f"the embedded taxonomy profile {name!r} does not have the recorded digest "
            f"taxonomy_sha256 {sha256[:12] or 'empty'} (sha256 {digest[:12]})",
            path,
            field="taxonomy",
        )
    return taxonomy


def _svm(arrays: dict[str, np.ndarray], path: Path) -> Any:
    """The stored SVM pipeline, built by skops only from the trusted types."""
    data = arrays["svm_skops"].tobytes()
    untrusted = [t for t in sio.get_untrusted_types(data=data) if t not in SVM_TRUSTED_TYPES]
    if untrusted:
        raise InputError(f"SVM holds untrusted types {untrusted}", path, field="svm_skops")
    return sio.loads(data, trusted=list(SVM_TRUSTED_TYPES))


def _forest_arrays(forest: ForestHead) -> dict[str, np.ndarray]:
    """A packed forest's arrays under FOREST_PREFIX, with its number of features."""
    arrays = {FOREST_PREFIX + k: v for k, v in forest.arrays_.items()}
    arrays[FOREST_PREFIX + "n_features"] = np.asarray(forest.n_features_in_)
    return arrays


def _forest(
    params: dict[str, Any], classes: list[str], arrays: dict[str, np.ndarray]
) -> ForestHead:
    """The stored forest (alone or in the vote), from its packed arrays."""
    packed = {k[len(FOREST_PREFIX) :]: v for k, v in arrays.items() if k.startswith(FOREST_PREFIX)}
    forest_params = {"n_estimators": int(params["n_estimators"]), "min_samples_leaf": 1}
    return ForestHead.from_arrays(forest_params, classes, packed)


def _vote(header: dict[str, Any], arrays: dict[str, np.ndarray], path: Path) -> SvmForestClassifier:
    """The stored SVM + forest vote: the SVM as above, the forest from its packed arrays."""
    params = {k: int(header["vote"][k]) for k in ("n_estimators", "random_state")}
    forest = _forest(params, header["classes"], arrays)
    return SvmForestClassifier.from_members(_svm(arrays, path), forest, params)


def _task_of_header(header: dict[str, Any], path: Path) -> Task:
    """The model's task; files written before tasks were stored: HIRO's, or their classes."""
    data = header.get("task")
    if data is None:
        return task_of_names([[str(c) for c in header.get("classes") or []]])
    if not isinstance(data, dict):
        raise InputError("task must be a mapping", path, field="task")
    try:
        return Task.from_dict(data)
    except InputError as exc:
        raise InputError(
            exc.message, path, field=f"task.{exc.field}" if exc.field else "task"
        ) from None


def model_taxonomy(
    model: SubtaskModel, given: TaxonomyConfig | None = None, path: Path | str | None = None
) -> TaxonomyConfig:
    """The profile that labels the words `model` classifies: `given` (an override, refused when
    it is not the model's), else the one the model embeds (older files: reference)."""
    recorded = (model.taxonomy_profile, model.taxonomy_sha256)
    return _labelling_taxonomy(recorded, model.taxonomy, given, path)


def model_file_taxonomy(path: Path | str, given: TaxonomyConfig | None = None) -> TaxonomyConfig:
    """model_taxonomy of the model file at `path`, from its header alone (checksum verified,
    classifier not built): what segmenter_node labels with for that model."""
    header, _ = read_checked(Path(path), "model", FORMAT, FORMAT_VERSION, "rcbht train")
    embedded = _embedded_taxonomy(header, Path(path))
    return _labelling_taxonomy(_recorded_profile(header), embedded, given, path)


def _labelling_taxonomy(
    recorded: tuple[str, str],
    embedded: TaxonomyConfig | None,
    given: TaxonomyConfig | None,
    path: Path | str | None,
) -> TaxonomyConfig:
    """`given`, else `embedded`, else reference; an InputError when its digest is not the
    `recorded` (name, digest): the model would see words of a profile it never learned."""
    name, sha256 = recorded
    taxonomy = given or embedded or default_config()
    digest = taxonomy_digest(taxonomy)
    if sha256 and sha256 != digest:
        raise InputError(
            f"the model was trained on words of taxonomy profile {name!r} "
            f"(sha256 {sha256[:12]}), not of {taxonomy.profile!r} (sha256 {digest[:12]}); give "
            "the profile it was trained with (--taxonomy-config / --profile, or the segmenter's "
            "taxonomy_config_file)",
            path,
        )
    return taxonomy


def load_subtask_model(path: str, expected_profile: str = "") -> tuple[SubtaskModel | None, str]:
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
    if not classes or not set(classes) <= set(model.task.subtasks):
        return (
            None,
            f"{path}: model classes {classes} are not sub-tasks {list(model.task.subtasks)}",
        )
    profile = str(getattr(model, "taxonomy_profile", ""))
    if expected_profile and profile != expected_profile:
        return None, (
            f"{path}: model was trained with taxonomy profile {profile!r}, "
            f"the segmenter uses {expected_profile!r}"
        )
    return model, ""


__all__ = [
    "FORMAT_VERSION",
    "load_model",
    "load_subtask_model",
    "model_file_taxonomy",
    "model_taxonomy",
    "save_model",
]
