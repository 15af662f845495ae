"""One simulated trial: draw the trial's variation, run MuJoCo with the scripted controller,
pass the recorded wrench through the sensor model, and return a Trial.

The outcome is checked physically (is the male part latched under the hooks at the end?); a draw
whose physical outcome contradicts the requested one is redrawn (counted in metadata["attempts"]).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.config import FailureType, SensorConfig, SimConfig
from rcbht_introspection.sim.controller import (
    ControllerState,
    ControlPlan,
    HolderController,
    SnapController,
)
from rcbht_introspection.sim.failures import (
    PartDeviation,
    deviation_dirs,
    draw_deviation,
    failure_classes,
)
from rcbht_introspection.sim.arm_model import ARM_JOINTS
from rcbht_introspection.sim.model import TrialPhysics, build_model
from rcbht_introspection.sim.onset import (
    NO_ONSET,
    STROKE_END,
    ContactLog,
    Onset,
    TwinWatch,
    contact_onset,
)
from rcbht_introspection.sim.scenario import ScenarioName, get_scenario
from rcbht_introspection.sim.sensor import (
    SensorDraw,
    decimation,
    draw_sensor,
    measure,
    resample,
)

SETTLE_TIME = 0.3
"""Time (s) the arm servos settle under gravity before taring and recording start."""
MAX_DURATION = 80.0
"""Upper bound (s) on one trial; the controller's own time-outs end every trial well before."""


Observer = Callable[[float, str, mujoco.MjModel, mujoco.MjData], None]
"""Called after every physics step with the trial time, the controller's phase, model and data."""


@dataclass(frozen=True)
class PhysicsRun:
    """One physics run: tared tool-frame wrench per step (R columns 0-5, L 6-11), events, outcome."""

    wrench: np.ndarray
    state: ControllerState
    latched: bool


def _uniform(rng: np.random.Generator, r: tuple[float, float]) -> float:
    return float(rng.uniform(r[0], r[1]))


@dataclass(frozen=True)
class TrialDraw:
    """One draw of a trial: its physics, its nominal twin's (the same draw without the failure's
    offset), the controller's set-points, the sensor's errors and the part's deviation."""

    physics: TrialPhysics
    twin: TrialPhysics
    plan: ControlPlan
    sensor: SensorDraw
    deviation: PartDeviation


def draw_trial(
    config: SimConfig, rng: np.random.Generator, failure: FailureType | None
) -> TrialDraw:
    """Sample one trial's physical variation, controller set-points and sensor errors."""
    g, var, fc, cc = config.geometry, config.variation, config.failures, config.controller
    ox, oy, oz = (float(v) for v in rng.normal(0.0, [var.offset_xy, var.offset_xy, var.offset_z]))
    yaw = float(rng.normal(0.0, var.offset_yaw))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    deviation = PartDeviation()
    nominal = (ox, oy, oz, yaw)
    if failure == "misalignment":
        oy = sign * _uniform(rng, fc.misalignment_xy)
    elif failure == "jamming":
        yaw = sign * _uniform(rng, fc.jamming_yaw)
    elif failure == "missed_snap":
        oz = -_uniform(rng, fc.missed_snap_z)
    elif failure is not None and (dirs := deviation_dirs(failure)) is not None:
        deviation = draw_deviation(fc, dirs, rng)
    elif failure is not None:
        known = ", ".join(failure_classes(fc))
        raise InputError(f"unknown failure type {failure!r} (known: {known})", field="failure")
    tilt = _uniform(rng, cc.tilt)
    a = g.male_half + g.clearance
    start_x = a + 0.5 * g.chamfer - g.male_half * math.cos(tilt)
    start_z = g.wall_height + g.male_half * math.sin(tilt) + _uniform(rng, cc.start_height)
    physics = TrialPhysics(
        female_offset=(ox, oy, oz),
        female_yaw=math.degrees(yaw),
        friction_scale=_uniform(rng, var.friction_scale),
        stiffness_scale=_uniform(rng, var.stiffness_scale),
        start_pose=(start_x, 0.0, start_z),
        part_offset=(deviation.x, deviation.y, deviation.yaw),
    )
    plan = ControlPlan(
        start=(start_x, 0.0, start_z),
        tilt=tilt,
        approach_speed=_uniform(rng, cc.approach_speed),
        rotation_speed=_uniform(rng, cc.rotation_speed),
        rotation_force=_uniform(rng, cc.rotation_force),
        insertion_force_rate=_uniform(rng, cc.insertion_force_rate),
        hold_force=_uniform(rng, cc.hold_force),
        hold_time=_uniform(rng, cc.hold_time),
        retract_speed=_uniform(rng, cc.retract_speed),
        retract_lateral=(_uniform(rng, cc.retract_lateral), _uniform(rng, cc.retract_lateral)),
        ripple_seed=int(rng.integers(0, 2**31)),
    )
    sensor = draw_sensor(config.sensor, rng, var.bias_force, var.bias_torque, var.noise_scale)
    twin = replace(
        physics,
        female_offset=nominal[:3],
        female_yaw=math.degrees(nominal[3]),
        part_offset=(0.0, 0.0, 0.0),
    )
    return TrialDraw(physics, twin, plan, sensor, deviation)


