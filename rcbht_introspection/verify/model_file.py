"""The verifier model file: the detector's nominal models and thresholds and the characteriser's
packed trees as a safe .npz (JSON header and plain arrays, checksummed, written atomically;
loading executes no code)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.config_files import from_mapping
from rcbht_introspection.errors import InputError
from rcbht_introspection.io.safe_file import read_checked, write_safe_npz
from rcbht_introspection.learn.forest import ARRAYS, ForestHead
from rcbht_introspection.verify.characterise import FAILURE, Characteriser
from rcbht_introspection.verify.config import VerifyConfig, check_verify_config
from rcbht_introspection.verify.detector import Detector, SignalModels
from rcbht_introspection.verify.features import lag_ticks
from rcbht_introspection.verify.labels import DIRECTION_AXES, DIRECTIONS
from rcbht_introspection.verify.novelty import NeighbourModel, NominalLevel, TimingModel
from rcbht_introspection.verify.shape import ShapeHead

FORMAT = "rcbht-verifier"
FORMAT_VERSION = 9
"""9: the departure signal (8: the transient signal and scikit-learn heads; 7: the shape head;
6: forest heads only; 5 and older: Mondrian heads; retrain)."""
KIND = "verifier"


@dataclass
class VerifierModel:
    """What the verifier node runs: the detector (signals, thresholds) and the characteriser."""

    arms: tuple[str, ...]
    detector: Detector
    characteriser: Characteriser | None
    trained_on: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def config(self) -> VerifyConfig:
        return self.detector.config


def _detector_parts(d: Detector) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    header: dict[str, Any] = {"signals": list(d.signals), "phases": list(d.phases)}
    arrays: dict[str, np.ndarray] = {"thresholds": d.thresholds}
    level, tm = d.models.level, d.models.timing
    models = d.models
    for key, nb in (
        ("neighbours", models.neighbours),
        ("transient", models.transient),
        ("departure", models.departure),
    ):
        if nb is not None:
            header[key] = {
                "phases": list(nb.phases),
                "n_trials": nb.n_trials,
                "bin_s": nb.bin_s,
                "tolerance_s": nb.tolerance_s,
                "relative": nb.relative,
                "largest": nb.largest,
            }
            for i in range(len(nb.phases)):
                arrays[f"{key}.{i}.elapsed"] = nb.elapsed[i]
                arrays[f"{key}.{i}.points"] = nb.points[i]
                arrays[f"{key}.{i}.scale"] = nb.scale[i]
            arrays[f"{key}.columns"] = nb.columns
    if level is not None:
        header["level"] = {"phases": list(level.phases)}
        arrays.update({f"level.{i}": m for i, m in enumerate(level.median)})
    if tm is not None:
        header["timing"] = {"phases": list(tm.phases)}
        arrays.update({"timing.low": tm.low, "timing.high": tm.high, "timing.scale": tm.scale})
    return header, arrays


def _head_parts(name: str, head: ForestHead) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    header = {"classes": [str(c) for c in head.classes_], "params": head.get_params()}
    arrays = {f"head.{name}.{k}": v for k, v in head.arrays_.items()}
    arrays[f"head.{name}.n_features"] = np.array(head.n_features_in_)
    return header, arrays


def save_verifier(model: VerifierModel, path: Path | str) -> Path:
    """Write `model` as a safe verifier file."""
    path = Path(path)
    det_header, arrays = _detector_parts(model.detector)
    header: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "arms": list(model.arms),
        "config": dataclasses.asdict(model.config),
        "trained_on": model.trained_on,
        **det_header,
    }
    ch = model.characteriser
    if ch is not None:
        heads = {}
        for name, head in ch.heads_.items():
            heads[name], head_arrays = _head_parts(name, head)
            arrays.update(head_arrays)
        header["characteriser"] = {
            "params": ch.get_params(),
            "heads": heads,
            "signs": [[*key, cls] for key, cls in ch.signs_.items()],
        }
        if ch.shape_ is not None:
            header["characteriser"]["shape"] = {
                "params": ch.shape_.get_params(),
                "classes": [str(c) for c in ch.shape_.classes_],
                "weight": ch.shape_weight_,
            }
            arrays.update({f"shape.{k}": v for k, v in ch.shape_.to_arrays().items()})
    write_safe_npz(path, header, arrays)
    return path


def _detector(
    header: dict[str, Any], arrays: dict[str, np.ndarray], config: VerifyConfig
) -> Detector:
    level = timing = None
    if "level" in header:
        phases = tuple(header["level"]["phases"])
        level = NominalLevel(phases, [arrays[f"level.{i}"] for i in range(len(phases))])
    if "timing" in header:
        t = ("timing.low", "timing.high", "timing.scale")
        timing = TimingModel(tuple(header["timing"]["phases"]), *(arrays[k] for k in t))
    models = SignalModels(
        neighbours=_neighbours(header, arrays, "neighbours"),
        transient=_neighbours(header, arrays, "transient"),
        level=level,
        timing=timing,
        departure=_neighbours(header, arrays, "departure"),
        lag=lag_ticks(config),
    )
    thresholds = arrays["thresholds"]
    phases = tuple(header["phases"])
    if thresholds.shape != (len(header["signals"]), len(phases)):
        raise ValueError("thresholds do not match the signals and sub-tasks")
    return Detector(tuple(header["signals"]), models, thresholds, config, phases)


def _neighbours(
    header: dict[str, Any], arrays: dict[str, np.ndarray], key: str
) -> NeighbourModel | None:
    """A neighbour model stored under `key` (None when the file has none)."""
    if key not in header:
        return None
    nh = header[key]
    n = len(nh["phases"])
    return NeighbourModel(
        tuple(nh["phases"]),
        [arrays[f"{key}.{i}.elapsed"] for i in range(n)],
        [arrays[f"{key}.{i}.points"] for i in range(n)],
        [arrays[f"{key}.{i}.scale"] for i in range(n)],
        float(nh["bin_s"]),
        int(nh["n_trials"]),
        float(nh["tolerance_s"]),
        float(nh["relative"]),
        arrays[f"{key}.columns"],
        largest=bool(nh.get("largest", False)),
    )


def _characteriser(c: dict[str, Any], arrays: dict[str, np.ndarray]) -> Characteriser:
    ch = Characteriser(**c["params"])
    ch.heads_ = {}
    for name, h in c["heads"].items():
        if name != FAILURE and name.partition("@")[0] not in DIRECTION_AXES:
            raise ValueError(f"unknown characteriser head {name!r}")
        start = f"head.{name}."
        own = {k[len(start) :]: a for k, a in arrays.items() if k.startswith(start)}
        missing = [k for k in (*ARRAYS, "n_features") if k not in own]
        if missing:
            raise ValueError(f"head {name!r} lacks {', '.join(missing)}")
        ch.heads_[name] = ForestHead.from_arrays(h["params"], h["classes"], own)
    if FAILURE not in ch.heads_:
        raise ValueError("no failure-class head")
    ch.classes_ = ch.heads_[FAILURE].classes_
    ch.n_features_in_ = ch.heads_[FAILURE].n_features_in_
    ch.signs_ = {tuple(str(v) for v in row[:-1]): str(row[-1]) for row in c["signs"]}
    ch.shape_, ch.shape_weight_ = _shape(c.get("shape"), arrays)
    for key, cls in ch.signs_.items():
        if len(key) != len(DIRECTION_AXES) or not set(key) <= set(DIRECTIONS):
            raise ValueError(f"direction signs {list(key)} are not one of -, 0, + per axis")
        if cls not in ch.heads_[FAILURE].classes_:
            raise ValueError(f"direction signs name the unknown class {cls!r}")
    return ch


def _shape(
    s: dict[str, Any] | None, arrays: dict[str, np.ndarray]
) -> tuple[ShapeHead | None, float]:
    """The shape head and its vote weight (none in the file: no head, weight 0)."""
    if s is None:
        return None, 0.0
    weight = float(s["weight"])
    if not 0.0 < weight <= 1.0:
        raise ValueError(f"the shape head's weight {weight} is not in (0, 1]")
    own = {k[len("shape.") :]: a for k, a in arrays.items() if k.startswith("shape.")}
    return ShapeHead.from_arrays(s["params"], s["classes"], own), weight


def load_verifier(path: Path | str) -> VerifierModel:
    """Read a verifier file; a corrupt, tampered, foreign or wrong-version file is a one-line error."""
    path = Path(path)
    header, arrays = read_checked(path, KIND, FORMAT, FORMAT_VERSION, "rcbht verify-train")
    try:
        config = from_mapping(VerifyConfig, header["config"], path=path, prefix="config.")
        try:
            check_verify_config(config)
        except InputError as exc:
            raise InputError(exc.message, path, field=f"config.{exc.field}") from None
        detector = _detector(header, arrays, config)
        ch = _characteriser(header["characteriser"], arrays) if "characteriser" in header else None
    except (KeyError, TypeError, ValueError, IndexError, OverflowError, AttributeError) as exc:
        raise InputError(f"inconsistent verifier content: {exc}", path) from None
    return VerifierModel(tuple(header["arms"]), detector, ch, dict(header.get("trained_on") or {}))


def load_usable_verifier(path: str, arms: Sequence[str]) -> tuple[VerifierModel | None, str]:
    """The verifier model at `path` for a node of `arms`, or None and why it cannot be used."""
    if not path:
        return None, "verifier_file not set"
    try:
        model = load_verifier(path)
    except InputError as exc:
        return None, str(exc)
    if set(model.arms) != set(arms):
        return None, f"the model's arms {list(model.arms)} are not the node's {list(arms)}"
    ch = model.characteriser
    if ch is not None and ch.shape_ is not None:  # numba compiles or loads MiniRocket now,
        ch.shape_.predict_proba([np.zeros((1, ch.shape_.n_channels_))])  # not at the first alarm
    return model, ""
