"""MJCF of the cantilever-snap camera assembly, built in code from a SimConfig.

The male part (camera) is held rigidly by the right arm's end effector; a 6-axis force/torque
sensor site sits between the hand and the part. The female housing has rigid walls with 45 degree
lead-in chamfers and four cantilever snap beams, each a hinged spring latch with a hook (lead-in
ramp, flat retention face). The arm, its hand, sensors and contact classes are the shared ones
(sim/arm_model.py). In the two-arm scenario the housing is held by a second (left) servo arm with
its own sensor site; otherwise it is fixed to the world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rcbht_introspection.sim.arm_model import (
    SIDES,
    arm_actuators_xml,
    arm_hand_xml,
    contact_class_xml,
    ft_sensor_xml,
    mjcf_document,
    prism_vertices,
)
from rcbht_introspection.sim.config import GeometryConfig, SimConfig


@dataclass(frozen=True)
class TrialPhysics:
    """The per-trial physical variation applied to the model (all relative to the config)."""

    female_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Housing position error (m) with respect to where the controller believes it is."""
    female_yaw: float = 0.0
    friction_scale: float = 1.0
    stiffness_scale: float = 1.0
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.05)
    """Initial tool centre point x, y, z (m); the initial pitch is set on the arm's joint."""
    part_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The held part's displacement in the hand: x, y (m) and yaw (rad) about the tool axis; the
    controller does not know it (a deviation failure: the part slipped in the gripper)."""


def _housing_meshes(g: GeometryConfig) -> list[str]:
    """The housing's meshes: a wall half on either side of its beam, a beam and a hook."""
    a = g.male_half + g.clearance  # inner half width of the housing opening
    h, c, bt, bw = g.wall_height, g.chamfer, g.beam_thickness, g.beam_half_width
    z_tip = g.male_lower_height + g.hook_play  # height of the hooks' retention face
    y_in = bw + 0.0008
    y_out = a + g.wall_thickness
    wall_profile = [(a, 0.0), (y_out, 0.0), (y_out, h), (a + c, h), (a, h - c)]
    beam_c = min(c, 0.9 * bt)
    root = -g.beam_root_depth
    beam_profile = [
        (-bt / 2, root),
        (bt / 2, root),
        (bt / 2, h),
        (-bt / 2 + beam_c, h),
        (-bt / 2, h - beam_c),
    ]
    hook_profile = [
        (-bt / 2, z_tip),
        (-bt / 2 - g.hook_depth, z_tip),
        (-bt / 2, z_tip + g.hook_ramp),
    ]
    return [
        f'<mesh name="wall_lo" vertex="{prism_vertices(wall_profile, -y_out, -y_in)}"/>',
        f'<mesh name="wall_hi" vertex="{prism_vertices(wall_profile, y_in, y_out)}"/>',
        f'<mesh name="beam" vertex="{prism_vertices(beam_profile, -bw, bw)}"/>',
        f'<mesh name="hook" vertex="{prism_vertices(hook_profile, -bw, bw)}"/>',
    ]


def _snap_beam_xml(i: int, yaw: int, config: SimConfig, physics: TrialPhysics) -> str:
    """Cantilever snap beam `i` on the side at `yaw`: a hinged spring latch carrying its hook."""
    g, p = config.geometry, config.physics
    h, bt = g.wall_height, g.beam_thickness
    k_beam = p.beam_stiffness * physics.stiffness_scale
    ang = np.deg2rad(yaw)
    r = g.male_half + g.clearance + bt / 2
    beam_mass = 0.004
    return (
        f'<body name="beam{i}" pos="{r * np.cos(ang):.6g} {r * np.sin(ang):.6g} 0" euler="0 0 {yaw}">'
        f'<joint name="beam{i}" type="hinge" pos="0 0 {-g.beam_root_depth:.6g}" axis="0 1 0" stiffness="{k_beam:.6g}" '
        f'damping="{p.beam_damping:.6g}" armature="{p.beam_armature:.6g}" '
        'range="-0.05 0.3" limited="true"/>'
        f'<inertial pos="0 0 {h / 2:.6g}" mass="{beam_mass}" diaginertia="2e-7 2e-7 2e-8"/>'
        f'<geom name="beam{i}" class="female" type="mesh" mesh="beam"/>'
        f'<geom name="hook{i}" class="female" type="mesh" mesh="hook"/>'
        "</body>"
    )


