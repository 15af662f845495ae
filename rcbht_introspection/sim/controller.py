"""Scripted hybrid force/position controller of the snap assembly's four sub-tasks.

approach: guarded move down until the contact force exceeds a threshold; rotation: pivot the tilted
part level on its contact edge while an admittance loop keeps a contact force and the lateral servo
centres it; insertion: ramp the force set-point until the snap hooks give way (force peak, then the
snap-through drop), stopping at a planned stroke or a time-out; mating: hold a force, then move away
until the force is released. The force loop and phase bookkeeping are the shared controller base's
(sim/arm_control.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rcbht_introspection.sim.arm_control import ArmController, ArmPlan, PhaseState, PhaseStep, Tick
from rcbht_introspection.sim.config import ControllerConfig, SimConfig
from rcbht_introspection.task import HIRO_TASK

PHASES: tuple[str, ...] = ("approach", "rotation", "insertion", "mating", "backoff", "done")
SLIP_PHASES: tuple[str, ...] = PHASES[1:3]
"""The phases a slow slip starts in: the part in contact and loaded."""
STRUCK_PHASES: tuple[str, ...] = PHASES[:3]
"""The phases a collision strikes in: the part is free or sliding in the housing. Once it is
seated (mating), a push on it loads the housing's hooks, which the wrist's sensor hardly sees."""


@dataclass(frozen=True)
class ControlPlan(ArmPlan):
    """The per-trial draws of the controller's set-points (ArmPlan: the start pose; speeds,
    forces, times)."""

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
class ControllerState(PhaseState):
    """What the controller has done so far: phase, switch times, detected events."""

    phase: str = "approach"
    peak_force: float = 0.0
    snap_time: float | None = None
    stroke_time: float | None = None
    seat_time: float | None = None
    hold_end: float | None = None
    release_time: float | None = None


class SnapController(ArmController[ControllerConfig, ControllerState]):
    """Hybrid force/position controller: one `update` per control tick returns the six servo targets."""

    subtasks = HIRO_TASK.subtasks

    def __init__(self, config: SimConfig, plan: ControlPlan) -> None:
        timestep = config.physics.timestep
        super().__init__(
            config.controller, ControllerState(), plan.start, timestep, plan.ripple_seed
        )
        self.plan = plan
        self.target[4] = plan.tilt
        self.force_set = 0.0
        self.half_width = config.geometry.male_half
        self.pivot_x = 0.0
        g = config.geometry
        self.hook_top = g.male_lower_height + g.hook_play + g.hook_ramp
        """Believed tool height below which the part is engaged in the snap hooks."""
        self.pivot_z = 0.0
        self.admittance_z = 0.0
        self.trace: list[tuple[float, ...]] | None = None
        self.seat_floor = -self.cfg.insertion_stroke
        """Lowest believed tool height the insertion may reach before it counts as done."""

    def subtask_steps(self) -> tuple[PhaseStep, ...]:
        """approach, rotation, insertion, mating."""
        return (self._approach, self._rotation, self._insertion, self._mating)

    def backoff_motion(self) -> tuple[float, float]:
        """After an aborted insertion: up at the config's back-off speed for its abort time."""
        return self.cfg.backoff_speed, self.cfg.abort_time

    def _record(self, t: float, force: float, z: float) -> None:
        """Append the tick to the trace when one is kept: time, force, set-point, height, targets."""
        if self.trace is not None:
            self.trace.append((t, force, self.force_set, z, *self.target))

    def _approach(self, tick: Tick) -> None:
        """Guarded move down; on contact, pivot on the part's low edge (the rotation)."""
        u = self.target
        if self._guarded_move(tick, self.plan.approach_speed, self.cfg.approach_timeout):
            self.force_set = self.plan.rotation_force
            self.pivot_x = u[0] + self.half_width * math.cos(u[4])
            self.pivot_z = u[2] - self.half_width * math.sin(u[4])
            self.admittance_z = 0.0
            self._switch(tick.t, "rotation")

    def _rotation(self, tick: Tick) -> None:
        """Pivot on the contact edge: the edge's x stays put while the part levels out."""
        u, plan = self.target, self.plan
        u[4] = max(0.0, u[4] - plan.rotation_speed * tick.dt)
        self._admit_force(tick.dt, tick.force)
        u[0] = self.pivot_x - self.half_width * math.cos(u[4])
        u[2] = self.pivot_z + self.half_width * math.sin(u[4]) + self.admittance_z
        settle = plan.tilt / plan.rotation_speed + self.cfg.rotation_settle
        if u[4] == 0.0 and tick.elapsed > settle:
            self.state.peak_force = 0.0
            self._switch(tick.t, "insertion")

    def _insertion(self, tick: Tick) -> None:
        """Ramp the force until the hooks give way, stopping at the planned stroke."""
        cfg, st = self.cfg, self.state
        self._comply(tick.dt, tick.elapsed < cfg.centering_time)
        if st.seat_time is None:
            self.force_set = min(
                cfg.insertion_force_max,
                self.plan.rotation_force + self.plan.insertion_force_rate * tick.elapsed,
            )
        if st.snap_time is None:
            self._watch_snap(tick)
        if tick.z <= self.seat_floor:
            if st.stroke_time is None:
                st.stroke_time = tick.t
            self.target[2] = max(self.target[2], tick.z)  # planned stroke reached: stop descending
        else:
            self._admit_force(tick.dt, tick.force)
        self._watch_seat(tick)
        self._end_insertion(tick)

    def _watch_snap(self, tick: Tick) -> None:
        """Snap-through: once engaged in the hooks, the force drops below its peak by snap_drop."""
        cfg, st = self.cfg, self.state
        st.peak_force = max(st.peak_force, tick.force)
        engaged = tick.z < self.hook_top
        if (
            engaged
            and st.peak_force > cfg.snap_min_peak
            and tick.force < (1.0 - cfg.snap_drop) * st.peak_force
        ):
            st.snap_time = tick.t

    def _watch_seat(self, tick: Tick) -> None:
        """Seated: after the snap, the force is back near the hold force at the believed seat."""
        st = self.state
        if (
            st.snap_time is not None
            and st.seat_time is None
            and self._seated(tick, 0.0, self.plan.hold_force)
        ):
            st.seat_time = tick.t
            self.force_set = self.plan.hold_force

    def _end_insertion(self, tick: Tick) -> None:
        """Mate once seated (or, the snap missed, once the stroke ended); abort on time-out."""
        cfg, st, t = self.cfg, self.state, tick.t
        if st.seat_time is not None and t - st.seat_time > cfg.seat_settle:
            self._switch(t, "mating")
        elif st.stroke_time is not None and t - st.stroke_time > cfg.seat_settle:
            self.force_set = self.plan.hold_force  # believes it is done: the snap was missed
            self._switch(t, "mating")
        elif tick.elapsed > cfg.insertion_timeout:
            self._abort(t)

    def _mating(self, tick: Tick) -> None:
        """Hold the force, then move away until the force is released, then a short tail."""
        cfg, st, plan, u, t = self.cfg, self.state, self.plan, self.target, tick.t
        if st.hold_end is None:
            self._comply(tick.dt, False)
            if tick.z > self.seat_floor:
                self._admit_force(tick.dt, tick.force)
            if tick.elapsed > plan.hold_time:
                st.hold_end = t
        elif st.release_time is None:
            u[2] += plan.retract_speed * tick.dt
            u[0] += plan.retract_lateral[0] * tick.dt  # the move-away path is not purely vertical
            u[1] += plan.retract_lateral[1] * tick.dt
            if tick.force < cfg.release_force or t - st.hold_end > cfg.retract_time:
                st.release_time = t
        elif t - st.release_time > cfg.tail_time:
            self._switch(t, "done")

    def _comply(self, dt: float, centre: bool) -> None:
        """Lateral axes: pull towards the believed centre first, then yield to lateral forces."""
        u = self.target
        if centre:
            for i in (0, 1):
                u[i] += self.cfg.lateral_gain * (0.0 - u[i]) * dt
        self._yield_laterally(dt)

    def _admit_force(self, dt: float, f: float) -> None:
        """The shared admittance towards the current set-point; its travel is kept for the
        rotation's pivot."""
        self.admittance_z -= self._admit(dt, f, self.force_set, self.cfg.max_admittance_speed)


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
