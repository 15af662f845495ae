"""MJCF of the peg-in-hole task, built in code from a PegConfig.

A square peg is held by a gripper (a weld between gripper and peg, switched off when the gripper
opens) on a Cartesian servo arm (3 slides + 3 hinges at the peg tip, as the snap assembly's arm);
a 6-axis force/torque sensor site sits between the arm's hand and the gripper. The hole is cut in
a fixed block: four walls with a 45 degree lead-in chamfer on their top inner edge and a floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from rcbht_introspection.sim.model import arm_actuators_xml, arm_joints_xml, prism_vertices
from rcbht_introspection.sim.peg_config import PegConfig

GRIP = "grip"
"""Name of the weld equality that is the gripper's hold on the peg."""
WALL_YAWS: tuple[int, ...] = (0, 90, 180, 270)
"""Yaw (degrees) of the hole's four walls; each wall is modelled in a frame facing +x."""


@dataclass(frozen=True)
class PegPhysics:
    """The per-trial physical variation applied to the model (relative to the config)."""

    hole_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Hole position error (m) with respect to where the controller believes it is."""
    hole_yaw: float = 0.0
    """Hole yaw error (degrees)."""
    friction_scale: float = 1.0
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.03)
    """Initial peg tip x, y, z (m) in the believed hole frame (surface at z = 0)."""


def build_peg_mjcf(config: PegConfig, physics: PegPhysics) -> str:
    """MJCF text of the peg-in-hole scene for one trial."""
    g, p = config.geometry, config.physics
    a = g.peg_half + g.clearance  # half width of the hole
    w = g.block_half
    d = g.hole_depth
    c = g.chamfer
    mu = p.friction * physics.friction_scale
    solref = " ".join(f"{v:.6g}" for v in p.contact_solref)
    solimp = " ".join(f"{v:.6g}" for v in p.contact_solimp)
    grip_solref = " ".join(f"{v:.6g}" for v in p.grip_solref)
    grip_solimp = " ".join(f"{v:.6g}" for v in p.grip_solimp)
    wall_profile = [(a, -d), (w, -d), (w, 0.0), (a + c, 0.0), (a, -c)]
    walls = "".join(
        f'<geom class="block" type="mesh" mesh="wall" euler="0 0 {yaw}"/>' for yaw in WALL_YAWS
    )
    ox, oy, oz = physics.hole_offset
    floor = (
        f'<geom class="block" type="box" size="{w:.6g} {w:.6g} {g.floor_thickness / 2:.6g}" '
        f'pos="0 0 {-d - g.floor_thickness / 2:.6g}"/>'
    )
    block = (
        f'<body name="block" pos="{ox:.6g} {oy:.6g} {oz:.6g}" euler="0 0 {physics.hole_yaw:.6g}">'
        f"{floor}{walls}</body>"
    )
    sx, sy, sz = physics.start_pose
    li = p.arm_link_inertia
    hand = (
        f'<body name="r_hand" pos="{sx:.6g} {sy:.6g} {sz:.6g}" gravcomp="1">'
        f'<inertial pos="0 0 0" mass="{p.arm_link_mass:.6g}" diaginertia="{li:.6g} {li:.6g} {li:.6g}"/>'
        f"{arm_joints_xml('r', p.arm_kd_lin, p.arm_kd_rot)}"
        f'<body name="gripper" pos="0 0 {g.grip_height:.6g}">'
        f'<inertial pos="0 0 0.01" mass="{p.gripper_mass:.6g}" diaginertia="2e-4 2e-4 2e-4"/>'
        f'<site name="r_ft" pos="0 0 {g.sensor_height - g.grip_height:.6g}"/>'
        '<geom type="box" size="0.02 0.012 0.01" pos="0 0 0.01" contype="0" conaffinity="0" '
        'rgba=".6 .6 .6 1"/>'
        "</body></body>"
    )
    h = g.peg_half
    peg = (
        f'<body name="peg" pos="{sx:.6g} {sy:.6g} {sz + g.peg_length / 2:.6g}">'
        '<freejoint name="peg"/>'
        f'<geom class="peg" type="box" size="{h:.6g} {h:.6g} {g.peg_length / 2:.6g}" '
        f'mass="{p.peg_mass:.6g}"/>'
        "</body>"
    )
    return f"""<mujoco model="peg_in_hole">
<compiler angle="degree" autolimits="true"/>
<option timestep="{p.timestep:.6g}" gravity="0 0 {-p.gravity:.6g}" integrator="implicitfast">
<flag multiccd="enable"/>
</option>
<default>
<default class="block"><geom contype="2" conaffinity="1" friction="{mu:.6g} 0.005 0.0001"
 solref="{solref}" solimp="{solimp}" rgba=".3 .3 .35 1"/></default>
<default class="peg"><geom contype="1" conaffinity="2" friction="{mu:.6g} 0.005 0.0001"
 solref="{solref}" solimp="{solimp}" rgba=".8 .6 .2 1"/></default>
</default>
<asset>
<mesh name="wall" vertex="{prism_vertices(wall_profile, -w, w)}"/>
</asset>
<worldbody>
{block}
{hand}
{peg}
</worldbody>
<equality>
<weld name="{GRIP}" body1="gripper" body2="peg" solref="{grip_solref}" solimp="{grip_solimp}"/>
</equality>
<actuator>
{arm_actuators_xml("r", p.arm_kp_lin, p.arm_kp_rot)}
</actuator>
<sensor>
<force name="r_force" site="r_ft"/><torque name="r_torque" site="r_ft"/>
</sensor>
</mujoco>
"""


def build_peg_model(config: PegConfig, physics: PegPhysics) -> mujoco.MjModel:
    """Compile the trial's MJCF into a MuJoCo model."""
    return mujoco.MjModel.from_xml_string(build_peg_mjcf(config, physics))