def _housing_xml(config: SimConfig, physics: TrialPhysics) -> str:
    """The housing's geoms in its own frame: floor, two wall halves and a snap beam per side."""
    g = config.geometry
    base = (
        f'<geom name="floor" class="female" type="box" size="{g.base_half:.6g} {g.base_half:.6g} '
        f'{g.base_thickness / 2:.6g}" pos="0 0 {-g.base_thickness / 2:.6g}"/>'
    )
    walls = [
        f'<geom name="wall{i}_{half}" class="female" type="mesh" mesh="wall_{half}" euler="0 0 {yaw}"/>'
        for i, yaw in enumerate(SIDES)
        for half in ("lo", "hi")
    ]
    beams = [_snap_beam_xml(i, yaw, config, physics) for i, yaw in enumerate(SIDES)]
    return "\n".join([base, *walls, *beams])


def _female_xml(config: SimConfig, physics: TrialPhysics, two_arm: bool) -> str:
    """The housing's body: fixed to the world, or (two-arm) held by the left arm's hand above
    its sensor site."""
    g, p = config.geometry, config.physics
    ox, oy, oz = physics.female_offset
    housing = _housing_xml(config, physics)
    if not two_arm:
        return (
            f'<body name="female" pos="{ox:.6g} {oy:.6g} {oz:.6g}" '
            f'euler="0 0 {physics.female_yaw:.6g}">{housing}</body>'
        )
    held = (
        '<geom type="cylinder" size="0.02 0.015" pos="0 0 -0.015" contype="0" conaffinity="0" rgba=".5 .5 .5 1"/>'
        f'<body name="female" pos="0 0 {g.base_thickness + 0.03:.6g}">'
        f'<inertial pos="0 0 -0.005" mass="{p.female_mass:.6g}" diaginertia="1e-4 1e-4 1e-4"/>'
        f'<site name="l_ft" pos="0 0 {-g.base_thickness - 0.02:.6g}" euler="180 0 0"/>'
        f"{housing}</body>"
    )
    pos = (ox, oy, oz - g.base_thickness - 0.03)
    damping = (p.holder_kd_lin, p.holder_kd_rot)
    return arm_hand_xml("l", pos, p, damping, held, yaw=physics.female_yaw)


def _male_xml(config: SimConfig, physics: TrialPhysics) -> str:
    """The right arm's hand holding the male part (displaced by the trial's part offset) under
    its sensor site."""
    g, p = config.geometry, config.physics
    m, hl = g.male_half, g.male_lower_height
    n, hn = g.male_neck_half, g.male_neck_height
    dx, dy, dyaw = physics.part_offset
    turn = f' euler="0 0 {math.degrees(dyaw):.6g}"' if dyaw else ""  # no attribute when centred
    part = (
        '<body name="male" pos="0 0 0">'
        f'<inertial pos="{dx:.6g} {dy:.6g} {hl:.6g}" mass="{p.male_mass + p.hand_mass:.6g}" '
        'diaginertia="2e-4 2e-4 2e-4"/>'
        f'<site name="r_ft" pos="0 0 {g.sensor_height:.6g}"/>'
        f'<geom name="male_block" class="male" type="box" size="{m:.6g} {m:.6g} {hl / 2:.6g}" '
        f'pos="{dx:.6g} {dy:.6g} {hl / 2:.6g}"{turn}/>'
        f'<geom name="male_neck" class="male" type="box" size="{n:.6g} {n:.6g} {hn / 2:.6g}" '
        f'pos="{dx:.6g} {dy:.6g} {hl + hn / 2:.6g}"{turn}/>'
        f'<geom type="cylinder" size="0.02 0.02" pos="0 0 {g.sensor_height + 0.02:.6g}" '
        'contype="0" conaffinity="0" rgba=".6 .6 .6 1"/>'
        "</body>"
    )
    return arm_hand_xml("r", physics.start_pose, p, (p.arm_kd_lin, p.arm_kd_rot), part)


def build_mjcf(config: SimConfig, physics: TrialPhysics, two_arm: bool = False) -> str:
    """MJCF text of the assembly for one trial."""
    p = config.physics
    style = 'density="1200"'
    defaults = [
        contact_class_xml("female", False, p, physics.friction_scale, f'rgba=".2 .4 .8 1" {style}'),
        contact_class_xml("male", True, p, physics.friction_scale, f'rgba=".8 .5 .2 1" {style}'),
    ]
    actuators = [arm_actuators_xml("r", p.arm_kp_lin, p.arm_kp_rot)]
    sensors = ft_sensor_xml("r")
    if two_arm:
        actuators.append(arm_actuators_xml("l", p.holder_kp_lin, p.holder_kp_rot))
        sensors += ft_sensor_xml("l")
    bodies = [_female_xml(config, physics, two_arm), _male_xml(config, physics)]
    return mjcf_document(
        "snap_assembly", p, defaults, _housing_meshes(config.geometry), bodies, actuators, sensors
    )


def build_model(config: SimConfig, physics: TrialPhysics, two_arm: bool = False) -> mujoco.MjModel:
    """Compile the trial's MJCF into a MuJoCo model."""
    return mujoco.MjModel.from_xml_string(build_mjcf(config, physics, two_arm))
