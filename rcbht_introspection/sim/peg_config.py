"""Typed configuration of the peg-in-hole simulator (config/sim/peg.yaml): geometry, physics,
controller set-points, per-trial variation and the (Robotiq-like) sensor, none in the code."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.sim.arm_config import (
    ArmPhysicsConfig,
    CollisionConfig,
    ForceLoopConfig,
    Range,
    SensorConfig,
)


@dataclass(frozen=True)
class PegGeometryConfig:
    """Dimensions (m) of the square peg, the hole block and the sensor's place on the hand."""

    peg_half: float = 0.008
    """Half width of the square peg."""
    peg_length: float = 0.05
    clearance: float = 0.0002
    """Gap between each peg face and the hole wall facing it."""
    hole_depth: float = 0.015
    chamfer: float = 0.0008
    """Size of the 45 degree lead-in chamfer on the hole's top edge."""
    block_half: float = 0.04
    """Half width of the square block the hole is cut in."""
    floor_thickness: float = 0.01
    grip_height: float = 0.035
    """Height above the peg tip where the gripper holds the peg (the hand's frame)."""
    sensor_height: float = 0.08
    """Height of the force/torque sensor site above the peg tip."""


@dataclass(frozen=True)
class PegPhysicsConfig(ArmPhysicsConfig):
    """MuJoCo constants of the peg-in-hole: the arm's (ArmPhysicsConfig), masses, grip softness."""

    peg_mass: float = 0.06
    gripper_mass: float = 0.4
    """Mass of the gripper between the sensor and the peg (tared away with the peg)."""
    grip_solref: tuple[float, float] = (0.002, 1.0)
    """Softness of the grip (a weld between gripper and peg, switched off when the gripper opens)."""
    grip_solimp: tuple[float, float, float] = (0.99, 0.999, 0.001)


@dataclass(frozen=True)
class PegControllerConfig(ForceLoopConfig):
    """Scripted force/position controller of reach, search, insert and release: the shared force
    loop (ForceLoopConfig, its own gains) and the sub-tasks' set-points and time-outs."""

    start_height: Range = (0.008, 0.035)
    """Initial clearance (m) of the peg tip above the block surface, drawn per trial."""
    reach_speed: Range = (0.008, 0.02)
    contact_force: float = 3.0
    """Guarded move: force (N) that ends the reach."""
    reach_timeout: float = 10.0
    search_force: Range = (5.0, 9.0)
    """Force (N) pressed on the surface while searching."""
    search_speed: Range = (0.005, 0.01)
    """Path speed (m/s) of the spiral search."""
    spiral_pitch: float = 0.0012
    """Radial growth (m) of the spiral per turn; below twice the capture width, so no hole is missed."""
    search_drop: float = 0.00025
    """The hole is found when the tip is this far (m) below the height where contact was made."""
    search_max_speed: float = 0.01
    """Speed limit (m/s) of the admittance loop while searching."""
    search_timeout: float = 15.0
    insert_force: Range = (8.0, 15.0)
    """Force (N) set-point of the insertion; pressed against the hole's floor at the end."""
    insert_speed: Range = (0.005, 0.012)
    """Speed limit (m/s) of the insertion's descent (the admittance loop's limit)."""
    insert_timeout: float = 8.0
    seat_settle: Range = (0.2, 0.5)
    """Time (s) pressed on the floor, once seated (ForceLoopConfig: near the floor, the force back
    to a fraction of the insertion set-point), before the gripper opens."""
    release_pause: Range = (0.2, 0.8)
    """Time (s) the open gripper stays before it moves away."""
    retreat_speed: Range = (0.01, 0.02)
    retreat_time: Range = (0.5, 2.0)
    force_gain: float = 0.0008
    lateral_compliance: float = 0.0004
    """Insertion: yield to the hole walls' push."""


@dataclass(frozen=True)
class PegVariationConfig:
    """Per-trial random variation of a trial (uniform ranges or std)."""

    hole_offset: Range = (0.002, 0.0035)
    """Unknown hole position error (m) as a Chebyshev radius (max of |x|, |y|): always beyond the
    chamfer's capture, so every trial searches; the direction is uniform."""
    offset_z: float = 0.0003
    """Std (m) of the hole's height error."""
    offset_yaw: float = 0.004
    """Std (rad) of the hole's yaw error (the square peg fits within about 0.025 rad)."""
    friction_scale: Range = (0.7, 1.4)
    noise_scale: Range = (0.8, 1.25)
    bias_force: float = 0.5
    bias_torque: float = 0.02


@dataclass(frozen=True)
class PegSensorConfig(SensorConfig):
    """A Robotiq FT 300-like sensor: a 100 Hz stream in 0.01 N / 0.001 N m units, white noise
    about 8x the snap assembly's (fields: SensorConfig)."""

    rate_hz: float = 100.0
    noise_force: float = 0.1
    noise_torque: float = 0.005
    drift_force: float = 0.2
    drift_torque: float = 0.005
    vibration_force: float = 0.05
    vibration_torque: float = 0.002
    wander_force: float = 0.05
    wander_torque: float = 0.002
    quantization_force: float = 0.01
    quantization_torque: float = 0.001


PEG_FAILURES: tuple[str, ...] = ("hole_yaw", "collision")
"""The peg task's failure classes."""


@dataclass(frozen=True)
class PegFailureConfig:
    """The peg task's failure family (`rcbht sim --task peg-in-hole --failures`, `rcbht
    closed-loop --task peg`), its size drawn uniformly, its sign at random."""

    types: tuple[str, ...] = ("hole_yaw",)
    """hole_yaw: the hole turned about the vertical beyond the square peg's fit, so the peg
    lands on the hole's edges and the search or the insertion times out."""
    hole_yaw: Range = (0.035, 0.07)
    """Size (rad) of the hole's yaw error: a few degrees beyond the peg's fit (about 0.025 rad),
    where the peg still drops into the hole's mouth and jams."""
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    """collision (not in the default types): a push on the held peg during reach, search or
    insert (sim/collision.py), a failure whether or not the peg still goes in."""


@dataclass(frozen=True)
class PegConfig:
    """Every number of the peg-in-hole simulator, one object per trial set."""

    geometry: PegGeometryConfig = field(default_factory=PegGeometryConfig)
    physics: PegPhysicsConfig = field(default_factory=PegPhysicsConfig)
    controller: PegControllerConfig = field(default_factory=PegControllerConfig)
    variation: PegVariationConfig = field(default_factory=PegVariationConfig)
    sensor: PegSensorConfig = field(default_factory=PegSensorConfig)
    failures: PegFailureConfig = field(default_factory=PegFailureConfig)
    max_attempts: int = 4
    """Draws of one trial until its peg ends in the hole (a failed draw is redrawn)."""


def check_peg_config(config: PegConfig) -> None:
    """Validation: known failure types, a yaw range of two sizes low to high."""
    fc = config.failures
    for i, name in enumerate(fc.types):
        if name not in PEG_FAILURES:
            known = ", ".join(PEG_FAILURES)
            raise InputError(
                f"unknown failure type {name!r} (known: {known})", field=f"failures.types[{i}]"
            )
    low, high = fc.hole_yaw
    if not 0 < low <= high:
        raise InputError("must be 0 < low <= high", field="failures.hole_yaw")


def load_peg_config(path: Path | str | None = None) -> PegConfig:
    """Load config/sim/peg.yaml (or `path`); unknown keys and wrong types give one-line errors."""
    file = path if path is not None else config_path("sim/peg.yaml")
    return load_config(PegConfig, file, check=check_peg_config)
