"""The verifier model file: detection and characterisation heads as a safe .npz (JSON header and
plain arrays, checksummed, written atomically; loading executes no code)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rcbht_introspection.config_files import from_mapping
from rcbht_introspection.errors import InputError
from rcbht_introspection.learn.model_file import check_checksum, read_safe_npz, write_safe_npz
from rcbht_introspection.learn.mondrian_state import forest_arrays, forest_from_arrays
from rcbht_introspection.verify.characterise import (
    CONTACT_PER_ARM,
    FAILURE,
    Characteriser,
    ForestHead,
)
from rcbht_introspection.verify.config import VerifyConfig, check_verify_config
from rcbht_introspection.verify.detector import Detector, SignalModels
from rcbht_introspection.verify.labels import DIRECTION_AXES, DIRECTIONS
from rcbht_introspection.verify.novelty import EnvelopeModel, NeighbourModel, TimingModel

FORMAT = "rcbht-verifier"
FORMAT_VERSION = 5
"""5: narrow direction heads reading some wrench axes and the sign-to-class table (4: contact
forests trained on touching evidence only, weighed per head; 3: contact-geometry forests beside
the class and x, y heads; 2: Mondrian heads; 1: logistic regressions)."""
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


def _head_parts(prefix: str, head: ForestHead) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    params, arrays = forest_arrays(head.forest)
    return params, {f"{prefix}.{name}": a for name, a in arrays.items()}


def _head(prefix: str, params: dict[str, Any], arrays: dict[str, np.ndarray]) -> ForestHead:
    start = f"{prefix}."
    own = {k[len(start) :]: a for k, a in arrays.items() if k.startswith(start)}
    return ForestHead(forest_from_arrays(params, own))


def save_verifier(model: VerifierModel, path: Path | str) -> Path:
    """Write `model` as a safe verifier file."""
    path = Path(path)
    d = model.detector
    header: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "arms": list(model.arms),
        "config": dataclasses.asdict(d.config),
        "signals": list(d.signals),
        "phases": list(d.phases),
        "trained_on": model.trained_on,
    }
    arrays: dict[str, np.ndarray] = {"thresholds": d.thresholds}
    env = d.models.envelope
    if env is not None:
        header["envelope"] = {"phases": list(env.phases), "bin_s": env.bin_s, "top_k": env.top_k}
        for i, (m, s) in enumerate(zip(env.median, env.scale, strict=True)):
            arrays[f"envelope.{i}.median"] = m
            arrays[f"envelope.{i}.scale"] = s
    nb = d.models.neighbours
    if nb is not None:
        header["neighbours"] = {
            "phases": list(nb.phases),
            "n_trials": nb.n_trials,
            "bin_s": nb.bin_s,
            "tolerance_s": nb.tolerance_s,
            "relative": nb.relative,
            "k": nb.k,
        }
        for i in range(len(nb.phases)):
            arrays[f"neighbours.{i}.elapsed"] = nb.elapsed[i]
            arrays[f"neighbours.{i}.points"] = nb.points[i]
            arrays[f"neighbours.{i}.trial_ids"] = nb.trial_ids[i]
            arrays[f"neighbours.{i}.scale"] = nb.scale[i]
        arrays["neighbours.columns"] = nb.columns
    tm = d.models.timing
    if tm is not None:
        header["timing"] = {"phases": list(tm.phases)}
        arrays.update({"timing.low": tm.low, "timing.high": tm.high, "timing.scale": tm.scale})
    ch = model.characteriser
    if ch is not None:
        failure_header, failure_arrays = _head_parts("failure", ch.failure)
        header["characteriser"] = {
            "phases": list(ch.phases),
            "failure": failure_header,
            "directions": {},
        }
        arrays.update(failure_arrays)
        for axis, head in ch.directions.items():
            h, a = _head_parts(f"direction.{axis}", head)
            header["characteriser"]["directions"][axis] = h
            arrays.update(a)
        header["characteriser"]["contact"] = {}
        for name, head in ch.contact.items():
            h, a = _head_parts(f"contact.{name}", head)
            header["characteriser"]["contact"][name] = h
            arrays.update(a)
        header["characteriser"]["narrow"] = {}
        for axis, head in ch.narrow.items():
            h, a = _head_parts(f"narrow.{axis}", head)
            header["characteriser"]["narrow"][axis] = h
            arrays.update(a)
        header["characteriser"]["signs"] = [[*key, cls] for key, cls in ch.signs.items()]
    write_safe_npz(path, header, arrays)
    return path


def load_verifier(path: Path | str) -> VerifierModel:
    """Read a verifier file; a corrupt, tampered, foreign or wrong-version file is a one-line error."""
    path = Path(path)
    header, arrays = read_safe_npz(path, KIND)
    if header.get("format") != FORMAT:
        raise InputError("not an rcbht verifier file", path, field="format")
    if header.get("format_version") != FORMAT_VERSION:
        raise InputError(
            f"verifier format version {header.get('format_version')!r} is not supported "
            f"(this version reads {FORMAT_VERSION}); retrain with `rcbht verify-train`",
            path,
            field="format_version",
        )
    check_checksum(header, arrays, path, KIND)
    try:
        config = from_mapping(VerifyConfig, header["config"], path=path, prefix="config.")
        try:
            check_verify_config(config)
        except InputError as exc:
            raise InputError(exc.message, path, field=f"config.{exc.field}") from None
        env = None
        if "envelope" in header:
            e = header["envelope"]
            n = len(e["phases"])
            env = EnvelopeModel(
                tuple(e["phases"]),
                [arrays[f"envelope.{i}.median"] for i in range(n)],
                [arrays[f"envelope.{i}.scale"] for i in range(n)],
                float(e["bin_s"]),
                int(e["top_k"]),
            )
        neighbours = None
        if "neighbours" in header:
            nh = header["neighbours"]
            n = len(nh["phases"])
            neighbours = NeighbourModel(
                tuple(nh["phases"]),
                [arrays[f"neighbours.{i}.elapsed"] for i in range(n)],
                [arrays[f"neighbours.{i}.points"] for i in range(n)],
                [arrays[f"neighbours.{i}.trial_ids"] for i in range(n)],
                [arrays[f"neighbours.{i}.scale"] for i in range(n)],
                float(nh["bin_s"]),
                int(nh["n_trials"]),
                float(nh["tolerance_s"]),
                float(nh["relative"]),
                int(nh["k"]),
                arrays["neighbours.columns"],
            )
        timing = None
        if "timing" in header:
            timing = TimingModel(
                tuple(header["timing"]["phases"]),
                arrays["timing.low"],
                arrays["timing.high"],
                arrays["timing.scale"],
            )
        detector = Detector(
            tuple(header["signals"]),
            SignalModels(envelope=env, neighbours=neighbours, timing=timing),
            arrays["thresholds"],
            config,
            tuple(header["phases"]),
        )
        ch = None
        if "characteriser" in header:
            c = header["characteriser"]
            ch = Characteriser(
                tuple(c["phases"]),
                _head("failure", c["failure"], arrays),
                {a: _head(f"direction.{a}", h, arrays) for a, h in c["directions"].items()},
                config,
                {n: _head(f"contact.{n}", h, arrays) for n, h in c["contact"].items()},
                {a: _head(f"narrow.{a}", h, arrays) for a, h in c["narrow"].items()},
                {tuple(str(v) for v in row[:-1]): str(row[-1]) for row in c["signs"]},
            )
            for axis, cols in ch.columns.items():
                head = ch.narrow[axis]
                if not set(head.classes) <= set(ch.directions[axis].classes):
                    raise ValueError(f"the narrow {axis} head names other classes")
                if len(cols) != head.forest.n_features_in_:
                    raise ValueError(f"the narrow {axis} head reads other columns than it names")
            for key, cls in ch.signs.items():
                if len(key) != len(DIRECTION_AXES) or not set(key) <= set(DIRECTIONS):
                    raise ValueError(f"direction signs {list(key)} are not one of -, 0, + per axis")
                if cls not in ch.failure.classes:
                    raise ValueError(f"direction signs name the unknown class {cls!r}")
            width = CONTACT_PER_ARM * len(header["arms"])
            for name, head in ch.contact.items():
                if not config.contact_weights.get(name, 0.0) > 0:
                    raise ValueError(f"a contact forest for {name!r}, which has no contact weight")
                own = ch.failure if name == FAILURE else ch.directions[name]
                if not set(head.classes) <= set(own.classes) or len(head.classes) < 2:
                    raise ValueError(f"the {name} head's contact forest names other classes")
                if head.forest.n_features_in_ != width:
                    raise ValueError(f"the {name} head's contact forest reads other features")
    except (KeyError, TypeError, ValueError, IndexError, OverflowError, AttributeError) as exc:
        raise InputError(f"inconsistent verifier content: {exc}", path) from None
    return VerifierModel(tuple(header["arms"]), detector, ch, dict(header.get("trained_on") or {}))
