"""Scripted hybrid force/position controller of the snap assembly's four sub-tasks.

approach: guarded move down until the contact force exceeds a threshold; rotation: pivot the tilted
part level on its contact edge while an admittance loop keeps a contact force and the lateral servo
centres it; insertion: ramp the force set-point until the snap hooks give way (force peak, then the
snap-through drop), stopping at a planned stroke or a time-out; mating: hold a force, then move away
until the force is released. Sub-task switch times are recorded as the controller makes them.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from rcbht_introspection.sim.config import SimConfig

PHASES: tuple[str, ...] = ("approach", "rotation", "insertion", "mating", "backoff", "done")


@dataclass(frozen=True)
class ControlPlan:
    """The per-trial draws of the controller's set-points (speeds, forces, times, start pose)."""

    start: tuple[float, float, float]
    """Initial tool centre point (male bottom centre) x, y, z in the believed housing frame."""
    tilt: float
    approach_speed: float
    rotation_speed: float
    rotation_force: float
    insertion_force_rate: float
    hold_force: float
    hold_time: float
    retract_speed: float
    ripple_seed: int = 0
    """Seed of the force loop's ripple (drawn per trial)."""
    retract_lateral: tuple[float, float] = (0.0, 0.0)
    """Lateral velocity (m/s) of the move-away path; the latched part resists it."""


@dataclass
class ControllerState:
    """What the controller has done so far: phase, switch times, detected events."""

    phase: str = "approach"
    switch_times: list[float] = field(default_factory=lambda: [0.0])
    phase_start: float = 0.0
    peak_force: float = 0.0
    snap_time: float | None = None
    stroke_time: float | None = None
    seat_time: float | None = None
    hold_end: float | None = None
    release_time: float | None = None
    aborted: bool = False


