"""Running a simulated trial, shared by both tasks: redraw until the physics agrees, settle and
tare the servo arm, run its controller on the physics, and put the recorded wrench on the
sensor's clock."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.io.trial import Trial
from rcbht_introspection.sim.arm_config import Range
from rcbht_introspection.sim.arm_control import ArmController
from rcbht_introspection.sim.arm_model import ARM_JOINTS
from rcbht_introspection.sim.sensor import resample

SETTLE_TIME = 0.3
"""Time (s) the arm servos settle under gravity before taring and recording start."""

Wrench = NDArray[np.float64]
"""Tared tool-frame wrench per step or sample: (N, 6) per sensor, sensors side by side."""
StepHook = Callable[[], None]
"""Called before each physics step (after the arm's servo targets are set)."""
StepObserver = Callable[[float], None]
"""Called after each physics step with the trial time it reached."""
Result = TypeVar("Result")


def uniform(rng: np.random.Generator, r: Range) -> float:
    """One uniform draw in the range `r` (a config range)."""
    return float(rng.uniform(r[0], r[1]))


def draw_set_points(
    rng: np.random.Generator, config: object, names: tuple[str, ...], **ranges: Range
) -> dict[str, float]:
    """A plan's set-points, one uniform draw per name in the order of `names` (which fixes the
    trial's draws): from the range passed under that name, else from the config's range of the
    same name, as each plan field is named after the config range it is drawn from."""
    return {
        name: uniform(rng, ranges[name] if name in ranges else getattr(config, name))
        for name in names
    }


def draw_seed(rng: np.random.Generator) -> int:
    """A seed, from the trial's draws, for a generator of its own (the force loop's ripple)."""
    return int(rng.integers(0, 2**31))


def redraw_until(
    seed: int, max_attempts: int, attempt: Callable[[np.random.Generator], tuple[Result, bool]]
) -> tuple[Result, int]:
    """Run `attempt` on the seed's draw generators ([seed, 0], [seed, 1], ...) until it says
    its physics agrees, or `max_attempts` are spent; its last result and the attempts."""
    attempts = 0
    while True:
        rng = np.random.default_rng([int(seed), attempts])
        result, agrees = attempt(rng)
        attempts += 1
        if agrees or attempts >= max_attempts:
            return result, attempts


def sensor_rng(seed: int, attempts: int) -> np.random.Generator:
    """The generator of the sensor's noise for a trial drawn `attempts` times."""
    return np.random.default_rng([int(seed), attempts, 7])


def on_clock(t: float, period: float) -> float:
    """Time `t` rounded to the sensor's sample clock."""
    return round(round(t / period) * period, 9)


class PhaseTrigger:
    """Fires `delay` s into the first run of a controller phase, or as that phase ends if it
    ends sooner: when a collision's first push or a slip starts."""

    def __init__(self, phase: str, delay: float) -> None:
        self.phase = phase
        self.delay = delay
        self.fired: float | None = None
        self._start: float | None = None

    def update(self, t: float, phase: str) -> float | None:
        """The phase running at time `t`; the time it fired (None: not yet)."""
        if self.fired is None:
            if phase == self.phase:
                self._start = t if self._start is None else self._start
                if t - self._start >= self.delay:
                    self.fired = t
            elif self._start is not None:
                self.fired = t
        return self.fired


def disturbance_record(
    failure: str, onset: float, rate_hz: float, rule: str, **details: object
) -> dict[str, object]:
    """meta.json's failure entry of a disturbance that starts at a known time (a push, a slip):
    the class, its onset on the sample clock and rule, and its details (deviation, phase...)."""
    return {
        "class": failure,
        "onset": on_clock(onset, 1.0 / rate_hz),
        "onset_rule": rule,
        "onset_contact": None,
        **details,
    }


Times = NDArray[np.float64]
"""Sample times (s) of a trial."""
Measure = Callable[[Wrench, Times], dict[str, Wrench]]
"""The sensors' readings (per arm) of the true wrench at the sample times."""


def sensor_trial(
    name: str,
    raw: Wrench,
    k: int,
    rate_hz: float,
    measured: Measure,
    switch_times: list[float],
    outcome: str,
    metadata: dict[str, object],
    phases: tuple[str, ...] = (),
) -> Trial:
    """The trial as recorded: the physics-rate wrench decimated by `k` to the sensor's rate and
    read by its sensors, the switch times on the sample clock."""
    samples = resample(raw, k)
    period = 1.0 / rate_hz
    time = np.round(np.arange(len(samples)) * period, 9)
    return Trial(
        name=name,
        time=time,
        wrench=measured(samples, time),
        state_times=tuple(on_clock(t, period) for t in switch_times),
        outcome=outcome,
        metadata=metadata,
        phases=phases,
    )


class ServoRig:
    """The servo arm in its model, settled under gravity with its sensors tared: runs a
    controller on the physics (the right arm's six servos, the tool height from its z slide)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        pitch: float | None = None,
        yaw: float = 0.0,
    ) -> None:
        self.model = model
        self.data = data
        self.dt: float = model.opt.timestep
        self.act = [model.actuator(f"r_{n}").id for n in ARM_JOINTS]
        qadr = [model.joint(f"r_{n}").qposadr[0] for n in ARM_JOINTS]
        self.qz = qadr[2]
        if pitch is not None:  # the arm starts tilted: joint and servo at the pitch
            data.qpos[qadr[4]] = pitch
            data.ctrl[self.act[4]] = pitch
        if yaw:  # a corrected attempt: the hand turned about the tool axis from the start
            data.qpos[qadr[3]] = yaw
            data.ctrl[self.act[3]] = yaw
        self.yaw = yaw
        for _ in range(int(SETTLE_TIME / self.dt)):
            mujoco.mj_step(model, data)  # the servos take the weight before the sensor is tared
        self.tare: NDArray[np.float64] = data.sensordata.copy()

    def run(
        self,
        controller: ArmController[Any, Any],
        start: tuple[float, float, float],
        max_steps: int,
        before_step: StepHook | None = None,
        after_step: StepObserver | None = None,
    ) -> Wrench:
        """Run `controller` (targets relative to the hand's `start`) until it is done or
        `max_steps`; the tared tool-frame wrench per physics step (compression: +Fz)."""
        raw = np.empty((max_steps, self.model.nsensordata))
        offsets = self.offsets(start)
        step = 0
        while step < max_steps and not controller.done:
            raw[step] = self.step(controller, step, offsets, before_step)
            if after_step is not None:
                after_step(step * self.dt + self.dt)
            step += 1
        # tool-frame convention: the wrench the part exerts on the sensor (compression: +Fz), tared
        wrench: Wrench = self.tare[None, :] - raw[:step]
        return wrench

    def offsets(self, start: tuple[float, float, float]) -> tuple[float, ...]:
        """What each servo target is taken from: the hand's start, and its yaw."""
        sx, sy, sz = start
        return (sx, sy, sz, -self.yaw, 0.0, 0.0)

    def step(
        self,
        controller: ArmController[Any, Any],
        step: int,
        offsets: tuple[float, ...],
        before_step: StepHook | None = None,
    ) -> NDArray[np.float64]:
        """One control tick and physics step; the raw sensor data after it (not tared)."""
        data, tare, sensordata = self.data, self.tare, self.data.sensordata
        u = controller.update(
            step * self.dt,
            self.dt,
            tare[0] - sensordata[0],
            tare[1] - sensordata[1],
            tare[2] - sensordata[2],
            offsets[2] + data.qpos[self.qz],
        )
        ctrl, act = data.ctrl, self.act
        for i in range(6):
            ctrl[act[i]] = u[i] - offsets[i]
        if before_step is not None:
            before_step()
        mujoco.mj_step(self.model, data)
        readings: NDArray[np.float64] = sensordata
        return readings