def run_physics(
    config: SimConfig,
    physics: TrialPhysics,
    plan: ControlPlan,
    two_arm: bool,
    trace: list[tuple[float, ...]] | None = None,
    observer: Observer | None = None,
) -> PhysicsRun:
    """Run the controller on the model; return the tared wrench per physics step and the events."""
    model = build_model(config, physics, two_arm)
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    r_qadr = [model.joint(f"r_{n}").qposadr[0] for n in ARM_JOINTS]
    r_act = [model.actuator(f"r_{n}").id for n in ARM_JOINTS]
    l_act = [model.actuator(f"l_{n}").id for n in ARM_JOINTS] if two_arm else []
    data.qpos[r_qadr[4]] = plan.tilt
    data.ctrl[r_act[4]] = plan.tilt
    for _ in range(int(SETTLE_TIME / model.opt.timestep)):
        mujoco.mj_step(model, data)  # let the servos take the weight before the sensor is tared
    controller = SnapController(config, plan)
    if trace is not None:
        controller.trace = trace
    holder = HolderController(config) if two_arm else None
    sx, sy, sz = plan.start
    nsens = model.nsensordata
    max_steps = int(MAX_DURATION / dt)
    raw = np.empty((max_steps, nsens))
    tare = data.sensordata.copy()
    lz_sensor = 8
    qz = r_qadr[2]
    ra = r_act
    step = 0
    sensordata = data.sensordata
    qpos = data.qpos
    ctrl = data.ctrl
    while step < max_steps and not controller.done:
        t = step * dt
        u = controller.update(
            t,
            dt,
            tare[0] - sensordata[0],
            tare[1] - sensordata[1],
            tare[2] - sensordata[2],
            sz + qpos[qz],
        )
        ctrl[ra[0]] = u[0] - sx
        ctrl[ra[1]] = u[1] - sy
        ctrl[ra[2]] = u[2] - sz
        ctrl[ra[3]] = u[3]
        ctrl[ra[4]] = u[4]
        ctrl[ra[5]] = u[5]
        if holder is not None:
            lu = holder.update(dt, tare[lz_sensor] - sensordata[lz_sensor])
            ctrl[l_act[2]] = lu[2]
        mujoco.mj_step(model, data)
        raw[step] = sensordata
        if observer is not None:
            observer(t + dt, controller.state.phase, model, data)
        step += 1
    raw = raw[:step]
    # tool-frame convention: the wrench the part exerts on the sensor (compression: +Fz), tared
    wrench = tare[None, :] - raw
    return PhysicsRun(wrench=wrench, state=controller.state, latched=_latched(config, model, data))


