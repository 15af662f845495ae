"""Typed configuration of the snap-assembly simulator (config/sim/snap.yaml): every physical constant,
controller gain, variation range and failure offset lives here, none in the code."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from rcbht_introspection.config_files import config_path, load_config
from rcbht_introspection.errors import InputError
from rcbht_introspection.sim.arm_config import ArmPhysicsConfig as ArmPhysicsConfig
from rcbht_introspection.sim.arm_config import CollisionConfig, SlipConfig
from rcbht_introspection.sim.arm_config import ForceLoopConfig as ForceLoopConfig
from rcbht_introspection.sim.arm_config import Range as Range
from rcbht_introspection.sim.arm_config import SensorConfig as SensorConfig

# ArmPhysicsConfig, ForceLoopConfig, Range and SensorConfig are shared with the peg-in-hole task
# (sim/arm_config.py) and re-exported here, where they used to live

FailureFamily = Literal["misalignment", "jamming", "missed_snap", "deviation", "collision", "slip"]
"""The failure families the simulator can produce (each by its offset range in FailureConfig)."""
FailureType = str
"""A failure class: a family other than deviation, or `deviation_<dirs>` (sim/failures.py)."""


@dataclass(frozen=True)
class GeometryConfig:
    """Dimensions (m) of the male camera part and the female snap housing."""

    male_half: float = 0.02
    """Half width of the male part's lower block (square footprint)."""
    male_lower_height: float = 0.005
    """Height of the lower block; its top edge is the shoulder the snap hooks catch."""
    male_neck_half: float = 0.014
    male_neck_height: float = 0.02
    clearance: float = 0.0004
    """Gap between the male block and the housing's inner faces."""
    base_half: float = 0.04
    base_thickness: float = 0.01
    wall_height: float = 0.011
    wall_thickness: float = 0.004
    chamfer: float = 0.0025
    """Size of the 45 degree lead-in chamfer on the top inner edge of walls and beams."""
    beam_half_width: float = 0.011
    beam_thickness: float = 0.002
    beam_root_depth: float = 0.008
    """The beams are rooted this far below the housing floor (their lever arm grows with it)."""
    hook_depth: float = 0.0014
    """How far each snap hook protrudes into the opening (the beam deflection needed)."""
    hook_ramp: float = 0.003
    """Vertical length of the hook's lead-in ramp."""
    hook_play: float = 0.0005
    """Vertical gap between the seated male's shoulder and the hook's retention face."""
    sensor_height: float = 0.07
    """Height of the force/torque sensor site above the male part's bottom face."""


@dataclass(frozen=True)
class PhysicsConfig(ArmPhysicsConfig):
    """MuJoCo constants of the snap assembly: the arm's (ArmPhysicsConfig), the parts' masses,
    the beams' stiffness and the holding arm's gains."""

    male_mass: float = 0.12
    hand_mass: float = 0.35
    female_mass: float = 0.25
    beam_stiffness: float = 0.65
    """Rotational stiffness (N m/rad) of each cantilever beam about its root."""
    beam_damping: float = 0.004
    beam_armature: float = 1.0e-5
    holder_kp_lin: float = 15000.0
    """Stiffness of the second arm holding the female part (two-arm scenario)."""
    holder_kd_lin: float = 220.0
    holder_kp_rot: float = 80.0
    holder_kd_rot: float = 0.8


@dataclass(frozen=True)
class ControllerConfig(ForceLoopConfig):
    """Scripted hybrid force/position controller: the shared force loop (ForceLoopConfig),
    speeds, force set-points, gains, time-outs."""

    start_height: Range = (0.028, 0.04)
    """Initial clearance (m) of the male bottom above the housing top, drawn per trial."""
    approach_speed: Range = (0.005, 0.008)
    approach_timeout: float = 15.0
    tilt: Range = (0.12, 0.22)
    """Initial side-approach tilt (rad) about the y axis, removed during the rotation sub-task."""
    rotation_speed: Range = (0.025, 0.05)
    """Angular speed (rad/s) of the alignment rotation."""
    rotation_force: Range = (5.0, 9.0)
    """Force (N) kept on the contact while rotating."""
    rotation_settle: float = 0.6
    insertion_force_rate: Range = (10.0, 18.0)
    """Ramp (N/s) of the insertion force set-point."""
    insertion_force_max: float = 45.0
    insertion_timeout: float = 8.0
    insertion_stroke: float = 0.002
    """Planned stroke: the insertion never goes deeper than this below the believed seat height."""
    snap_drop: float = 0.25
    """Snap-through detected when force falls by this fraction below its insertion peak."""
    snap_min_peak: float = 13.0
    seat_settle: float = 0.3
    """Time (s) pressed once seated (ForceLoopConfig: near the seat, the force back to a fraction
    of the hold force), or once the planned stroke ended, before the mating."""
    hold_force: Range = (22.0, 34.0)
    hold_time: Range = (3.0, 14.0)
    retract_speed: Range = (0.00012, 0.0003)
    """Move-away speed (m/s) after the hold; stops at release_force or retract_time."""
    retract_lateral: Range = (-0.0003, 0.0003)
    """Range of the move-away path's lateral speed (m/s) in x and y."""
    release_force: float = 3.0
    retract_time: float = 9.0
    tail_time: float = 0.5
    abort_time: float = 1.5
    """After a failed insertion: time spent backing off before the trial ends."""
    backoff_speed: float = 0.004
    """Upward speed (m/s) of the back-off after an aborted insertion."""
    max_admittance_speed: float = 0.004
    """Speed limit (m/s) of the admittance loop."""
    lateral_gain: float = 1.5
    """Proportional gain (1/s) pulling the lateral position towards the believed hole centre."""
    centering_time: float = 1.0
    """Insertion: the lateral servo centres the part this long (s), then only complies."""
    holder_force: float = 2.0
    """Two-arm: upward preload (N) of the holding arm; its admittance yields to the insertion force."""
    holder_compliance: float = 0.00015
    """Two-arm: holder's admittance (m per N) around its home pose."""


