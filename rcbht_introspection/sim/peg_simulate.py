"""One simulated peg-in-hole trial: draw the trial's variation, run MuJoCo with the scripted
controller, pass the wrench through the sensor model, and return a Trial named by PEG_TASK.

The outcome is checked physically (is the peg in the hole at the end?); a draw that ends
otherwise is redrawn, up to max_attempts (counted in metadata["attempts"]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import arm_run
from rcbht_introspection.sim.arm_run import Wrench, uniform
from rcbht_introspection.sim.collision import (
    COLLISION,
    Collision,
    CollisionRun,
    collision_record,
    draw_collision,
)
from rcbht_introspection.sim.peg_config import PEG_FAILURES, PegConfig
from rcbht_introspection.sim.peg_controller import PEG_TASK, PegController, PegPlan, PegState
from rcbht_introspection.sim.peg_model import GRIP, PegPhysics, build_peg_model
from rcbht_introspection.sim.sensor import SensorDraw, decimation, draw_sensor, measure

DEPARTURE_NOISE = 3.0
"""A failure's onset: its wrench departs from its twin's by this many times the sensor's noise."""
WRENCH_DEPARTURE = "wrench_departure"
"""The onset rule of the peg task's failures."""
BOUND_SLACK = 1.0
"""Time (s) added to the sum of the phases' bounds (each may overrun its bound by a step)."""
PLAN_DRAWS: tuple[str, ...] = (
    "reach_speed",
    "search_force",
    "search_speed",
    "spiral_angle",
    "insert_force",
    "insert_speed",
    "seat_settle",
    "release_pause",
    "retreat_speed",
    "retreat_time",
)
"""The plan's set-points drawn, in order, from the controller config's ranges of the same names
(the spiral's start direction from a whole turn)."""


def draw_peg_trial(
    config: PegConfig, rng: np.random.Generator
) -> tuple[PegPhysics, PegPlan, SensorDraw]:
    """Sample one trial's hole pose error, friction, controller set-points and sensor errors
    (a failure's error is drawn after them: draw_peg_failure)."""
    var, cc = config.variation, config.controller
    # a point on a square of Chebyshev radius rho: beyond the chamfer's capture in x or y
    rho = uniform(rng, var.hole_offset)
    angle = float(rng.uniform(0.0, 2 * math.pi))
    norm = max(abs(math.cos(angle)), abs(math.sin(angle)))
    ox, oy = rho * math.cos(angle) / norm, rho * math.sin(angle) / norm
    oz = float(rng.normal(0.0, var.offset_z))
    yaw = float(rng.normal(0.0, var.offset_yaw))
    start = (0.0, 0.0, uniform(rng, cc.start_height))
    physics = PegPhysics(
        hole_offset=(ox, oy, oz),
        hole_yaw=math.degrees(yaw),
        friction_scale=uniform(rng, var.friction_scale),
        start_pose=start,
    )
    set_points = arm_run.draw_set_points(rng, cc, PLAN_DRAWS, spiral_angle=(0.0, 2 * math.pi))
    plan = PegPlan(start=start, **set_points, ripple_seed=arm_run.draw_seed(rng))
    sensor = draw_sensor(config.sensor, rng, var.bias_force, var.bias_torque, var.noise_scale)
    return physics, plan, sensor


def draw_peg_failure(
    config: PegConfig, physics: PegPhysics, failure: str, rng: np.random.Generator
) -> tuple[PegPhysics, float]:
    """The trial's physics with the failure's error added, and that error's yaw (rad): the
    hole turned by a size in `failures.hole_yaw`, either way."""
    if failure not in PEG_FAILURES or failure == COLLISION:
        known = ", ".join(PEG_FAILURES)
        raise InputError(f"unknown failure type {failure!r} (known: {known})", field="failure")
    sign = 1.0 if rng.random() < 0.5 else -1.0
    yaw = sign * uniform(rng, config.failures.hole_yaw)
    return replace(physics, hole_yaw=physics.hole_yaw + math.degrees(yaw)), yaw


def max_duration(config: PegConfig) -> float:
    """Upper bound (s) of one trial: every phase at its time-out or longest draw."""
    c = config.controller
    return (
        c.reach_timeout
        + c.search_timeout
        + c.insert_timeout
        + c.seat_settle[1]
        + c.release_pause[1]
        + c.retreat_time[1]
        + BOUND_SLACK
    )


def run_peg_physics(
    config: PegConfig, physics: PegPhysics, plan: PegPlan, collision: Collision | None = None
) -> tuple[Wrench, PegState, bool, float | None]:
    """Run the controller on the model (a collision's pushes struck on the peg): the tared
    tool-frame wrench per physics step (N, 6), the controller's events, whether the peg ends in
    the hole and when the collision struck (None: no collision, or it never struck)."""
    model = build_peg_model(config, physics)
    data = mujoco.MjData(model)
    rig = arm_run.ServoRig(model, data)
    controller = PegController(config, plan)
    max_steps = int(max_duration(config) / rig.dt)
    release = _gripper_release(controller, model, data)
    strike = CollisionRun(collision, data, "peg") if collision is not None else None

    def after(t: float) -> None:
        if strike is not None:
            strike.update(t, controller.state.phase)

    wrench = rig.run(controller, plan.start, max_steps, release, after if strike else None)
    onset = strike.onset if strike is not None else None
    return wrench, controller.state, in_hole(config, data), onset


def _gripper_release(
    controller: PegController, model: mujoco.MjModel, data: mujoco.MjData
) -> arm_run.StepHook:
    """Before each physics step: once the controller opens the gripper, its weld is off."""
    grip = model.equality(GRIP).id

    def release() -> None:
        if not controller.gripping:
            data.eq_active[grip] = 0

    return release


