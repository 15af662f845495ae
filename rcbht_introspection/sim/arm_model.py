"""The MJCF both simulated tasks share: the Cartesian servo arm, its hand, the force/torque
sensor, the two contact classes and the document around a task's own bodies.

The arm is a Cartesian servo (3 slides along the world axes + 3 hinges at the tool centre point)
whose compliance is its finite servo stiffness; the held part (class `held`) collides only with
the fixed part (class `fixed`), so the arm's own links never touch anything.
"""

from __future__ import annotations

from collections.abc import Sequence

from rcbht_introspection.sim.arm_config import ArmPhysicsConfig

ARM_JOINTS: tuple[str, ...] = ("x", "y", "z", "yaw", "pitch", "roll")
SIDES: tuple[int, ...] = (0, 90, 180, 270)
"""Yaw (degrees) of the four sides of a square opening (the snap housing's, the hole's walls);
each side is modelled in a frame facing +x, then turned by its yaw."""
_JOINT_AXES: dict[str, str] = {
    "x": "1 0 0", "y": "0 1 0", "z": "0 0 1", "yaw": "0 0 1", "pitch": "0 1 0", "roll": "1 0 0",
}  # fmt: skip


def numbers(values: Sequence[float]) -> str:
    """Space-separated MJCF numbers (6 significant digits), e.g. a solref or solimp."""
    return " ".join(f"{v:.6g}" for v in values)


def prism_vertices(points_xz: list[tuple[float, float]], y0: float, y1: float) -> str:
    """Vertex list of a convex prism: a polygon in the x-z plane extruded from y0 to y1."""
    verts = [(x, y, z) for y in (y0, y1) for x, z in points_xz]
    return numbers([v for p in verts for v in p])


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


def arm_hand_xml(
    prefix: str,
    pos: tuple[float, float, float],
    physics: ArmPhysicsConfig,
    damping: tuple[float, float],
    content: str,
    yaw: float | None = None,
) -> str:
    """The arm's hand body `<prefix>_hand` (gravity compensated, its six servo joints with
    `damping` (linear, rotational)) around `content`; `yaw` (degrees) turns it about z."""
    x, y, z = pos
    turn = "" if yaw is None else f' euler="0 0 {yaw:.6g}"'
    li = physics.arm_link_inertia
    return (
        f'<body name="{prefix}_hand" pos="{x:.6g} {y:.6g} {z:.6g}"{turn} gravcomp="1">'
        f'<inertial pos="0 0 0" mass="{physics.arm_link_mass:.6g}" '
        f'diaginertia="{li:.6g} {li:.6g} {li:.6g}"/>'
        f"{arm_joints_xml(prefix, *damping)}"
        f"{content}</body>"
    )


def ft_sensor_xml(prefix: str) -> str:
    """The force and torque sensors of the arm's sensor site `<prefix>_ft`."""
    return (
        f'<force name="{prefix}_force" site="{prefix}_ft"/>'
        f'<torque name="{prefix}_torque" site="{prefix}_ft"/>'
    )


def contact_class_xml(
    name: str, held: bool, physics: ArmPhysicsConfig, friction_scale: float, style: str
) -> str:
    """Default class of the fixed part's (or the `held` part's) geoms: one shared contact model
    (friction scaled for the trial, soft contacts); `style` adds rgba and the like."""
    mu = physics.friction * friction_scale
    contype, conaffinity = (1, 2) if held else (2, 1)
    return (
        f'<default class="{name}"><geom contype="{contype}" conaffinity="{conaffinity}" '
        f'friction="{mu:.6g} 0.005 0.0001"\n solref="{numbers(physics.contact_solref)}" '
        f'solimp="{numbers(physics.contact_solimp)}" {style}/></default>'
    )


def mjcf_document(
    model: str,
    physics: ArmPhysicsConfig,
    defaults: Sequence[str],
    assets: Sequence[str],
    bodies: Sequence[str],
    actuators: Sequence[str],
    sensors: str,
    equality: str | None = None,
) -> str:
    """The whole MJCF document of a task: options (time step, gravity, integrator), the contact
    classes, meshes, world bodies, optional equality constraints, actuators and sensors."""
    constraints = "" if equality is None else f"<equality>\n{equality}\n</equality>\n"
    return f"""<mujoco model="{model}">
<compiler angle="degree" autolimits="true"/>
<option timestep="{physics.timestep:.6g}" gravity="0 0 {-physics.gravity:.6g}" integrator="implicitfast">
<flag multiccd="enable"/>
</option>
<default>
{chr(10).join(defaults)}
</default>
<asset>
{chr(10).join(assets)}
</asset>
<worldbody>
{chr(10).join(bodies)}
</worldbody>
{constraints}<actuator>
{chr(10).join(actuators)}
</actuator>
<sensor>
{sensors}
</sensor>
</mujoco>
"""
