"""Failure classes of the snap-assembly simulator: the families of config/sim.yaml and the
deviation classes (the held part slipped in the hand by a signed x, y and/or yaw offset)."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.sim.config import FailureConfig, FailureType, SimConfig

DEVIATION = "deviation"
DEVIATION_AXES: tuple[str, ...] = ("x", "y", "r")
"""Deviation axes in the order a class names them: x, y (m) and r (yaw, rad)."""
_DIRS = re.compile(r"(x[+-])?(y[+-])?(r[+-])?")


@dataclass(frozen=True)
class PartDeviation:
    """The held part's slip in the hand: x, y (m) and yaw (rad), unknown to the controller."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """The `deviation` record of metadata["failure"]."""
        return {"x": round(self.x, 6), "y": round(self.y, 6), "yaw": round(self.yaw, 6)}


def deviation_signs(dirs: str) -> dict[str, int]:
    """Axis -> sign (+1/-1) of a deviation class such as `x+y-` (axes in order x, y, r)."""
    match = _DIRS.fullmatch(dirs)
    if not dirs or match is None:
        raise InputError(
            f"bad deviation class {dirs!r}: signed axes in the order x, y, r, e.g. x+, y-r+",
            field="deviation_classes",
        )
    return {part[0]: 1 if part[1] == "+" else -1 for part in match.groups() if part}


def deviation_dirs(failure: FailureType) -> str | None:
    """The directions of a deviation class name (`deviation_x+` -> `x+`), else None."""
    prefix = f"{DEVIATION}_"
    return failure[len(prefix) :] if failure.startswith(prefix) else None


def failure_classes(failures: FailureConfig) -> tuple[FailureType, ...]:
    """Every failure class of the config, in cycle order: the families, `deviation` expanded
    into one class per configured direction set."""
    out: list[FailureType] = []
    for family in failures.types:
        if family == DEVIATION:
            out.extend(f"{DEVIATION}_{dirs}" for dirs in failures.deviation_classes)
        else:
            out.append(family)
    return tuple(out)


def check_failures(config: SimConfig) -> None:
    """Validation of the failure section: well-formed, distinct deviation classes."""
    classes = config.failures.deviation_classes
    for i, dirs in enumerate(classes):
        try:
            deviation_signs(dirs)
        except InputError as exc:
            raise InputError(exc.message, field=f"failures.deviation_classes[{i}]") from None
        if dirs in classes[:i]:
            raise InputError(
                f"deviation class {dirs!r} listed twice", field=f"failures.deviation_classes[{i}]"
            )
    if DEVIATION in config.failures.types and not classes:
        raise InputError("deviation needs at least one class", field="failures.deviation_classes")


def draw_deviation(failures: FailureConfig, dirs: str, rng: np.random.Generator) -> PartDeviation:
    """Sizes of a deviation class drawn uniformly in the configured ranges, with its signs."""
    signs = deviation_signs(dirs)
    size = {
        axis: float(
            rng.uniform(*(failures.deviation_yaw if axis == "r" else failures.deviation_xy))
        )
        for axis in DEVIATION_AXES
    }
    return PartDeviation(
        x=signs.get("x", 0) * size["x"],
        y=signs.get("y", 0) * size["y"],
        yaw=signs.get("r", 0) * size["r"],
    )
