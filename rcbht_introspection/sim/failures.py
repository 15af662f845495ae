"""Failure classes of the snap-assembly simulator: the families of config/sim/snap.yaml and the
deviation classes (the held part slipped in the hand by a signed x, y and/or yaw offset)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rcbht_introspection.sim.config import (  # the class vocabulary lives with the config
    DEVIATION,
    DEVIATION_AXES,
    FailureConfig,
    check_failures,
    deviation_dirs,
    deviation_signs,
    failure_classes,
)

__all__ = [
    "DEVIATION",
    "DEVIATION_AXES",
    "PartDeviation",
    "check_failures",
    "deviation_dirs",
    "deviation_signs",
    "draw_deviation",
    "failure_classes",
]


@dataclass(frozen=True)
class PartDeviation:
    """The held part's offset against the housing, x, y (m) and yaw (rad), unknown to the
    controller: a slip in the hand, or the housing's own offset negated."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """The `deviation` record of metadata["failure"]."""
        return {"x": round(self.x, 6), "y": round(self.y, 6), "yaw": round(self.yaw, 6)}


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
