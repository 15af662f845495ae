"""One simulated peg-in-hole trial: draw the trial's variation, run MuJoCo with the scripted
controller, pass the wrench through the sensor model, and return a Trial named by PEG_TASK.

The outcome is checked physically (is the peg in the hole at the end?); a draw that ends
otherwise is redrawn, up to max_attempts (counted in metadata["attempts"]).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.arm_model import ARM_JOINTS
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_controller import PEG_TASK, PegController, PegPlan, PegState
from rcbht_introspection.sim.peg_model import GRIP, PegPhysics, build_peg_model
from rcbht_introspection.sim.sensor import SensorDraw, decimation, draw_sensor, measure, resample
from rcbht_introspection.sim.simulate import SETTLE_TIME

BOUND_SLACK = 1.0
"""Time (s) added to the sum of the phases' bounds (each may overrun its bound by a step)."""


def _uniform(rng: np.random.Generator, r: tuple[float, float]) -> float:
    return float(rng.uniform(r[0], r[1]))


def draw_peg_trial(
    config: PegConfig, rng: np.random.Generator
) -> tuple[PegPhysics, PegPlan, SensorDraw]:
    """Sample one trial's hole pose error, friction, controller set-points and sensor errors."""
    var, cc = config.variation, config.controller
    # a point on a square of Chebyshev radius rho: beyond the chamfer's capture in x or y
    rho = _uniform(rng, var.hole_offset)
    angle = float(rng.uniform(0.0, 2 * math.pi))
    norm = max(abs(math.cos(angle)), abs(math.sin(angle)))
    ox, oy = rho * math.cos(angle) / norm, rho * math.sin(angle) / norm
    oz = float(rng.normal(0.0, var.offset_z))
    yaw = float(rng.normal(0.0, var.offset_yaw))
    start = (0.0, 0.0, _uniform(rng, cc.start_height))
    physics = PegPhysics(
        hole_offset=(ox, oy, oz),
        hole_yaw=math.degrees(yaw),
        friction_scale=_uniform(rng, var.friction_scale),
        start_pose=start,
    )
    plan = PegPlan(
        start=start,
        reach_speed=_uniform(rng, cc.reach_speed),
        search_force=_uniform(rng, cc.search_force),
        search_speed=_uniform(rng, cc.search_speed),
        spiral_angle=float(rng.uniform(0.0, 2 * math.pi)),
        insert_force=_uniform(rng, cc.insert_force),
        insert_speed=_uniform(rng, cc.insert_speed),
        seat_settle=_uniform(rng, cc.seat_settle),
        release_pause=_uniform(rng, cc.release_pause),
        retreat_speed=_uniform(rng, cc.retreat_speed),
        retreat_time=_uniform(rng, cc.retreat_time),
        ripple_seed=int(rng.integers(0, 2**31)),
    )
    sensor = draw_sensor(config.sensor, rng, var.bias_force, var.bias_torque, var.noise_scale)
    return physics, plan, sensor


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
    config: PegConfig, physics: PegPhysics, plan: PegPlan
) -> tuple[np.ndarray, PegState, bool]:
    """Run the controller on the model: the tared tool-frame wrench per physics step (N, 6),
    the controller's events, and whether the peg ends in the hole."""
    model = build_peg_model(config, physics)
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    qadr = [model.joint(f"r_{n}").qposadr[0] for n in ARM_JOINTS]
    act = [model.actuator(f"r_{n}").id for n in ARM_JOINTS]
    grip = model.equality(GRIP).id
    for _ in range(int(SETTLE_TIME / dt)):
        mujoco.mj_step(model, data)  # the servos take the weight before the sensor is tared
    controller = PegController(config, plan)
    sx, sy, sz = plan.start
    offsets = (sx, sy, sz, 0.0, 0.0, 0.0)
    max_steps = int(max_duration(config) / dt)
    raw = np.empty((max_steps, model.nsensordata))
    tare = data.sensordata.copy()
    sensordata, qpos, ctrl = data.sensordata, data.qpos, data.ctrl
    qz = qadr[2]
    step = 0
    while step < max_steps and not controller.done:
        u = controller.update(
            step * dt,
            dt,
            tare[0] - sensordata[0],
            tare[1] - sensordata[1],
            tare[2] - sensordata[2],
            sz + qpos[qz],
        )
        for i in range(6):
            ctrl[act[i]] = u[i] - offsets[i]
        if not controller.gripping:
            data.eq_active[grip] = 0
        mujoco.mj_step(model, data)
        raw[step] = sensordata
        step += 1
    # tool-frame convention: the wrench the peg exerts on the sensor (compression: +Fz), tared
    wrench = tare[None, :] - raw[:step]
    return wrench, controller.state, _in_hole(config, data)


def _in_hole(config: PegConfig, data: mujoco.MjData) -> bool:
    """True when the peg's tip lies near the hole's floor, inside the hole."""
    g = config.geometry
    peg = data.body("peg").xpos
    block = data.body("block").xpos
    tip = peg[2] - g.peg_length / 2
    floor = block[2] - g.hole_depth
    lateral = max(abs(peg[0] - block[0]), abs(peg[1] - block[1]))
    return bool(tip < floor + g.chamfer and lateral < g.clearance + 1e-4)


def simulate_peg_trial(
    config: PegConfig, seed: int, rate_hz: float | None = None, name: str | None = None
) -> Trial:
    """Simulate one peg-in-hole trial (deterministic for `seed`) at the sensor's rate (default
    the config's)."""
    rate = config.sensor.rate_hz if rate_hz is None else rate_hz
    k = decimation(rate, config.physics.timestep)
    attempts = 0
    while True:
        rng = np.random.default_rng([int(seed), attempts])
        physics, plan, sensor = draw_peg_trial(config, rng)
        raw, state, inserted = run_peg_physics(config, physics, plan)
        attempts += 1
        if (inserted and not state.aborted) or attempts >= config.max_attempts:
            break
    samples = resample(raw, k)
    period = 1.0 / rate
    time = np.round(np.arange(len(samples)) * period, 9)
    sensor_rng = np.random.default_rng([int(seed), attempts, 7])
    wrench = {"R": measure(samples, time, config.sensor, sensor, sensor_rng)}
    state_times = tuple(round(round(t / period) * period, 9) for t in state.switch_times)
    metadata: dict[str, object] = {
        "seed": int(seed),
        "task": PEG_TASK.to_dict(),
        "scenario": "one-arm",
        "requested": "success",
        "attempts": attempts,
        "inserted": inserted,
        "aborted": state.aborted,
        "rate_hz": rate,
        "hole_offset": [round(v, 6) for v in physics.hole_offset],
        "hole_yaw_deg": round(physics.hole_yaw, 4),
        "friction_scale": round(physics.friction_scale, 4),
        "noise_scale": round(sensor.noise_scale, 4),
    }
    return Trial(
        name=name or f"sim-peg-{seed}",
        time=time,
        wrench=wrench,
        state_times=state_times,
        outcome="success" if inserted and not state.aborted else "failure",
        metadata=metadata,
        phases=state.phases,
    )