class SnapController:
    """Hybrid force/position controller: one `update` per control tick returns the six servo targets."""

    def __init__(self, config: SimConfig, plan: ControlPlan) -> None:
        self.cfg = config.controller
        self.plan = plan
        self.state = ControllerState()
        x, y, z = plan.start
        self.target = [x, y, z, 0.0, plan.tilt, 0.0]
        self.force = 0.0
        self.force_set = 0.0
        self.half_width = config.geometry.male_half
        self.pivot_x = 0.0
        self.lateral = [0.0, 0.0]
        g = config.geometry
        self.hook_top = g.male_lower_height + g.hook_play + g.hook_ramp
        """Believed tool height below which the part is engaged in the snap hooks."""
        self.pivot_z = 0.0
        self.admittance_z = 0.0
        self.trace: list[tuple[float, ...]] | None = None
        self.rng = random.Random(plan.ripple_seed)
        self.ripple = 0.0
        dt = config.physics.timestep
        self.ripple_kick = self.cfg.force_ripple * math.sqrt(2.0 * dt / self.cfg.force_ripple_time)
        self.seat_floor = -self.cfg.insertion_stroke
        """Lowest believed tool height the insertion may reach before it counts as done."""

    def _switch(self, t: float, phase: str) -> None:
        st = self.state
        if phase in ("rotation", "insertion", "mating"):
            st.switch_times.append(t)
        st.phase = phase
        st.phase_start = t

    def update(
        self, t: float, dt: float, fx: float, fy: float, fz: float, tcp_z: float
    ) -> list[float]:
        """Advance one tick given the tool-frame forces (compression fz > 0) and the tool height."""
        cfg, st, plan, u = self.cfg, self.state, self.plan, self.target
        alpha = dt / (cfg.force_filter + dt)
        self.force += alpha * (fz - self.force)
        self.lateral[0] += alpha * (fx - self.lateral[0])
        self.lateral[1] += alpha * (fy - self.lateral[1])
        f = self.force
        elapsed = t - st.phase_start
        if self.trace is not None:
            self.trace.append((t, f, self.force_set, tcp_z, *u))
        if st.phase == "approach":
            u[2] -= plan.approach_speed * dt
            if f > cfg.contact_force:
                self.force_set = plan.rotation_force
                self.pivot_x = u[0] + self.half_width * math.cos(u[4])
                self.pivot_z = u[2] - self.half_width * math.sin(u[4])
                self.admittance_z = 0.0
                self._switch(t, "rotation")
            elif elapsed > cfg.approach_timeout:
                st.aborted = True
                self._switch(t, "backoff")
        elif st.phase == "rotation":
            # pivot on the contact edge: the edge's x stays put while the part levels out
            u[4] = max(0.0, u[4] - plan.rotation_speed * dt)
            self._admit(dt, f)
            u[0] = self.pivot_x - self.half_width * math.cos(u[4])
            u[2] = self.pivot_z + self.half_width * math.sin(u[4]) + self.admittance_z
            if u[4] == 0.0 and elapsed > plan.tilt / plan.rotation_speed + cfg.rotation_settle:
                st.peak_force = 0.0
                self._switch(t, "insertion")
        elif st.phase == "insertion":
            self._comply(dt, t - st.phase_start < cfg.centering_time)
            if st.seat_time is None:
                self.force_set = min(
                    cfg.insertion_force_max,
                    plan.rotation_force + plan.insertion_force_rate * elapsed,
                )
            if st.snap_time is None:
                st.peak_force = max(st.peak_force, f)
                engaged = tcp_z < self.hook_top
                if (
                    engaged
                    and st.peak_force > cfg.snap_min_peak
                    and f < (1.0 - cfg.snap_drop) * st.peak_force
                ):
                    st.snap_time = t
            if tcp_z <= self.seat_floor:
                if st.stroke_time is None:
                    st.stroke_time = t
                u[2] = max(u[2], tcp_z)  # planned stroke reached: stop descending
            else:
                self._admit(dt, f)
            if (
                st.snap_time is not None
                and st.seat_time is None
                and f > cfg.seat_fraction * plan.hold_force
                and tcp_z < cfg.seat_tolerance
            ):
                st.seat_time = t
                self.force_set = plan.hold_force
            if st.seat_time is not None and t - st.seat_time > cfg.seat_settle:
                self._switch(t, "mating")
            elif st.stroke_time is not None and t - st.stroke_time > cfg.seat_settle:
                self.force_set = plan.hold_force  # believes it is done: the snap was missed
                self._switch(t, "mating")
            elif elapsed > cfg.insertion_timeout:
                st.aborted = True
                self._switch(t, "backoff")
        elif st.phase == "mating":
            if st.hold_end is None:
                self._comply(dt, False)
                if tcp_z > self.seat_floor:
                    self._admit(dt, f)
                if elapsed > plan.hold_time:
                    st.hold_end = t
            elif st.release_time is None:
                u[2] += plan.retract_speed * dt
                u[0] += plan.retract_lateral[0] * dt  # the move-away path is not purely vertical
                u[1] += plan.retract_lateral[1] * dt
                if f < cfg.release_force or t - st.hold_end > cfg.retract_time:
                    st.release_time = t
            elif t - st.release_time > cfg.tail_time:
                self._switch(t, "done")
        elif st.phase == "backoff":
            u[2] += cfg.backoff_speed * dt
            if elapsed > cfg.abort_time:
                self._switch(t, "done")
        return u

    def _comply(self, dt: float, centre: bool) -> None:
        """Lateral axes: pull towards the believed centre first, then yield to lateral forces."""
        u = self.target
        for i in (0, 1):
            if centre:
                u[i] += self.cfg.lateral_gain * (0.0 - u[i]) * dt
            u[i] += self.cfg.lateral_compliance * self.lateral[i] * dt

    def _admit(self, dt: float, f: float) -> None:
        """Admittance on the tool axis: descend while the force is below its set-point.

        The regulated force hunts around its set-point (an Ornstein-Uhlenbeck ripple of
        `force_ripple` x set-point), as the real arm's force loop does.
        """
        a = dt / self.cfg.force_ripple_time
        self.ripple += -a * self.ripple + self.ripple_kick * self.rng.gauss(0.0, 1.0)
        target = self.force_set * (1.0 + self.ripple)
        limit = self.cfg.max_admittance_speed * dt
        step = min(limit, max(-limit, self.cfg.force_gain * (target - f) * dt))
        self.target[2] -= step
        self.admittance_z -= step

    @property
    def done(self) -> bool:
        return self.state.phase == "done"


class HolderController:
    """Two-arm scenario: the left arm holds the housing with an impedance around its home pose."""

    def __init__(self, config: SimConfig) -> None:
        self.cfg = config.controller
        self.force = 0.0
        self.target = [0.0] * 6

    def update(self, dt: float, fz: float) -> list[float]:
        """Yield along the insertion axis in proportion to the force above the preload."""
        alpha = dt / (self.cfg.force_filter + dt)
        self.force += alpha * (fz - self.force)
        self.target[2] = -self.cfg.holder_compliance * (self.force - self.cfg.holder_force)
        return self.target
