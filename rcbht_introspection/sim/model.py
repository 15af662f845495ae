"""MJCF of the cantilever-snap camera assembly, built in code from a SimConfig.

The male part (camera) is held rigidly by the right arm's end effector; a 6-axis force/torque
sensor site sits between the hand and the part. The female housing has rigid walls with 45 degree
lead-in chamfers and four cantilever snap beams, each a hinged spring latch with a hook (lead-in
ramp, flat retention face). The arm is a Cartesian servo (3 slides + 3 hinges at the tool centre
point) whose compliance is its finite servo stiffness. In the two-arm scenario the housing is held
by a second (left) servo arm with its own sensor site; otherwise it is fixed to the world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rcbht_introspection.sim.config import SimConfig

ARM_JOINTS: tuple[str, ...] = ("x", "y", "z", "yaw", "pitch", "roll")
_JOINT_AXES: dict[str, str] = {
    "x": "1 0 0", "y": "0 1 0", "z": "0 0 1", "yaw": "0 0 1", "pitch": "0 1 0", "roll": "1 0 0",
}  # fmt: skip
SIDES: tuple[int, ...] = (0, 90, 180, 270)
"""Yaw (degrees) of the four housing sides; each side is modelled in a frame facing +x."""


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


def prism_vertices(points_xz: list[tuple[float, float]], y0: float, y1: float) -> str:
    """Vertex list of a convex prism: a polygon in the x-z plane extruded from y0 to y1."""
    verts = [(x, y, z) for y in (y0, y1) for x, z in points_xz]
    return " ".join(f"{v:.6g}" for p in verts for v in p)


def arm_joints_xml(prefix: str, kd_lin: float, kd_rot: float) -> str:
    """Six servo joints of a Cartesian arm: slides first (world axes), then hinges at the TCP."""
    lines = []
    for name in ARM_JOINTS:
        kind = "slide" if name in ("x", "y", "z") else "hinge"
        damping = kd_lin if kind == "slide" else kd_rot
        lines.append(
            f'<joint name="{prefix}_{name}" type="{kind}" axis="{_JOINT_AXES[name]}" '
            f'damping="{damping:.6g}" limited="false"/>'
        )
    return "\n".join(lines)


def arm_actuators_xml(prefix: str, kp_lin: float, kp_rot: float) -> str:
    """Position servos (the arm controller's inner loop) on the six arm joints."""
    lines = []
    for name in ARM_JOINTS:
        kp = kp_lin if name in ("x", "y", "z") else kp_rot
        lines.append(
            f'<position name="{prefix}_{name}" joint="{prefix}_{name}" kp="{kp:.6g}" '
            'ctrllimited="false"/>'
        )
    return "\n".join(lines)


def build_mjcf(config: SimConfig, physics: TrialPhysics, two_arm: bool = False) -> str:
    """MJCF text of the assembly for one trial."""
    g, p = config.geometry, config.physics
    a = g.male_half + g.clearance  # inner half width of the housing opening
    h = g.wall_height
    c = g.chamfer
    tw = g.wall_thickness
    bt = g.beam_thickness
    z_tip = g.male_lower_height + g.hook_play  # height of the hooks' retention face
    mu = p.friction * physics.friction_scale
    k_beam = p.beam_stiffness * physics.stiffness_scale
    solref = " ".join(f"{v:.6g}" for v in p.contact_solref)
    solimp = " ".join(f"{v:.6g}" for v in p.contact_solimp)

    meshes: list[str] = []
    wall_geoms: list[str] = []
    beams: list[str] = []
    y_in = g.beam_half_width + 0.0008
    y_out = a + tw
    wall_profile = [(a, 0.0), (a + tw, 0.0), (a + tw, h), (a + c, h), (a, h - c)]
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
    bw = g.beam_half_width
    meshes.append(f'<mesh name="wall_lo" vertex="{prism_vertices(wall_profile, -y_out, -y_in)}"/>')
    meshes.append(f'<mesh name="wall_hi" vertex="{prism_vertices(wall_profile, y_in, y_out)}"/>')
    meshes.append(f'<mesh name="beam" vertex="{prism_vertices(beam_profile, -bw, bw)}"/>')
    meshes.append(f'<mesh name="hook" vertex="{prism_vertices(hook_profile, -bw, bw)}"/>')
    beam_mass = 0.004
    for i, yaw in enumerate(SIDES):
        q = f'euler="0 0 {yaw}"'
        wall_geoms.append(
            f'<geom name="wall{i}_lo" class="female" type="mesh" mesh="wall_lo" {q}/>'
        )
        wall_geoms.append(
            f'<geom name="wall{i}_hi" class="female" type="mesh" mesh="wall_hi" {q}/>'
        )
        ang = np.deg2rad(yaw)
        r = a + bt / 2
        beams.append(
            f'<body name="beam{i}" pos="{r * np.cos(ang):.6g} {r * np.sin(ang):.6g} 0" {q}>'
            f'<joint name="beam{i}" type="hinge" pos="0 0 {root:.6g}" axis="0 1 0" stiffness="{k_beam:.6g}" '
            f'damping="{p.beam_damping:.6g}" armature="{p.beam_armature:.6g}" '
            'range="-0.05 0.3" limited="true"/>'
            f'<inertial pos="0 0 {h / 2:.6g}" mass="{beam_mass}" diaginertia="2e-7 2e-7 2e-8"/>'
            f'<geom name="beam{i}" class="female" type="mesh" mesh="beam"/>'
            f'<geom name="hook{i}" class="female" type="mesh" mesh="hook"/>'
            "</body>"
        )
    base = (
        f'<geom name="floor" class="female" type="box" size="{g.base_half:.6g} {g.base_half:.6g} '
        f'{g.base_thickness / 2:.6g}" pos="0 0 {-g.base_thickness / 2:.6g}"/>'
    )
    ox, oy, oz = physics.female_offset
    female_inner = "\n".join([base, *wall_geoms, *beams])
    if two_arm:
        female = (
            f'<body name="l_hand" pos="{ox:.6g} {oy:.6g} {oz - g.base_thickness - 0.03:.6g}" '
            f'euler="0 0 {physics.female_yaw:.6g}" gravcomp="1">'
            f'<inertial pos="0 0 0" mass="{p.arm_link_mass:.6g}" '
            f'diaginertia="{p.arm_link_inertia:.6g} {p.arm_link_inertia:.6g} {p.arm_link_inertia:.6g}"/>'
            f"{arm_joints_xml('l', p.holder_kd_lin, p.holder_kd_rot)}"
            '<geom type="cylinder" size="0.02 0.015" pos="0 0 -0.015" contype="0" conaffinity="0" rgba=".5 .5 .5 1"/>'
            f'<body name="female" pos="0 0 {g.base_thickness + 0.03:.6g}">'
            f'<inertial pos="0 0 -0.005" mass="{p.female_mass:.6g}" diaginertia="1e-4 1e-4 1e-4"/>'
            f'<site name="l_ft" pos="0 0 {-g.base_thickness - 0.02:.6g}" euler="180 0 0"/>'
            f"{female_inner}</body></body>"
        )
    else:
        female = (
            f'<body name="female" pos="{ox:.6g} {oy:.6g} {oz:.6g}" '
            f'euler="0 0 {physics.female_yaw:.6g}">{female_inner}</body>'
        )

    sx, sy, sz = physics.start_pose
    m = g.male_half
    hl = g.male_lower_height
    n = g.male_neck_half
    hn = g.male_neck_height
    dx, dy, dyaw = physics.part_offset
    turn = f' euler="0 0 {math.degrees(dyaw):.6g}"' if dyaw else ""  # no attribute when centred
    male = (
        f'<body name="r_hand" pos="{sx:.6g} {sy:.6g} {sz:.6g}" gravcomp="1">'
        f'<inertial pos="0 0 0" mass="{p.arm_link_mass:.6g}" '
        f'diaginertia="{p.arm_link_inertia:.6g} {p.arm_link_inertia:.6g} {p.arm_link_inertia:.6g}"/>'
        f"{arm_joints_xml('r', p.arm_kd_lin, p.arm_kd_rot)}"
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
        "</body></body>"
    )
    actuators = arm_actuators_xml("r", p.arm_kp_lin, p.arm_kp_rot)
    if two_arm:
        actuators += "\n" + arm_actuators_xml("l", p.holder_kp_lin, p.holder_kp_rot)
    sensors = '<force name="r_force" site="r_ft"/><torque name="r_torque" site="r_ft"/>'
    if two_arm:
        sensors += '<force name="l_force" site="l_ft"/><torque name="l_torque" site="l_ft"/>'
    return f"""<mujoco model="snap_assembly">
<compiler angle="degree" autolimits="true"/>
<option timestep="{p.timestep:.6g}" gravity="0 0 {-p.gravity:.6g}" integrator="implicitfast">
<flag multiccd="enable"/>
</option>
<default>
<default class="female"><geom contype="2" conaffinity="1" friction="{mu:.6g} 0.005 0.0001"
 solref="{solref}" solimp="{solimp}" rgba=".2 .4 .8 1" density="1200"/></default>
<default class="male"><geom contype="1" conaffinity="2" friction="{mu:.6g} 0.005 0.0001"
 solref="{solref}" solimp="{solimp}" rgba=".8 .5 .2 1" density="1200"/></default>
</default>
<asset>
{chr(10).join(meshes)}
</asset>
<worldbody>
{female}
{male}
</worldbody>
<actuator>
{actuators}
</actuator>
<sensor>
{sensors}
</sensor>
</mujoco>
"""


def build_model(config: SimConfig, physics: TrialPhysics, two_arm: bool = False) -> mujoco.MjModel:
    """Compile the trial's MJCF into a MuJoCo model."""
    return mujoco.MjModel.from_xml_string(build_mjcf(config, physics, two_arm))