@dataclass(frozen=True)
class VariationConfig:
    """Per-trial random variation (uniform ranges or std) of a successful trial."""

    offset_xy: float = 0.0006
    """Std (m) of the unknown female pose offset in x and y."""
    offset_z: float = 0.0005
    offset_yaw: float = 0.01
    """Std (rad) of the female yaw offset."""
    friction_scale: Range = (0.75, 1.3)
    stiffness_scale: Range = (0.8, 1.25)
    noise_scale: Range = (0.7, 1.4)
    bias_force: float = 0.25
    bias_torque: float = 0.01


@dataclass(frozen=True)
class FailureConfig:
    """Offsets that produce each failure type (sampled uniformly in the ranges)."""

    types: tuple[FailureFamily, ...] = ("misalignment", "jamming", "missed_snap", "deviation")
    """Families that `--failures` cycles through; `deviation` stands for each deviation class."""
    misalignment_xy: Range = (0.004, 0.007)
    """Lateral offset (m) beyond the chamfer's capture range: the male lands on the housing top."""
    jamming_yaw: Range = (0.12, 0.2)
    """Yaw offset (rad) that wedges the male's corners on the housing walls."""
    missed_snap_z: Range = (0.004, 0.007)
    """Housing lower than believed (m): the insertion stroke ends before the hooks engage."""
    deviation_classes: tuple[str, ...] = ("x+", "x-", "y+", "y-", "r+", "r-", "x+y+", "x-y-")
    """Deviation classes: signed directions of the held part's slip in the hand, axes in the
    order x, y, r (yaw); each is its own failure class `deviation_<dirs>`."""
    deviation_xy: Range = (0.0015, 0.0025)
    """Size (m) of the part's slip in x or y along each deviated axis."""
    deviation_yaw: Range = (0.04, 0.08)
    """Size (rad) of the part's yaw slip about the tool axis."""
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    slip: SlipConfig = field(default_factory=SlipConfig)
    """The held part sliding in the hand over seconds during a contact sub-task (sim/slip.py),
    to a size in the deviation ranges along one axis: a failure whether or not it still seats."""
    """A push on the held part during a sub-task (sim/collision.py): a failure whether or not
    the part still seats."""
    max_attempts: int = 4


@dataclass(frozen=True)
class SimConfig:
    """Every number the simulator uses, one object per trial set."""

    geometry: GeometryConfig = field(default_factory=GeometryConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    variation: VariationConfig = field(default_factory=VariationConfig)
    failures: FailureConfig = field(default_factory=FailureConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)


DEVIATION = "deviation"
DEVIATION_AXES: tuple[str, ...] = ("x", "y", "r")
"""Deviation axes in the order a class names them: x, y (m) and r (yaw, rad)."""
_DIRS = re.compile(r"(x[+-])?(y[+-])?(r[+-])?")


def deviation_signs(dirs: str) -> dict[str, int]:
    """Axis -> sign (+1/-1) of a deviation class such as `x+y-` (axes in order x, y, r)."""
    match = _DIRS.fullmatch(dirs)
    if not dirs or match is None:
        raise InputError(
            f"bad deviation class {dirs!r}: signed axes in the order x, y, r, e.g. x+, y-r+",
            field="deviation_classes",
        )
    return {part[0]: 1 if part[1] == "+" else -1 for part in match.groups() if part}


def deviation_dirs(failure: FailureType) -> str | None:
    """The directions of a deviation class name (`deviation_x+` -> `x+`), else None."""
    prefix = f"{DEVIATION}_"
    return failure[len(prefix) :] if failure.startswith(prefix) else None


def failure_classes(failures: FailureConfig) -> tuple[FailureType, ...]:
    """Every failure class of the config, in cycle order: the families, `deviation` expanded
    into one class per configured direction set."""
    out: list[FailureType] = []
    for family in failures.types:
        if family == DEVIATION:
            out.extend(f"{DEVIATION}_{dirs}" for dirs in failures.deviation_classes)
        else:
            out.append(family)
    return tuple(out)


def check_failures(config: SimConfig) -> None:
    """Validation of the failure section: well-formed, distinct deviation classes."""
    classes = config.failures.deviation_classes
    for i, dirs in enumerate(classes):
        try:
            deviation_signs(dirs)
        except InputError as exc:
            raise InputError(exc.message, field=f"failures.deviation_classes[{i}]") from None
        if dirs in classes[:i]:
            raise InputError(
                f"deviation class {dirs!r} listed twice", field=f"failures.deviation_classes[{i}]"
            )
    if DEVIATION in config.failures.types and not classes:
        raise InputError("deviation needs at least one class", field="failures.deviation_classes")


def load_sim_config(path: Path | str | None = None) -> SimConfig:
    """Load config/sim/snap.yaml (or `path`); unknown keys and wrong types give one-line errors."""
    path = path if path is not None else config_path("sim/snap.yaml")
    return load_config(SimConfig, path, check=check_failures)
