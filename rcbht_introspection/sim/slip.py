"""Slow slips: the held part slides in the hand over seconds during a contact sub-task.

A slip starts a random delay into a randomly chosen contact sub-task and grows linearly over its
duration to a size of the deviation classes' ranges, along one signed axis (x, y or yaw). The
part sliding in the hand loads the housing as the hand moving by the same amount would, so the
slip moves the arm's servo targets (in the task frame; a correction of the same size undoes
it). Its onset is the slip's start; its deviation record is its final size.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from rcbht_introspection.sim.arm_config import Range, SlipConfig
from rcbht_introspection.sim.arm_run import PhaseTrigger, disturbance_record

SLIP = "slip"
"""The failure family of a part sliding in the hand (`failures.types` of the snap task)."""
SLIP_AXES = ("x", "y", "yaw")


@dataclass(frozen=True)
class Slip:
    """Where, when, how far and how fast the part slides."""

    phase: str
    delay: float
    """Seconds into the sub-task before it starts (at the sub-task's end if sooner)."""
    duration: float
    axis: str
    size: float
    """Final offset along `axis` (m, or rad for yaw), signed."""

    def deviation(self) -> dict[str, float]:
        """The `deviation` record of its label: the final offset."""
        return {a: round(self.size if a == self.axis else 0.0, 6) for a in SLIP_AXES}


def draw_slip(
    config: SlipConfig,
    phases: Sequence[str],
    sizes: tuple[Range, Range],
    rng: np.random.Generator,
) -> Slip:
    """A slip in one of `phases`, along one axis, its size in `sizes` (x and y, yaw)."""
    phase = phases[int(rng.integers(len(phases)))]
    axis = SLIP_AXES[int(rng.integers(len(SLIP_AXES)))]
    sign = 1.0 if rng.random() < 0.5 else -1.0
    size = sign * float(rng.uniform(*(sizes[1] if axis == "yaw" else sizes[0])))
    return Slip(
        phase=phase,
        delay=float(rng.uniform(*config.delay)),
        duration=float(rng.uniform(*config.duration)),
        axis=axis,
        size=size,
    )


class SlipRun:
    """Moves the servo targets as the part slides: call `update` after each physics step with
    the time reached and the phase running, then `apply` after the controller set the targets."""

    def __init__(self, slip: Slip, data: mujoco.MjData, actuators: Sequence[int]) -> None:
        self.slip = slip
        self.data = data
        self.actuator = actuators[{"x": 0, "y": 1, "yaw": 3}[slip.axis]]
        """A slip of +d is the hand moved by +d along the axis: that servo's target rises by d."""
        self.trigger = PhaseTrigger(slip.phase, slip.delay)
        self.offset = 0.0

    @property
    def onset(self) -> float | None:
        """When the part started to slide (None: not yet)."""
        return self.trigger.fired

    def update(self, t: float, phase: str) -> None:
        """Advance the slip to time `t`."""
        if (onset := self.trigger.update(t, phase)) is not None:
            share = min(1.0, (t - onset) / self.slip.duration)
            self.offset = share * self.slip.size

    def apply(self) -> None:
        """Add the slip so far to the servo's target (before the physics step)."""
        self.data.ctrl[self.actuator] += self.offset


def slip_record(slip: Slip, onset: float, rate_hz: float) -> dict[str, object]:
    """meta.json's failure entry of a slip: its onset on the sample clock and final offset."""
    return disturbance_record(
        SLIP,
        onset,
        rate_hz,
        "slip_start",
        deviation=slip.deviation(),
        phase=slip.phase,
        duration_s=round(slip.duration, 4),
    )
