"""A simulated trial run attempt by attempt, one sensor sample at a time: what sim_node and
`rcbht closed-loop` step.

A trial's world (the housing's pose error, the part's slip in the hand, friction, the sensor) is
drawn once and persists across its attempts. Each attempt starts at the approach start with a
correction of the held part's believed pose: the arm shifts the whole plan by (x, y, z) and
turns the hand by yaw. An attempt ends when the arm's controller is done: seated (its own seat
check passed, then the mating), failed by its own checks (an insertion time-out, or the planned
stroke ended without a snap), or aborted by the planner; a failed attempt backs off, then the
arm returns to the approach start at the back-off speed (counted as time, no samples).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from rcbht_introspection.io.bags import END_PHASE
from rcbht_introspection.sim import arm_run
from rcbht_introspection.sim.arm_config import SensorConfig
from rcbht_introspection.sim.arm_control import ArmController
from rcbht_introspection.sim.config import FailureType, SimConfig
from rcbht_introspection.sim.controller import SnapController
from rcbht_introspection.sim.model import build_model
from rcbht_introspection.sim.sensor import SensorDraw, decimation, quantize, sensor_errors
from rcbht_introspection.sim.simulate import (
    MAX_DURATION,
    TrialDraw,
    below_hooks,
    draw_trial,
    run_physics,
)

Pose = tuple[float, float, float, float]
"""A correction of the held part's pose: x, y, z (m), yaw (rad)."""
ARM = "R"
"""The arm whose wrench an episode records (the one-arm scenario)."""


@dataclass(frozen=True)
class TrialWorld:
    """What every task's trial world has: its seed, the failure asked for, the draws it took,
    and whether the uncorrected task ends as asked (fails for a failure, seats for a nominal)."""

    seed: int
    failure: str | None
    redraws: int
    as_requested: bool

    @property
    def failing(self) -> bool:
        return self.failure is not None and self.as_requested


def corrected_start(
    start: tuple[float, float, float], correction: Pose
) -> tuple[float, float, float]:
    """The hand's start shifted by a correction's x, y, z (its yaw turns the hand)."""
    return (start[0] + correction[0], start[1] + correction[1], start[2] + correction[2])


@dataclass(frozen=True)
class World(TrialWorld):
    """One snap trial's world, the same for all its attempts."""

    draw: TrialDraw

    @property
    def truth(self) -> Pose:
        """The correction that undoes the world's errors: the housing's pose error less the
        part's slip in the hand (what the oracle applies)."""
        p = self.draw.physics
        dx, dy, dyaw = p.part_offset
        ox, oy, oz = p.female_offset
        return (ox - dx, oy - dy, oz, math.radians(p.female_yaw) - dyaw)


def draw_world(config: SimConfig, seed: int, failure: FailureType | None) -> World:
    """The world of trial `seed`, drawn as `rcbht sim` draws it (redrawn up to the config's
    max_attempts times) until the uncorrected task fails with `failure` (or seats, for None),
    judged by where the part itself ends (`part_seated`)."""

    def attempt(rng: np.random.Generator) -> tuple[tuple[TrialDraw, bool], bool]:
        draw = draw_trial(config, rng, failure)
        final = _FinalState()
        run_physics(config, draw.physics, draw.plan, False, observer=final)
        agrees = final.seated(config) == (failure is None)
        return (draw, agrees), agrees

    (draw, agrees), redraws = arm_run.redraw_until(seed, config.failures.max_attempts, attempt)
    return World(seed, failure, redraws, agrees, draw=draw)


