"""Configuration every simulated task shares (the snap assembly's config/sim/snap.yaml and the
peg-in-hole's config/sim/peg.yaml): the servo arm's physics, the controller's force loop and the
force/torque sensor model; each task's config (sim/config.py, sim/peg_config.py) extends them."""

from __future__ import annotations

from dataclasses import dataclass

Range = tuple[float, float]
"""A uniform range [low, high] drawn per trial."""


@dataclass(frozen=True)
class ArmPhysicsConfig:
    """MuJoCo constants every simulated task shares: time step, gravity, the contact model
    (friction, softness) and the Cartesian servo arm's gains, mass and inertia."""

    timestep: float = 0.001
    gravity: float = 9.81
    friction: float = 0.3
    contact_solref: tuple[float, float] = (0.008, 1.0)
    contact_solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    arm_kp_lin: float = 20000.0
    """Stiffness (N/m) of the arm's Cartesian position servo."""
    arm_kd_lin: float = 250.0
    arm_kp_rot: float = 60.0
    arm_kd_rot: float = 0.6
    arm_link_mass: float = 0.5
    arm_link_inertia: float = 0.001


@dataclass(frozen=True)
class ForceLoopConfig:
    """The force loop every simulated task's controller shares: force filter, guarded-move
    threshold, admittance gain and ripple, lateral compliance, and when the part counts as seated."""

    contact_force: float = 2.0
    """Guarded move: force (N) that ends the first sub-task."""
    force_gain: float = 0.00015
    """Admittance gain (m/s per N) of the force-controlled axis."""
    force_ripple: float = 0.05
    """Std of the force loop's hunting around its set-point, as a fraction of the set-point."""
    force_ripple_time: float = 0.3
    """Correlation time (s) of that ripple."""
    lateral_compliance: float = 0.0002
    """Lateral admittance (m/s per N): yield to the fixed part's push."""
    force_filter: float = 0.02
    """Time constant (s) of the controller's force low-pass filter."""
    seat_tolerance: float = 0.002
    """Seated only with the tool within this height (m) of the believed seat (the housing's seat,
    the hole's floor) ..."""
    seat_fraction: float = 0.7
    """... and the force back to this fraction of the force the part is pressed with there."""


@dataclass(frozen=True)
class SensorConfig:
    """Force/torque sensor model: output rate, white noise std, low-frequency drift, output filtering."""

    rate_hz: float = 200.0
    """Output rate (Hz) when none is asked for; it must divide the physics rate."""
    noise_force: float = 0.012
    noise_torque: float = 0.0006
    drift_force: float = 0.05
    drift_torque: float = 0.002
    drift_period: Range = (15.0, 60.0)
    """Range (s) of the period of the slow sinusoidal drift, drawn per trial."""
    vibration_force: float = 0.035
    """Std (N) of the arm's structural vibration seen by the sensor (low-pass, see vibration_time)."""
    vibration_torque: float = 0.0015
    vibration_time: float = 0.1
    """Correlation time (s) of the vibration (an Ornstein-Uhlenbeck process)."""
    wander_force: float = 0.06
    """Std (N) of the slow wander of the reading while the arm moves (a second, slower OU process)."""
    wander_torque: float = 0.002
    wander_time: float = 0.8
    quantization_force: float = 0.001
    quantization_torque: float = 0.0001
    session_bias_force: float = 20.0
    """A set simulated in sessions (`rcbht sim --sessions N`) draws per session a constant bias
    uniform in +-this (N) on each force axis: the sensor re-biased between recording days."""
    session_bias_torque: float = 1.0
    """... and on each moment axis (N m)."""
    session_drift_force: float = 0.02
    """... and a drift uniform in +-this (N/s) on each force axis, from each trial's start."""
    session_drift_torque: float = 0.001
    """... and on each moment axis (N m/s)."""


@dataclass(frozen=True)
class CollisionConfig:
    """How hard, how long and how often a collision strikes (drawn uniformly in the ranges)."""

    force: Range = (5.0, 40.0)
    """Peak force (N) of each pulse on the held part, in a direction uniform on the sphere."""
    duration: Range = (0.01, 0.3)
    """How long (s) each pulse pushes (a half-sine: it rises and falls within that time)."""
    delay: Range = (0.1, 1.5)
    """When (s) into its sub-task the first pulse starts (at the sub-task's end if sooner)."""
    second_pulse: float = 0.25
    """Chance of a second pulse, `gap` after the first ends."""
    gap: Range = (0.1, 1.0)
    lever: float = 0.01
    """Largest distance (m) per axis from the part's centre to where the push lands: its moment."""


@dataclass(frozen=True)
class SlipConfig:
    """When and how fast a slow slip slides (its size: the deviation classes' ranges)."""

    delay: Range = (0.1, 1.0)
    """When (s) into its sub-task the slip starts (at the sub-task's end if sooner)."""
    duration: Range = (1.0, 4.0)
    """How long (s) the part takes to slide to its final offset."""
