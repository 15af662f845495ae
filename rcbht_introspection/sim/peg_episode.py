"""A simulated peg-in-hole trial run attempt by attempt, as sim/episode.py runs the snap task:
the world (the hole's pose error, a failure's yaw, friction, the sensor) is drawn once; each
attempt shifts the plan by a correction (x, y, z) and turns the hand by its yaw."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from rcbht_introspection.sim import arm_run
from rcbht_introspection.sim.episode import Pose, SteppedAttempt, TrialWorld, corrected_start
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_controller import PegController
from rcbht_introspection.sim.peg_model import GRIP, build_peg_model
from rcbht_introspection.sim.peg_simulate import PegRun, draw_and_run, in_hole, max_duration


@dataclass(frozen=True)
class PegWorld(TrialWorld):
    """One peg trial's world, the same for all its attempts."""

    run: PegRun

    @property
    def truth(self) -> Pose:
        """The correction that undoes the failure: the hole's yaw (its offset is the search's)."""
        return (0.0, 0.0, 0.0, math.radians(self.run.physics.hole_yaw))


def draw_peg_world(config: PegConfig, seed: int, failure: str | None) -> PegWorld:
    """The world of peg trial `seed`, drawn as `rcbht sim --task peg-in-hole` draws it."""
    run, redraws = arm_run.redraw_until(
        seed, config.max_attempts, lambda rng: _agreeing(config, rng, failure)
    )
    return PegWorld(seed, failure, redraws, run[1], run=run[0])


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
        physics = replace(
            run.physics, start_pose=corrected_start(run.physics.start_pose, correction)
        )
        self.config, self.plan = config, run.plan
        model = build_peg_model(config, physics)
        rig = arm_run.ServoRig(model, mujoco.MjData(model), yaw=correction[3])
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

    def _in_place(self) -> bool:
        return in_hole(self.config, self.data)

    def _return_speed(self) -> float:
        return self.plan.retreat_speed
