"""MJCF of the peg-in-hole task, built in code from a PegConfig.

A square peg is held by a gripper (a weld between gripper and peg, switched off when the gripper
opens) on the shared Cartesian servo arm (sim/arm_model.py: 3 slides + 3 hinges at the peg tip);
a 6-axis force/torque sensor site sits between the arm's hand and the gripper. The hole is cut in
a fixed block: four walls with a 45 degree lead-in chamfer on their top inner edge and a floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from rcbht_introspection.sim import arm_model
from rcbht_introspection.sim.arm_model import (
    arm_actuators_xml,
    arm_hand_xml,
    contact_class_xml,
    ft_sensor_xml,
    mjcf_document,
    numbers,
    prism_vertices,
)
from rcbht_introspection.sim.peg_config import PegConfig

GRIP = "grip"
"""Name of the weld equality that is the gripper's hold on the peg."""
WALL_YAWS = arm_model.SIDES
"""Yaw (degrees) of the hole's four walls: the sides of a square opening, as the snap housing's."""


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


def _block_xml(config: PegConfig, physics: PegPhysics) -> str:
    """The block the hole is cut in: its floor and four chamfered walls, at the trial's pose."""
    g = config.geometry
    w, d = g.block_half, g.hole_depth
    walls = "".join(
        f'<geom class="block" type="mesh" mesh="wall" euler="0 0 {yaw}"/>' for yaw in WALL_YAWS
    )
    ox, oy, oz = physics.hole_offset
    floor = (
        f'<geom class="block" type="box" size="{w:.6g} {w:.6g} {g.floor_thickness / 2:.6g}" '
        f'pos="0 0 {-d - g.floor_thickness / 2:.6g}"/>'
    )
    return (
        f'<body name="block" pos="{ox:.6g} {oy:.6g} {oz:.6g}" euler="0 0 {physics.hole_yaw:.6g}">'
        f"{floor}{walls}</body>"
    )


def _wall_mesh(config: PegConfig) -> str:
    """The mesh of one hole wall: the block's quarter with the lead-in chamfer on its edge."""
    g = config.geometry
    a = g.peg_half + g.clearance  # half width of the hole
    w, d, c = g.block_half, g.hole_depth, g.chamfer
    wall_profile = [(a, -d), (w, -d), (w, 0.0), (a + c, 0.0), (a, -c)]
    return f'<mesh name="wall" vertex="{prism_vertices(wall_profile, -w, w)}"/>'


def _gripper_xml(config: PegConfig) -> str:
    """The gripper on the arm's hand, with the sensor site between them."""
    g, p = config.geometry, config.physics
    return (
        f'<body name="gripper" pos="0 0 {g.grip_height:.6g}">'
        f'<inertial pos="0 0 0.01" mass="{p.gripper_mass:.6g}" diaginertia="2e-4 2e-4 2e-4"/>'
        f'<site name="r_ft" pos="0 0 {g.sensor_height - g.grip_height:.6g}"/>'
        '<geom type="box" size="0.02 0.012 0.01" pos="0 0 0.01" contype="0" conaffinity="0" '
        'rgba=".6 .6 .6 1"/>'
        "</body>"
    )


def build_peg_mjcf(config: PegConfig, physics: PegPhysics) -> str:
    """MJCF text of the peg-in-hole scene for one trial."""
    g, p = config.geometry, config.physics
    sx, sy, sz = physics.start_pose
    damping = (p.arm_kd_lin, p.arm_kd_rot)
    hand = arm_hand_xml("r", physics.start_pose, p, damping, _gripper_xml(config))
    h = g.peg_half
    peg = (
        f'<body name="peg" pos="{sx:.6g} {sy:.6g} {sz + g.peg_length / 2:.6g}">'
        '<freejoint name="peg"/>'
        f'<geom class="peg" type="box" size="{h:.6g} {h:.6g} {g.peg_length / 2:.6g}" '
        f'mass="{p.peg_mass:.6g}"/>'
        "</body>"
    )
    defaults = [
        contact_class_xml("block", False, p, physics.friction_scale, 'rgba=".3 .3 .35 1"'),
        contact_class_xml("peg", True, p, physics.friction_scale, 'rgba=".8 .6 .2 1"'),
    ]
    weld = (
        f'<weld name="{GRIP}" body1="gripper" body2="peg" solref="{numbers(p.grip_solref)}" '
        f'solimp="{numbers(p.grip_solimp)}"/>'
    )
    return mjcf_document(
        "peg_in_hole",
        p,
        defaults,
        [_wall_mesh(config)],
        [_block_xml(config, physics), hand, peg],
        [arm_actuators_xml("r", p.arm_kp_lin, p.arm_kp_rot)],
        ft_sensor_xml("r"),
        equality=weld,
    )


def build_peg_model(config: PegConfig, physics: PegPhysics) -> mujoco.MjModel:
    """Compile the trial's MJCF into a MuJoCo model."""
    return mujoco.MjModel.from_xml_string(build_peg_mjcf(config, physics))