def in_hole(config: PegConfig, data: mujoco.MjData) -> bool:
    """True when the peg's tip lies near the hole's floor, inside the hole."""
    g = config.geometry
    peg = data.body("peg").xpos
    block = data.body("block").xpos
    tip = peg[2] - g.peg_length / 2
    floor = block[2] - g.hole_depth
    lateral = max(abs(peg[0] - block[0]), abs(peg[1] - block[1]))
    return bool(tip < floor + g.chamfer and lateral < g.clearance + 1e-4)


@dataclass(frozen=True)
class PegRun:
    """One draw of a peg trial and its physics: the failure's yaw error (0 for a nominal)."""

    physics: PegPhysics
    twin: PegPhysics
    """The same draw without the failure's error."""
    plan: PegPlan
    sensor: SensorDraw
    raw: Wrench
    state: PegState
    inserted: bool
    failure_yaw: float
    collision: Collision | None = None
    struck: float | None = None
    """When the collision's first push started (s)."""


def draw_and_run(
    config: PegConfig, rng: np.random.Generator, failure: str | None = None
) -> tuple[PegRun, bool]:
    """One attempt at a trial: draw it and run its physics; it agrees when the peg ended in the
    hole without an abort (for a nominal trial), or did not (for a failure)."""
    physics, plan, sensor = draw_peg_trial(config, rng)
    twin, yaw, collision = physics, 0.0, None
    if failure == COLLISION:
        collision = draw_collision(config.failures.collision, PEG_TASK.subtasks[:3], rng)
    elif failure is not None:
        physics, yaw = draw_peg_failure(config, physics, failure, rng)
    raw, state, inserted, struck = run_peg_physics(config, physics, plan, collision)
    run = PegRun(physics, twin, plan, sensor, raw, state, inserted, yaw, collision, struck)
    if collision is not None:  # struck: a failure whether or not the peg still goes in
        return run, struck is not None
    return run, (inserted and not state.aborted) == (failure is None)


def departure_onset(config: PegConfig, run: PegRun) -> float | None:
    """Where a failure first shows: the first physics step at which its wrench departs from its
    nominal twin's by more than DEPARTURE_NOISE x the sensor's noise on any axis (None: never)."""
    twin, _, _, _ = run_peg_physics(config, run.twin, run.plan)
    n = min(len(twin), len(run.raw))
    noise = config.sensor
    limit = DEPARTURE_NOISE * np.array([noise.noise_force] * 3 + [noise.noise_torque] * 3)
    apart = np.flatnonzero((np.abs(run.raw[:n] - twin[:n]) > limit).any(axis=1))
    return float(apart[0] + 1) * config.physics.timestep if len(apart) else None


def _failure_record(
    config: PegConfig, failure: str, run: PegRun, period: float
) -> dict[str, object]:
    """meta.json's failure entry: the class, its onset on the sample clock and the hole's error
    as the peg's against it (the yaw negated), as the snap task records a deviation."""
    onset = departure_onset(config, run)
    return {
        "class": failure,
        "onset": None if onset is None else arm_run.on_clock(onset, period),
        "onset_rule": "none" if onset is None else WRENCH_DEPARTURE,
        "deviation": {"x": 0.0, "y": 0.0, "yaw": round(-run.failure_yaw, 6)},
    }


def _peg_metadata(
    seed: int,
    attempts: int,
    rate: float,
    run: PegRun,
    failure: str | None,
) -> dict[str, object]:
    """meta.json of a peg-in-hole trial: its task, the attempts, the outcome and the draw."""
    physics, state = run.physics, run.state
    return {
        "seed": int(seed),
        "task": PEG_TASK.to_dict(),
        "scenario": "one-arm",
        "requested": failure or "success",
        "attempts": attempts,
        "inserted": run.inserted,
        "aborted": state.aborted,
        "rate_hz": rate,
        "hole_offset": [round(v, 6) for v in physics.hole_offset],
        "hole_yaw_deg": round(physics.hole_yaw, 4),
        "friction_scale": round(physics.friction_scale, 4),
        "noise_scale": round(run.sensor.noise_scale, 4),
    }


def simulate_peg_trial(
    config: PegConfig,
    seed: int,
    rate_hz: float | None = None,
    name: str | None = None,
    failure: str | None = None,
) -> Trial:
    """Simulate one peg-in-hole trial (deterministic for `seed`) at the sensor's rate (default
    the config's); `failure` None means a successful insertion."""
    rate = config.sensor.rate_hz if rate_hz is None else rate_hz
    k = decimation(rate, config.physics.timestep)
    run, attempts = arm_run.redraw_until(
        seed, config.max_attempts, lambda rng: draw_and_run(config, rng, failure)
    )
    noise = arm_run.sensor_rng(seed, attempts)
    ok = run.inserted and not run.state.aborted
    metadata = _peg_metadata(seed, attempts, rate, run, failure)
    outcome = "success" if ok else failure or "failure"
    if run.collision is not None and run.struck is not None:
        outcome = COLLISION
        metadata["failure"] = collision_record(run.collision, run.struck, rate)
    elif failure is not None and not ok:
        metadata["failure"] = _failure_record(config, failure, run, 1.0 / rate)
    return arm_run.sensor_trial(
        name or f"sim-peg-{seed}",
        run.raw,
        k,
        rate,
        lambda samples, time: {"R": measure(samples, time, config.sensor, run.sensor, noise)},
        run.state.switch_times,
        outcome,
        metadata,
        run.state.phases,
    )
