"""The recovery table (config/recovery/<task>.yaml): which correction of the held part's pose
each named failure class calls for, within the arm's bounds; one-line errors for a bad table."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError

AXES: tuple[str, ...] = ("x", "y", "z", "yaw")
"""Axes of a correction: x, y, z (m) and yaw (rad) of the held part in the task frame."""
VERDICT_AXES: dict[str, str] = {"x": "x", "y": "y", "r": "yaw"}
"""The verifier's direction axes (verify/labels.py) -> correction axes."""
ANOMALY = "anomaly"
"""The class of an alarm the verifier did not name in time."""
RecoveryAction = Literal["undo_direction", "try", "retry"]


@dataclass(frozen=True)
class Correction:
    """A shift of the held part's believed pose, applied by the arm to a whole attempt."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0

    @classmethod
    def of(cls, values: Mapping[str, float]) -> Correction:
        """From an axis -> value mapping (missing axes 0)."""
        return cls(**{a: float(values.get(a, 0.0)) for a in AXES})

    def get(self, axis: str) -> float:
        return float(getattr(self, axis))

    def values(self) -> tuple[float, float, float, float]:
        return (self.x, self.y, self.z, self.yaw)

    def moved(self, axis: str, by: float) -> Correction:
        """This correction with `by` added on `axis`."""
        return Correction.of({**self.as_dict(), axis: self.get(axis) + by})

    def clipped(self, bounds: Mapping[str, float]) -> Correction:
        """Each axis clipped to +- its bound."""
        return Correction.of(
            {a: max(-bounds[a], min(bounds[a], self.get(a))) for a in AXES if a in bounds}
        )

    def problem(self, bounds: Mapping[str, float]) -> str | None:
        """Why the arm must not run this correction (non-finite, out of bounds), else None."""
        for axis in AXES:
            value = self.get(axis)
            if not math.isfinite(value):
                return f"correction {axis} is not finite ({value})"
            if abs(value) > bounds.get(axis, 0.0) + 1e-12:
                return (
                    f"correction {axis} = {value:g} is beyond its bound {bounds.get(axis, 0.0):g}"
                )
        return None

    def as_dict(self) -> dict[str, float]:
        return {a: self.get(a) for a in AXES}


@dataclass(frozen=True)
class ClassRecovery:
    """What the planner does after an attempt it aborted on one failure class."""

    action: RecoveryAction = "retry"
    """undo_direction: move against the named deviation directions; try: the candidates in
    turn; retry: the same correction again (a knock, an unnamed alarm)."""
    size: dict[str, float] = field(default_factory=dict)
    """undo_direction: the first step per axis (m, rad) where the verifier file has no sizes
    learnt from its labelled deviations."""
    candidates: tuple[dict[str, float], ...] = ()
    """try: corrections (axis -> value) tried in turn, each relative to the correction before."""


@dataclass(frozen=True)
class RecoveryConfig:
    """The reference planner's table and limits for one task."""

    max_attempts: int = 3
    naming_wait_s: float = 1.0
    """After an alarm the planner waits this long for a class; then it aborts as `anomaly`."""
    abort_rate: float = 0.01
    """Share of nominal attempts the planner may abort needlessly: every alarm is an abort, so
    `rcbht closed-loop` calibrates its default verifier to this false-alarm rate."""
    bounds: dict[str, float] = field(
        default_factory=lambda: {"x": 0.008, "y": 0.008, "z": 0.008, "yaw": 0.25}
    )
    """Largest correction per axis (m, rad) the arm may apply; the action server rejects more."""
    search_step: dict[str, float] = field(
        default_factory=lambda: {"x": 0.002, "y": 0.002, "yaw": 0.06}
    )
    """The blind search's grid step per axis (policy `search`)."""
    classes: dict[str, ClassRecovery] = field(default_factory=dict)
    """Failure class -> its recovery; a class `family_dirs` falls back to `family`."""

    def recovery_of(self, failure_class: str) -> ClassRecovery:
        """The class's entry, else its family's (the name before the first `_`), else retry."""
        if failure_class in self.classes:
            return self.classes[failure_class]
        family = failure_class.split("_", 1)[0]
        return self.classes.get(family, ClassRecovery())


def check_recovery(config: RecoveryConfig) -> None:
    """Validation: axes known, bounds and steps positive, at least one attempt."""
    if config.max_attempts < 1:
        raise InputError("need at least one attempt", field="max_attempts")
    if config.naming_wait_s < 0:
        raise InputError("must not be negative", field="naming_wait_s")
    if not 0 < config.abort_rate < 1:
        raise InputError(f"must be in (0, 1), got {config.abort_rate}", field="abort_rate")
    for name, table in (("bounds", config.bounds), ("search_step", config.search_step)):
        _check_axes(table, name, positive=True)
    for cls, entry in config.classes.items():
        _check_axes(entry.size, f"classes.{cls}.size", positive=True)
        for i, candidate in enumerate(entry.candidates):
            _check_axes(candidate, f"classes.{cls}.candidates[{i}]", positive=False)


def _check_axes(table: Mapping[str, float], where: str, positive: bool) -> None:
    for axis, value in table.items():
        if axis not in AXES:
            raise InputError(f"unknown axis {axis!r} (known: {', '.join(AXES)})", field=where)
        if not math.isfinite(value) or (positive and value <= 0):
            raise InputError(f"{axis} must be a finite positive number", field=f"{where}.{axis}")


def load_recovery_config(task: str = "snap", path: Path | str | None = None) -> RecoveryConfig:
    """config/recovery/<task>.yaml (or `path`)."""
    file = path if path is not None else config_path(f"recovery/{task}.yaml")
    return load_config(RecoveryConfig, file, check=check_recovery)
