"""Scripted force/position controller of the peg-in-hole task's four sub-tasks.

reach: guarded move down until the contact force exceeds a threshold; search: press on the
surface (admittance loop) while the tip follows an Archimedean spiral until it drops into the
hole; insert: comply laterally and descend under a force set-point until pressed on the hole's
floor; release: open the gripper, pause, move away. Switch times are recorded as the controller
makes them.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.task import Task

PEG_TASK = Task(("reach", "search", "insert", "release"), ("done",), "peg-in-hole")
"""The peg-in-hole task: its sub-tasks in order (the controller's phases) and its end phase."""


@dataclass(frozen=True)
class PegPlan:
    """The per-trial draws of the controller's set-points (speeds, forces, times, start pose)."""

    start: tuple[float, float, float]
    """Initial peg tip x, y, z in the believed hole frame."""
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
class PegState:
    """What the controller has done so far: phase, switch times, detected events."""

    phase: str = "reach"
    switch_times: list[float] = field(default_factory=lambda: [0.0])
    phase_start: float = 0.0
    contact_z: float = 0.0
    """Tip height where the reach made contact: the surface as the controller measured it."""
    spiral: float = 0.0
    """Spiral angle (rad) travelled so far."""
    seat_time: float | None = None
    aborted: bool = False

    @property
    def phases(self) -> tuple[str, ...]:
        """The sub-task name of each switch time."""
        return PEG_TASK.subtasks[: len(self.switch_times)]


class PegController:
    """One `update` per control tick returns the six servo targets and whether the gripper is closed."""

    def __init__(self, config: PegConfig, plan: PegPlan) -> None:
        self.cfg = config.controller
        self.depth = config.geometry.hole_depth
        self.plan = plan
        self.state = PegState()
        self.target = [*plan.start, 0.0, 0.0, 0.0]
        self.gripping = True
        self.force = 0.0
        self.lateral = [0.0, 0.0]
        self.centre = (plan.start[0], plan.start[1])
        self.rng = random.Random(plan.ripple_seed)
        self.ripple = 0.0
        dt = config.physics.timestep
        self.ripple_kick = self.cfg.force_ripple * math.sqrt(2.0 * dt / self.cfg.force_ripple_time)

    def _switch(self, t: float, phase: str) -> None:
        st = self.state
        if phase in PEG_TASK.subtasks:
            st.switch_times.append(t)
        st.phase = phase
        st.phase_start = t

    def update(
        self, t: float, dt: float, fx: float, fy: float, fz: float, tip_z: float
    ) -> list[float]:
        """Advance one tick given the tool-frame forces (compression fz > 0) and the tip height."""
        cfg, st, plan, u = self.cfg, self.state, self.plan, self.target
        alpha = dt / (cfg.force_filter + dt)
        self.force += alpha * (fz - self.force)
        self.lateral[0] += alpha * (fx - self.lateral[0])
        self.lateral[1] += alpha * (fy - self.lateral[1])
        f = self.force
        elapsed = t - st.phase_start
        if st.phase == "reach":
            u[2] -= plan.reach_speed * dt
            if f > cfg.contact_force:
                st.contact_z = tip_z
                self.centre = (u[0], u[1])
                self._switch(t, "search")
            elif elapsed > cfg.reach_timeout:
                self._abort(t)
        elif st.phase == "search":
            self._admit(dt, f, plan.search_force, cfg.search_max_speed)
            # Archimedean spiral r = pitch * angle / 2 pi, travelled at the plan's path speed
            pitch = cfg.spiral_pitch / (2 * math.pi)
            st.spiral += plan.search_speed * dt / math.hypot(pitch * st.spiral, pitch)
            r = pitch * st.spiral
            u[0] = self.centre[0] + r * math.cos(st.spiral + plan.spiral_angle)
            u[1] = self.centre[1] + r * math.sin(st.spiral + plan.spiral_angle)
            if tip_z < st.contact_z - cfg.search_drop:
                self._switch(t, "insert")
            elif elapsed > cfg.search_timeout:
                self._abort(t)
        elif st.phase == "insert":
            for i in (0, 1):  # yield to the walls' push
                u[i] += cfg.lateral_compliance * self.lateral[i] * dt
            self._admit(dt, f, plan.insert_force, plan.insert_speed)
            floor = st.contact_z - self.depth
            if (
                st.seat_time is None
                and tip_z < floor + cfg.seat_tolerance
                and f > cfg.seat_fraction * plan.insert_force
            ):
                st.seat_time = t
            if st.seat_time is not None and t - st.seat_time > plan.seat_settle:
                self.gripping = False
                u[2] = tip_z  # the open hand stays where it is: no push without the peg
                self._switch(t, "release")
            elif elapsed > cfg.insert_timeout:
                self._abort(t)
        elif st.phase == "release":
            if elapsed > plan.release_pause:
                u[2] += plan.retreat_speed * dt
            if elapsed > plan.release_pause + plan.retreat_time:
                self._switch(t, "done")
        elif st.phase == "backoff":
            u[2] += plan.retreat_speed * dt
            if elapsed > plan.retreat_time:
                self._switch(t, "done")
        return u

    def _abort(self, t: float) -> None:
        self.state.aborted = True
        self._switch(t, "backoff")

    def _admit(self, dt: float, f: float, force_set: float, max_speed: float) -> None:
        """Admittance on the tool axis: descend while the force is below its set-point.

        The regulated force hunts around its set-point (an Ornstein-Uhlenbeck ripple of
        `force_ripple` x set-point), as a real arm's force loop does.
        """
        a = dt / self.cfg.force_ripple_time
        self.ripple += -a * self.ripple + self.ripple_kick * self.rng.gauss(0.0, 1.0)
        target = force_set * (1.0 + self.ripple)
        limit = max_speed * dt
        self.target[2] -= min(limit, max(-limit, self.cfg.force_gain * (target - f) * dt))

    @property
    def done(self) -> bool:
        return self.state.phase == "done"
