"""Scripted force/position controller of the peg-in-hole task's four sub-tasks.

reach: guarded move down until the contact force exceeds a threshold; search: press on the
surface (admittance loop) while the tip follows an Archimedean spiral until it drops into the
hole; insert: comply laterally and descend under a force set-point until pressed on the hole's
floor; release: open the gripper, pause, move away. The force loop and phase bookkeeping are the
shared controller base's (sim/arm_control.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rcbht_introspection.sim.arm_control import ArmController, ArmPlan, PhaseState, PhaseStep, Tick
from rcbht_introspection.sim.peg_config import PegConfig, PegControllerConfig
from rcbht_introspection.task import Task

PEG_TASK = Task(("reach", "search", "insert", "release"), ("done",), "peg-in-hole")
"""The peg-in-hole task: its sub-tasks in order (the controller's phases) and its end phase."""


@dataclass(frozen=True)
class PegPlan(ArmPlan):
    """The per-trial draws of the controller's set-points (ArmPlan: the start pose; speeds,
    forces, times)."""

    reach_speed: float
    search_force: float
    search_speed: float
    spiral_angle: float
    """Direction (rad) in which the spiral starts."""
    insert_force: float
    insert_speed: float
    seat_settle: float
    release_pause: float
    retreat_speed: float
    retreat_time: float
    ripple_seed: int = 0


@dataclass
class PegState(PhaseState):
    """What the controller has done so far: phase, switch times, detected events."""

    phase: str = "reach"
    contact_z: float = 0.0
    """Tip height where the reach made contact: the surface as the controller measured it."""
    spiral: float = 0.0
    """Spiral angle (rad) travelled so far."""
    seat_time: float | None = None

    @property
    def phases(self) -> tuple[str, ...]:
        """The sub-task name of each switch time."""
        return PEG_TASK.subtasks[: len(self.switch_times)]


class PegController(ArmController[PegControllerConfig, PegState]):
    """One `update` per control tick returns the six servo targets and whether the gripper is closed."""

    subtasks = PEG_TASK.subtasks

    def __init__(self, config: PegConfig, plan: PegPlan) -> None:
        timestep = config.physics.timestep
        super().__init__(config.controller, PegState(), plan.start, timestep, plan.ripple_seed)
        self.depth = config.geometry.hole_depth
        self.plan = plan
        self.gripping = True
        self.centre = (plan.start[0], plan.start[1])

    def subtask_steps(self) -> tuple[PhaseStep, ...]:
        """reach, search, insert, release."""
        return (self._reach, self._search, self._insert, self._release)

    def backoff_motion(self) -> tuple[float, float]:
        """After an abort: away as after a release, at the plan's retreat speed and time."""
        return self.plan.retreat_speed, self.plan.retreat_time

    def _reach(self, tick: Tick) -> None:
        """Guarded move down; on contact, remember the surface and the spiral's centre."""
        if self._guarded_move(tick, self.plan.reach_speed, self.cfg.reach_timeout):
            self.state.contact_z = tick.z
            self.centre = (self.target[0], self.target[1])
            self._switch(tick.t, "search")

    def _search(self, tick: Tick) -> None:
        """Press on the surface while the tip follows an Archimedean spiral r = pitch * angle /
        2 pi at the plan's path speed, until it drops into the hole."""
        cfg, st, plan, u = self.cfg, self.state, self.plan, self.target
        self._admit(tick.dt, tick.force, plan.search_force, cfg.search_max_speed)
        pitch = cfg.spiral_pitch / (2 * math.pi)
        st.spiral += plan.search_speed * tick.dt / math.hypot(pitch * st.spiral, pitch)
        r = pitch * st.spiral
        u[0] = self.centre[0] + r * math.cos(st.spiral + plan.spiral_angle)
        u[1] = self.centre[1] + r * math.sin(st.spiral + plan.spiral_angle)
        if tick.z < st.contact_z - cfg.search_drop:
            self._switch(tick.t, "insert")
        elif tick.elapsed > cfg.search_timeout:
            self._abort(tick.t)

    def _insert(self, tick: Tick) -> None:
        """Comply laterally and descend under the insertion force until pressed on the floor;
        then open the gripper."""
        cfg, st, plan, t = self.cfg, self.state, self.plan, tick.t
        self._yield_laterally(tick.dt)  # yield to the walls' push
        self._admit(tick.dt, tick.force, plan.insert_force, plan.insert_speed)
        floor = st.contact_z - self.depth
        if st.seat_time is None and self._seated(tick, floor, plan.insert_force):
            st.seat_time = t
        if st.seat_time is not None and t - st.seat_time > plan.seat_settle:
            self.gripping = False
            self.target[2] = tick.z  # the open hand stays where it is: no push without the peg
            self._switch(t, "release")
        elif tick.elapsed > cfg.insert_timeout:
            self._abort(t)

    def _release(self, tick: Tick) -> None:
        """The open gripper pauses, then moves away for the retreat time."""
        plan = self.plan
        if tick.elapsed > plan.release_pause:
            self.target[2] += plan.retreat_speed * tick.dt
        if tick.elapsed > plan.release_pause + plan.retreat_time:
            self._switch(tick.t, "done")
