"""A simulated peg-in-hole trial run attempt by attempt, as sim/episode.py runs the snap task:
the world (the hole's pose error, a failure's yaw, friction, the sensor) is drawn once; each
attempt shifts the plan by a correction (x, y, z) and turns the hand by its yaw."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from rcbht_introspection.sim import arm_run
from rcbht_introspection.sim.episode import AttemptEnd, Pose, SteppedAttempt
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_controller import PegController
from rcbht_introspection.sim.peg_model import GRIP, build_peg_model
from rcbht_introspection.sim.peg_simulate import PegRun, draw_and_run, in_hole, max_duration


@dataclass(frozen=True)
class PegWorld:
    """One peg trial's world, the same for all its attempts."""

    seed: int
    failure: str | None
    run: PegRun
    redraws: int
    as_requested: bool
    """The uncorrected task ends as asked: fails for a failure class, inserts for a nominal."""

    @property
    def failing(self) -> bool:
        return self.failure is not None and self.as_requested

    @property
    def truth(self) -> Pose:
        """The correction that undoes the failure: the hole's yaw (its offset is the search's)."""
        return (0.0, 0.0, 0.0, math.radians(self.run.physics.hole_yaw))


def draw_peg_world(config: PegConfig, seed: int, failure: str | None) -> PegWorld:
    """The world of peg trial `seed`, drawn as `rcbht sim --task peg-in-hole` draws it."""
    run, redraws = arm_run.redraw_until(
        seed, config.max_attempts, lambda rng: _agreeing(config, rng, failure)
    )
    return PegWorld(seed, failure, run[0], redraws, run[1])


def _agreeing(
    config: PegConfig, rng: np.random.Generator, failure: str | None
) -> tuple[tuple[PegRun, bool], bool]:
    run, agrees = draw_and_run(config, rng, failure)
    return (run, agrees), agrees


class PegAttempt(SteppedAttempt):
    """One attempt of a peg world under a correction."""

    def __init__(
        self, config: PegConfig, world: PegWorld, correction: Pose, index: int, rate_hz: float
    ) -> None:
        run = world.run
        cx, cy, cz, cyaw = correction
        sx, sy, sz = run.physics.start_pose
        physics = replace(run.physics, start_pose=(sx + cx, sy + cy, sz + cz))
        self.config, self.plan = config, run.plan
        model = build_peg_model(config, physics)
        rig = arm_run.ServoRig(model, mujoco.MjData(model), yaw=cyaw)
        controller = PegController(config, run.plan)
        super().__init__(
            rig, controller, run.plan.start,
            (config.sensor, run.sensor), (world.seed, index), rate_hz, max_duration(config),
        )  # fmt: skip
        grip, data = model.equality(GRIP).id, rig.data

        def release() -> None:  # once the controller opens the gripper, its weld is off
            if not controller.gripping:
                data.eq_active[grip] = 0

        self.before_step = release

    def _end(self) -> AttemptEnd:
        st = self.controller.state
        inserted = st.seat_time is not None and not st.aborted
        duration = round(self.samples * self.period, 9)
        climb = self.plan.start[2] - (self.offsets[2] + self.data.qpos[self.rig.qz])
        back = 0.0 if inserted else max(0.0, climb) / self.plan.retreat_speed
        return AttemptEnd(
            inserted, "seated" if inserted else self.reason or "unseated",
            in_hole(self.config, self.data), duration, back,
        )  # fmt: skip