class _FinalState:
    """Observer of a physics run that keeps its model and data, to judge where it ended."""

    def __init__(self) -> None:
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None

    def __call__(self, t: float, phase: str, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.model, self.data = model, data

    def seated(self, config: SimConfig) -> bool:
        assert self.model is not None and self.data is not None
        return part_seated(config, self.model, self.data)


def part_seated(config: SimConfig, model: mujoco.MjModel, data: mujoco.MjData) -> bool:
    """True when the held part's shoulder is below the hooks' retention face, inside the
    housing: measured on the part's block, which sits off the hand's centre by its slip."""
    block = data.geom("male_block").xpos  # its centre: half the block's height above its base
    return below_hooks(config, block[2] + 0.5 * config.geometry.male_lower_height, block[:2], data)


@dataclass(frozen=True)
class Sample:
    """One sensor sample of an attempt: its time from the attempt's first sample, the arm's
    wrench, and the sub-task events (time, name) due before it: each event goes with the first
    sample at or after its time, as a recorded trial's events are fed."""

    time: float
    wrench: NDArray[np.float64]
    events: tuple[tuple[float, str], ...]


@dataclass(frozen=True)
class AttemptEnd:
    """How an attempt ended: the arm's own seat check and why, the physical truth, its
    duration and the return to the approach start that a failed attempt needs."""

    seated: bool
    reason: str
    latched: bool
    duration: float
    return_s: float


class SteppedAttempt:
    """An attempt stepped a sensor sample at a time: the task's model, rig and controller are
    the subclass's; the sensor, the events, the abort and the stepping are shared."""

    def __init__(
        self,
        rig: arm_run.ServoRig,
        controller: ArmController[Any, Any],
        start: tuple[float, float, float],
        sensor: tuple[SensorConfig, SensorDraw],
        noise_seed: tuple[int, int],
        rate_hz: float,
        max_duration: float,
    ) -> None:
        self.rig, self.model, self.data = rig, rig.model, rig.data
        self.controller = controller
        self.start = start
        self.offsets = self.rig.offsets(start)
        self.k = decimation(rate_hz, self.rig.dt)
        self.period = 1.0 / rate_hz
        self.sensor = sensor[0]
        times = np.arange(int(max_duration * rate_hz), dtype=np.float64) * self.period
        rng = np.random.default_rng([*noise_seed, 11])
        self.errors = sensor_errors(times, sensor[0], sensor[1], rng)
        self.before_step: arm_run.StepHook | None = None
        self.step_count = 0
        self.samples = 0
        self.reason = ""
        self._phase = self.controller.state.phase
        self._events: list[tuple[float, str]] = [(0.0, self._phase)]
        self.end: AttemptEnd | None = None

    @property
    def time(self) -> float:
        """Physics time of the attempt (s)."""
        return self.step_count * self.rig.dt

    def abort(self, reason: str = "aborted") -> None:
        """The planner's cancel: the arm backs off from here."""
        if not self.reason:
            self.reason = reason
        self.controller.abort(self.time)

    def step(self) -> Sample | None:
        """The next sensor sample (k physics steps, box-averaged), None once the attempt ended."""
        if self.end is not None:
            return None
        if self.controller.done or self.samples >= len(self.errors):
            self.end = self._end()
            return None
        raw = np.zeros(self.model.nsensordata)
        for _ in range(self.k):
            if self.controller.done:  # a partial last block is no sample (as resample drops it)
                self.end = self._end()
                return None
            raw += self.rig.step(self.controller, self.step_count, self.offsets, self.before_step)
            self.step_count += 1
            self._watch()
        tared = self.rig.tare[:6] - raw[:6] / self.k
        t = round(self.samples * self.period, 9)
        wrench = quantize(tared + self.errors[self.samples], self.sensor)
        self.samples += 1
        events = tuple(e for e in self._events if e[0] <= t + 1e-9)
        self._events = self._events[len(events) :]
        return Sample(t, wrench, events)

    def _watch(self) -> None:
        """Sub-task events as the controller switches; an abort by the arm's own checks is a
        time-out (a task's own checks: _checked)."""
        st = self.controller.state
        if st.phase == self._phase:
            return
        t = arm_run.on_clock(st.phase_start, self.period)
        if self._checked(st.phase):
            pass
        elif st.phase == "backoff" and not self.reason:
            self.reason = "timeout"
        elif st.phase in self.controller.subtasks:
            self._events.append((t, st.phase))
        self._phase = self.controller.state.phase

    def _checked(self, phase: str) -> bool:
        """A task's own check on entering `phase` (True: it acted on it)."""
        return False

    def _end(self) -> AttemptEnd:
        """The arm's own seat check and why, the physical truth, the samples' duration, and the
        climb back to the approach start a failed attempt needs, at the task's return speed."""
        st = self.controller.state
        seated = st.seat_time is not None and not st.aborted
        duration = round(self.samples * self.period, 9)
        climb = self.start[2] - (self.offsets[2] + self.data.qpos[self.rig.qz])
        back = 0.0 if seated else max(0.0, climb) / self._return_speed()
        return AttemptEnd(
            seated, "seated" if seated else self.reason or "unseated",
            self._in_place(), duration, back,
        )  # fmt: skip

    def _in_place(self) -> bool:
        """The part physically where the task puts it (the task's own judgement)."""
        raise NotImplementedError

    def _return_speed(self) -> float:
        """Speed (m/s) of the return to the approach start after a failed attempt."""
        raise NotImplementedError

    def end_event(self) -> tuple[float, str]:
        """The end-of-task event after the attempt's last sample."""
        return (round(self.samples * self.period, 9), END_PHASE)


class Attempt(SteppedAttempt):
    """One attempt of a snap world under a correction."""

    def __init__(
        self, config: SimConfig, world: World, correction: Pose, index: int, rate_hz: float
    ) -> None:
        draw = world.draw
        physics = replace(
            draw.physics, start_pose=corrected_start(draw.physics.start_pose, correction)
        )
        self.config = config
        model = build_model(config, physics)
        rig = arm_run.ServoRig(model, mujoco.MjData(model), pitch=draw.plan.tilt, yaw=correction[3])
        super().__init__(
            rig, SnapController(config, draw.plan), draw.plan.start,
            (config.sensor, draw.sensor), (world.seed, index), rate_hz, MAX_DURATION,
        )  # fmt: skip

    def _checked(self, phase: str) -> bool:
        """The stroke ended without a snap: the arm's seat check failed."""
        if phase == "mating" and self.controller.state.seat_time is None:
            self.abort("no_snap")
            return True
        return False

    def _in_place(self) -> bool:
        return part_seated(self.config, self.model, self.data)

    def _return_speed(self) -> float:
        return self.config.controller.backoff_speed
