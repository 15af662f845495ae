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
from numpy.typing import NDArray

from rcbht_introspection.errors import InputError
from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim import arm_run
from rcbht_introspection.sim.arm_config import SensorConfig
from rcbht_introspection.sim.arm_run import Wrench, uniform
from rcbht_introspection.sim.collision import (
    COLLISION,
    Collision,
    CollisionRun,
    collision_record,
    draw_collision,
)
from rcbht_introspection.sim.config import FailureType, SimConfig
from rcbht_introspection.sim.controller import (
    SLIP_PHASES,
    STRUCK_PHASES,
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
from rcbht_introspection.sim.sensor import SensorDraw, decimation, draw_sensor, measure
from rcbht_introspection.sim.slip import SLIP, Slip, SlipRun, draw_slip, slip_record

MAX_DURATION = 80.0
"""Upper bound (s) on one trial; the controller's own time-outs end every trial well before."""
PLAN_DRAWS: tuple[str, ...] = (
    "approach_speed",
    "rotation_speed",
    "rotation_force",
    "insertion_force_rate",
    "hold_force",
    "hold_time",
    "retract_speed",
)
"""The plan's set-points drawn from the controller config's ranges of the same names, in order."""


Observer = Callable[[float, str, mujoco.MjModel, mujoco.MjData], None]
"""Called after every physics step with the trial time, the controller's phase, model and data."""


@dataclass(frozen=True)
class PhysicsRun:
    """One physics run: tared tool-frame wrench per step (R columns 0-5, L 6-11), events, outcome."""

    wrench: Wrench
    state: ControllerState
    latched: bool
    disturbance_onset: float | None = None
    """When a collision's first pulse struck or a slip started (s; None: none, or it never
    happened)."""


@dataclass(frozen=True)
class TrialDraw:
    """One draw of a trial: its physics, its nominal twin's (the same draw without the failure's
    offset), the controller's set-points, the sensor's errors and the part's deviation."""

    physics: TrialPhysics
    twin: TrialPhysics
    plan: ControlPlan
    sensor: SensorDraw
    deviation: PartDeviation
    collision: Collision | None = None
    slip: Slip | None = None

    @property
    def disturbed(self) -> bool:
        """A collision or a slip: a failure whether or not the part still seats."""
        return self.collision is not None or self.slip is not None


def draw_trial(
    config: SimConfig, rng: np.random.Generator, failure: FailureType | None
) -> TrialDraw:
    """Sample one trial's physical variation, controller set-points and sensor errors."""
    g, var, fc, cc = config.geometry, config.variation, config.failures, config.controller
    ox, oy, oz = (float(v) for v in rng.normal(0.0, [var.offset_xy, var.offset_xy, var.offset_z]))
    yaw = float(rng.normal(0.0, var.offset_yaw))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    deviation = PartDeviation()
    collision = slip = None
    nominal = (ox, oy, oz, yaw)
    if failure == COLLISION:
        collision = draw_collision(fc.collision, STRUCK_PHASES, rng)
    elif failure == SLIP:
        slip = draw_slip(fc.slip, SLIP_PHASES, (fc.deviation_xy, fc.deviation_yaw), rng)
    elif failure == "misalignment":
        oy = sign * uniform(rng, fc.misalignment_xy)
    elif failure == "jamming":
        yaw = sign * uniform(rng, fc.jamming_yaw)
    elif failure == "missed_snap":
        oz = -uniform(rng, fc.missed_snap_z)
    elif failure is not None and (dirs := deviation_dirs(failure)) is not None:
        deviation = draw_deviation(fc, dirs, rng)
    elif failure is not None:
        known = ", ".join(failure_classes(fc))
        raise InputError(f"unknown failure type {failure!r} (known: {known})", field="failure")
    tilt = uniform(rng, cc.tilt)
    a = g.male_half + g.clearance
    start_x = a + 0.5 * g.chamfer - g.male_half * math.cos(tilt)
    start_z = g.wall_height + g.male_half * math.sin(tilt) + uniform(rng, cc.start_height)
    physics = TrialPhysics(
        female_offset=(ox, oy, oz),
        female_yaw=math.degrees(yaw),
        friction_scale=uniform(rng, var.friction_scale),
        stiffness_scale=uniform(rng, var.stiffness_scale),
        start_pose=(start_x, 0.0, start_z),
        part_offset=(deviation.x, deviation.y, deviation.yaw),
    )
    set_points = arm_run.draw_set_points(rng, cc, PLAN_DRAWS)
    lateral = (uniform(rng, cc.retract_lateral), uniform(rng, cc.retract_lateral))
    plan = ControlPlan(
        start=(start_x, 0.0, start_z),
        tilt=tilt,
        **set_points,
        retract_lateral=lateral,
        ripple_seed=arm_run.draw_seed(rng),
    )
    sensor = draw_sensor(config.sensor, rng, var.bias_force, var.bias_torque, var.noise_scale)
    twin = replace(
        physics,
        female_offset=nominal[:3],
        female_yaw=math.degrees(nominal[3]),
        part_offset=(0.0, 0.0, 0.0),
    )
    return TrialDraw(physics, twin, plan, sensor, deviation, collision, slip)


def run_physics(
    config: SimConfig,
    physics: TrialPhysics,
    plan: ControlPlan,
    two_arm: bool,
    trace: list[tuple[float, ...]] | None = None,
    observer: Observer | None = None,
    collision: Collision | None = None,
    slip: Slip | None = None,
) -> PhysicsRun:
    """Run the controller on the model (a collision's pulses struck on the part, a slip moving
    it); return the tared wrench per physics step and the events."""
    model = build_model(config, physics, two_arm)
    data = mujoco.MjData(model)
    rig = arm_run.ServoRig(model, data, pitch=plan.tilt)
    controller = SnapController(config, plan)
    if trace is not None:
        controller.trace = trace
    disturbance: CollisionRun | SlipRun | None = None
    if collision is not None:
        disturbance = CollisionRun(collision, data, "male")
    elif slip is not None:
        disturbance = SlipRun(slip, data, rig.act)
    before = _before_step(_holder_step(config, rig) if two_arm else None, disturbance)
    after_step = _phase_observer(observer, disturbance, controller, model, data)
    max_steps = int(MAX_DURATION / rig.dt)
    wrench = rig.run(controller, plan.start, max_steps, before, after_step)
    latched = _latched(config, model, data)
    onset = disturbance.onset if disturbance is not None else None
    return PhysicsRun(wrench, controller.state, latched, onset)


def _before_step(
    holder: arm_run.StepHook | None, disturbance: CollisionRun | SlipRun | None
) -> arm_run.StepHook | None:
    """What runs before each physics step: the holding arm's step, a slip's servo offset."""
    slip = disturbance if isinstance(disturbance, SlipRun) else None
    if slip is None:
        return holder

    def step() -> None:
        if holder is not None:
            holder()
        slip.apply()

    return step


def _phase_observer(
    observer: Observer | None,
    disturbance: CollisionRun | SlipRun | None,
    controller: SnapController,
    model: mujoco.MjModel,
    data: mujoco.MjData,
) -> arm_run.StepObserver | None:
    """What runs after each physics step with the controller's phase at that time: the
    observer, and a collision's or a slip's next step."""
    if observer is None and disturbance is None:
        return None

    def observe(t: float) -> None:
        phase = controller.state.phase
        if observer is not None:
            observer(t, phase, model, data)
        if disturbance is not None:
            disturbance.update(t, phase)

    return observe


def _holder_step(config: SimConfig, rig: arm_run.ServoRig) -> arm_run.StepHook:
    """Two-arm: the left arm's step before each physics step, its impedance yielding to the
    force on its own (tared) sensor along the insertion axis."""
    holder = HolderController(config)
    z_servo = rig.model.actuator("l_z").id
    lz_sensor = 8
    tare, sensordata, ctrl = rig.tare, rig.data.sensordata, rig.data.ctrl

    def step() -> None:
        ctrl[z_servo] = holder.update(rig.dt, tare[lz_sensor] - sensordata[lz_sensor])[2]

    return step


def _latched(config: SimConfig, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
    """True when the male's shoulder is below the hooks' retention face, inside the housing."""
    male = data.body("male").xpos
    return below_hooks(config, male[2] + config.geometry.male_lower_height, male[:2], data)


def below_hooks(
    config: SimConfig, shoulder: float, centre: NDArray[np.float64], data: mujoco.MjData
) -> bool:
    """True when a shoulder at height `shoulder`, centred at `centre` (x, y), is below the
    hooks' retention face and within their depth of the housing's axis."""
    g = config.geometry
    female = data.body("female").xpos
    hook = female[2] + g.male_lower_height + g.hook_play
    lateral = math.hypot(centre[0] - female[0], centre[1] - female[1])
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


def _draw_and_run(
    config: SimConfig,
    rng: np.random.Generator,
    two_arm: bool,
    failure: FailureType | None,
) -> tuple[tuple[TrialDraw, PhysicsRun, ContactLog | None], bool]:
    """One attempt at a trial: draw it, run its physics (a failure's contacts logged for its
    onset); it agrees when the part latched exactly when a success was asked for."""
    draw = draw_trial(config, rng, failure)
    if draw.disturbed:  # struck or slid: a failure whether or not the part still seats
        result = run_physics(
            config, draw.physics, draw.plan, two_arm, collision=draw.collision, slip=draw.slip
        )
        return (draw, result, None), result.disturbance_onset is not None
    log = ContactLog(config) if failure is not None else None
    result = run_physics(config, draw.physics, draw.plan, two_arm, observer=log)
    consistent = result.latched if failure is None else not result.latched
    return (draw, result, log), consistent


def _measured_wrench(
    config: SimConfig,
    arms: tuple[str, ...],
    sensor: SensorDraw,
    samples: Wrench,
    time: NDArray[np.float64],
    rng: np.random.Generator,
) -> dict[str, Wrench]:
    """Each recorded arm's wrench through its sensor: the right arm's drawn errors, the left
    arm's its own (drawn from the same generator, after the right arm's noise)."""
    wrench: dict[str, Wrench] = {}
    for arm in arms:
        cols = slice(0, 6) if arm == "R" else slice(6, 12)
        errors = sensor if arm == "R" else _other_sensor(sensor, config.sensor, rng)
        wrench[arm] = measure(samples[:, cols], time, config.sensor, errors, rng)
    return wrench


def _trial_metadata(
    seed: int,
    scenario: ScenarioName,
    failure: FailureType | None,
    attempts: int,
    rate_hz: float,
    draw: TrialDraw,
    result: PhysicsRun,
) -> dict[str, object]:
    """meta.json of a trial: the request, the attempts, the physical outcome and the draw."""
    state = result.state
    return {
        "seed": int(seed),
        "scenario": scenario,
        "requested": failure or "success",
        "attempts": attempts,
        "latched": result.latched,
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


def _failure_metadata(
    failure: FailureType, onset: Onset, draw: TrialDraw, period: float
) -> dict[str, object]:
    """meta.json's failure entry: the class, its onset on the sample clock, the onset's rule and
    contact, and a deviation's draw."""
    return {
        "class": failure,
        "onset": None if onset.time is None else arm_run.on_clock(onset.time, period),
        "onset_rule": onset.rule,
        "onset_contact": onset.contact,
        "deviation": relative_deviation(draw).to_dict() if moves_part(failure) else None,
    }


def moves_part(failure: FailureType) -> bool:
    """True for the classes whose error is a lateral or yaw offset of the part against the
    housing (deviation, misalignment, jamming); a missed snap's is vertical."""
    return deviation_dirs(failure) is not None or failure in ("misalignment", "jamming")


def relative_deviation(draw: TrialDraw) -> PartDeviation:
    """The failure's offset of the held part against the housing: its slip in the hand less the
    housing's offset from the nominal twin's, the error a correction has to undo."""
    p, twin = draw.physics, draw.twin
    dx, dy, dyaw = p.part_offset
    return PartDeviation(
        x=dx - (p.female_offset[0] - twin.female_offset[0]),
        y=dy - (p.female_offset[1] - twin.female_offset[1]),
        yaw=dyaw - math.radians(p.female_yaw - twin.female_yaw),
    )


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
    (draw, result, log), attempts = arm_run.redraw_until(
        seed,
        config.failures.max_attempts,
        lambda rng: _draw_and_run(config, rng, scen.two_arm, failure),
    )
    latched = result.latched
    if failure is None:
        outcome = "success" if latched else "failure"
    else:
        outcome = failure if not latched or draw.disturbed else "success"
    metadata = _trial_metadata(seed, scenario, failure, attempts, rate_hz, draw, result)
    if failure is not None and not latched and log is not None:
        onset = failure_onset(config, draw, scen.two_arm, result.state, log)
        metadata["failure"] = _failure_metadata(failure, onset, draw, 1.0 / rate_hz)
    began = result.disturbance_onset
    if draw.collision is not None and began is not None:
        metadata["failure"] = collision_record(draw.collision, began, rate_hz)
    if draw.slip is not None and began is not None:
        metadata["failure"] = slip_record(draw.slip, began, rate_hz)
    rng = arm_run.sensor_rng(seed, attempts)
    return arm_run.sensor_trial(
        name or f"sim-{scenario}-{seed}",
        result.wrench,
        k,
        rate_hz,
        lambda samples, time: _measured_wrench(config, scen.arms, draw.sensor, samples, time, rng),
        result.state.switch_times,
        outcome,
        metadata,
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