def _latched(config: SimConfig, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
    """True when the male's shoulder is below the hooks' retention face, inside the housing."""
    g = config.geometry
    male = data.body("male").xpos
    female = data.body("female").xpos
    shoulder = male[2] + g.male_lower_height
    hook = female[2] + g.male_lower_height + g.hook_play
    lateral = math.hypot(male[0] - female[0], male[1] - female[1])
    return bool(shoulder < hook - 1e-4 and lateral < g.hook_depth)


def failure_onset(
    config: SimConfig,
    draw: TrialDraw,
    two_arm: bool,
    state: ControllerState,
    log: ContactLog,
) -> Onset:
    """The failure's onset (sim/onset.py): the first moment its contacts differ from the
    nominal twin's (the twin runs up to that moment), else the planned stroke's end when the part
    never seated there (the controller then takes the snap for done), else none (time None)."""
    watch = TwinWatch(config, log)
    onset = contact_onset(
        lambda: run_physics(config, draw.twin, draw.plan, two_arm, observer=watch), watch
    )
    if onset is not None:
        return onset
    if state.stroke_time is not None and state.seat_time is None:
        return Onset(state.stroke_time, STROKE_END)
    return Onset(None, NO_ONSET)


def simulate_trial(
    config: SimConfig,
    seed: int,
    scenario: ScenarioName = "one-arm",
    failure: FailureType | None = None,
    rate_hz: float = 200.0,
    name: str | None = None,
) -> Trial:
    """Simulate one trial (deterministic for `seed`); `failure` None means a successful assembly."""
    scen = get_scenario(scenario)
    k = decimation(rate_hz, config.physics.timestep)
    attempts = 0
    watched = failure is not None
    while True:
        rng = np.random.default_rng([int(seed), attempts])
        draw = draw_trial(config, rng, failure)
        log = ContactLog(config) if watched else None
        result = run_physics(config, draw.physics, draw.plan, scen.two_arm, observer=log)
        attempts += 1
        latched = result.latched
        consistent = latched if failure is None else not latched
        if consistent or attempts >= config.failures.max_attempts:
            break
    sensor = draw.sensor
    state = result.state
    raw = result.wrench
    samples = resample(raw, k)
    period = 1.0 / rate_hz
    time = np.round(np.arange(len(samples)) * period, 9)
    wrench: dict[str, np.ndarray] = {}
    sensor_rng = np.random.default_rng([int(seed), attempts, 7])
    for arm in scen.arms:
        cols = slice(0, 6) if arm == "R" else slice(6, 12)
        errors = sensor if arm == "R" else _other_sensor(sensor, config.sensor, sensor_rng)
        wrench[arm] = measure(samples[:, cols], time, config.sensor, errors, sensor_rng)
    state_times = tuple(round(round(t / period) * period, 9) for t in state.switch_times)
    if failure is None:
        outcome = "success" if latched else "failure"
    else:
        outcome = failure if not latched else "success"
    failed = failure is not None and not latched
    onset = (
        failure_onset(config, draw, scen.two_arm, result.state, log)
        if failed and log is not None
        else None
    )
    metadata: dict[str, object] = {
        "seed": int(seed),
        "scenario": scenario,
        "requested": failure or "success",
        "attempts": attempts,
        "latched": latched,
        "rate_hz": rate_hz,
        "snap_time": state.snap_time,
        "peak_force": round(float(state.peak_force), 4),
        "aborted": state.aborted,
        "female_offset": [round(v, 6) for v in draw.physics.female_offset],
        "female_yaw_deg": round(draw.physics.female_yaw, 4),
        "friction_scale": round(draw.physics.friction_scale, 4),
        "stiffness_scale": round(draw.physics.stiffness_scale, 4),
        "tilt": round(draw.plan.tilt, 5),
    }
    if failure is not None and onset is not None:
        metadata["failure"] = {
            "class": failure,
            "onset": None if onset.time is None else round(round(onset.time / period) * period, 9),
            "onset_rule": onset.rule,
            "onset_contact": onset.contact,
            "deviation": draw.deviation.to_dict() if deviation_dirs(failure) else None,
        }
    return Trial(
        name=name or f"sim-{scenario}-{seed}",
        time=time,
        wrench=wrench,
        state_times=state_times,
        outcome=outcome,
        metadata=metadata,
    )


def _other_sensor(draw: SensorDraw, config: SensorConfig, rng: np.random.Generator) -> SensorDraw:
    """The second arm's sensor: its own bias and drift with the same error magnitudes."""
    return SensorDraw(
        bias=draw.bias[rng.permutation(6)],
        drift=draw.drift[rng.permutation(6)],
        drift_period=float(rng.uniform(*config.drift_period)),
        drift_phase=float(rng.uniform(0.0, 2 * math.pi)),
        noise_scale=draw.noise_scale,
    )
