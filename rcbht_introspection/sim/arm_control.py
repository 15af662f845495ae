"""The controller base both simulated tasks share: the scripted hybrid force/position controller
of the Cartesian servo arm (sim/arm_model.py).

Each control tick low-passes the tool-frame forces, then runs the current phase's step on the six
servo targets (x, y, z, yaw, pitch, roll). The force loop is shared: a guarded move down until
contact, an admittance on the tool axis whose force hunts around its set-point (an
Ornstein-Uhlenbeck ripple, as a real arm's force loop does), lateral compliance, and a back-off
after an abort. Sub-task switch times are recorded as the controller makes them.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from rcbht_introspection.sim.arm_config import ForceLoopConfig


@dataclass(frozen=True)
class ArmPlan:
    """The per-trial draws of a controller's set-points: where the tool starts; a task's plan
    adds its speeds, forces and times after it (built positionally, `start` comes first)."""

    start: tuple[float, float, float]
    """Initial tool point x, y, z (m) in the believed frame of the fixed part (the male part's
    bottom centre above the housing, the peg tip above the hole)."""


@dataclass
class PhaseState:
    """What a controller has done so far: its phase, the sub-task switch times, abort."""

    phase: str
    switch_times: list[float] = field(default_factory=lambda: [0.0])
    phase_start: float = 0.0
    aborted: bool = False


@dataclass(frozen=True)
class Tick:
    """One control tick as a phase step sees it: time, step, filtered tool-axis force (compression
    > 0), time in the phase, and the tool's height."""

    t: float
    dt: float
    force: float
    elapsed: float
    z: float


PhaseStep = Callable[[Tick], None]
"""A phase's work in one tick: move the targets, maybe switch phase."""
ConfigT = TypeVar("ConfigT", bound=ForceLoopConfig)
StateT = TypeVar("StateT", bound=PhaseState)


class ArmController(Generic[ConfigT, StateT]):
    """Hybrid force/position controller of the servo arm: one `update` per control tick returns
    the six servo targets; a task's controller gives its sub-tasks' steps (`subtask_steps`) and
    its back-off (`backoff_motion`)."""

    subtasks: tuple[str, ...] = ()
    """The task's sub-tasks: switching to one records its start time."""

    def __init__(
        self,
        config: ConfigT,
        state: StateT,
        start: tuple[float, float, float],
        timestep: float,
        ripple_seed: int,
    ) -> None:
        self.cfg = config
        self.state = state
        self.target = [*start, 0.0, 0.0, 0.0]
        self.force = 0.0
        self.lateral = [0.0, 0.0]
        self.rng = random.Random(ripple_seed)
        self.ripple = 0.0
        self.ripple_kick = config.force_ripple * math.sqrt(
            2.0 * timestep / config.force_ripple_time
        )
        self.steps: dict[str, PhaseStep] = self.phase_steps()

    def phase_steps(self) -> dict[str, PhaseStep]:
        """Each phase's step: the sub-tasks' (`subtask_steps`, in `subtasks` order) and the
        back-off after an abort (`backoff_motion`); a phase without one (the end phase) idles."""
        steps = dict(zip(self.subtasks, self.subtask_steps(), strict=True))
        steps["backoff"] = lambda tick: self._back_off(tick, *self.backoff_motion())
        return steps

    def subtask_steps(self) -> tuple[PhaseStep, ...]:
        """The step of each sub-task, in `subtasks` order; the task's controller gives them."""
        return ()

    def backoff_motion(self) -> tuple[float, float]:
        """Speed (m/s) and duration (s) of the back-off after an abort; the task's controller
        gives them (read when the back-off runs, so they may come from the plan)."""
        raise NotImplementedError

    def update(self, t: float, dt: float, fx: float, fy: float, fz: float, z: float) -> list[float]:
        """Advance one tick given the tool-frame forces (compression fz > 0) and the tool height."""
        f = self._sense(dt, fx, fy, fz)
        self._record(t, f, z)
        step = self.steps.get(self.state.phase)
        if step is not None:
            step(Tick(t, dt, f, t - self.state.phase_start, z))
        return self.target

    def _sense(self, dt: float, fx: float, fy: float, fz: float) -> float:
        """Low-pass the tool-frame forces (the controller's filter); the filtered axial force."""
        alpha = dt / (self.cfg.force_filter + dt)
        self.force += alpha * (fz - self.force)
        self.lateral[0] += alpha * (fx - self.lateral[0])
        self.lateral[1] += alpha * (fy - self.lateral[1])
        return self.force

    def _record(self, t: float, force: float, z: float) -> None:
        """Hook called every tick before the phase step (e.g. a trace); nothing by default."""

    def _switch(self, t: float, phase: str) -> None:
        """Enter `phase` at `t`; a sub-task's start is recorded as a switch time."""
        st = self.state
        if phase in self.subtasks:
            st.switch_times.append(t)
        st.phase = phase
        st.phase_start = t

    def _abort(self, t: float) -> None:
        """Give up the task: mark the trial aborted and back off."""
        self.state.aborted = True
        self._switch(t, "backoff")

    def abort(self, t: float) -> None:
        """A planner's cancel at `t`: give up and back off, unless already backing off or done."""
        if self.state.phase not in ("backoff", "done"):
            self._abort(t)

    def _guarded_move(self, tick: Tick, speed: float, timeout: float) -> bool:
        """Descend at `speed` until the force passes the contact threshold (True); abort after
        `timeout` without contact."""
        self.target[2] -= speed * tick.dt
        if tick.force > self.cfg.contact_force:
            return True
        if tick.elapsed > timeout:
            self._abort(tick.t)
        return False

    def _admit(self, dt: float, force: float, force_set: float, max_speed: float) -> float:
        """Admittance on the tool axis: descend while the force is below its rippled set-point,
        at most `max_speed`; returns the step taken downwards (m)."""
        a = dt / self.cfg.force_ripple_time
        self.ripple += -a * self.ripple + self.ripple_kick * self.rng.gauss(0.0, 1.0)
        target = force_set * (1.0 + self.ripple)
        limit = max_speed * dt
        step = min(limit, max(-limit, self.cfg.force_gain * (target - force) * dt))
        self.target[2] -= step
        return step

    def _yield_laterally(self, dt: float) -> None:
        """Lateral compliance: the x and y targets give way to the filtered lateral forces."""
        u = self.target
        for i in (0, 1):
            u[i] += self.cfg.lateral_compliance * self.lateral[i] * dt

    def _seated(self, tick: Tick, seat_z: float, force_set: float) -> bool:
        """Whether the part sits where it should: the tool within seat_tolerance of the believed
        seat height `seat_z`, the force back to seat_fraction of the set-point `force_set`."""
        cfg = self.cfg
        return tick.z < seat_z + cfg.seat_tolerance and tick.force > cfg.seat_fraction * force_set

    def _back_off(self, tick: Tick, speed: float, duration: float) -> None:
        """Move up at `speed`; the trial ends `duration` after the phase began."""
        self.target[2] += speed * tick.dt
        if tick.elapsed > duration:
            self._switch(tick.t, "done")

    @property
    def done(self) -> bool:
        """Whether the controller has reached its end phase."""
        return self.state.phase == "done"
