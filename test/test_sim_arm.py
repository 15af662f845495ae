"""The arm, contact model and controller base both simulators share (sim/arm_model.py,
sim/arm_control.py): checked against straightforward computations, and the same in both tasks."""

from __future__ import annotations

import dataclasses
import math
import random

import mujoco
import numpy as np

from rcbht_introspection.sim.arm_model import ARM_JOINTS
from rcbht_introspection.sim.config import ForceLoopConfig, SimConfig
from rcbht_introspection.sim.controller import ControlPlan, SnapController
from rcbht_introspection.sim.model import TrialPhysics, build_model
from rcbht_introspection.sim.peg_config import PegConfig
from rcbht_introspection.sim.peg_controller import PegController, PegPlan
from rcbht_introspection.sim.peg_model import PegPhysics, build_peg_model

SEED = 1234
AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1), "yaw": (0, 0, 1), "pitch": (0, 1, 0)}
AXES["roll"] = (1, 0, 0)


def _controllers() -> tuple[SnapController, PegController, ForceLoopConfig]:
    """A snap and a peg controller whose force loops are configured alike (the snap's values)."""
    snap_cfg = SimConfig()
    loop = {
        f.name: getattr(snap_cfg.controller, f.name) for f in dataclasses.fields(ForceLoopConfig)
    }
    peg_cfg = PegConfig()
    peg_cfg = dataclasses.replace(
        peg_cfg, controller=dataclasses.replace(peg_cfg.controller, **loop)
    )
    snap_plan = ControlPlan((0.0, 0.0, 0.05), 0.1, 0.005, 0.03, 6.0, 12.0, 25.0, 5.0, 0.0002, SEED)
    peg_plan = PegPlan(
        (0.0, 0.0, 0.05), 0.01, 6.0, 0.008, 0.0, 10.0, 0.01, 0.3, 0.5, 0.01, 1.0, SEED
    )
    return (
        SnapController(snap_cfg, snap_plan),
        PegController(peg_cfg, peg_plan),
        ForceLoopConfig(**loop),
    )


def _admittance_by_hand(
    cfg: ForceLoopConfig, forces: list[float], force_set: float, max_speed: float, dt: float
) -> list[float]:
    """The tool height after each tick of a rippled admittance, written out directly."""
    rng = random.Random(SEED)
    kick = cfg.force_ripple * math.sqrt(2.0 * dt / cfg.force_ripple_time)
    ripple, z, heights = 0.0, 0.05, []
    for f in forces:
        ripple = ripple * (1.0 - dt / cfg.force_ripple_time) + kick * rng.gauss(0.0, 1.0)
        speed = cfg.force_gain * (force_set * (1.0 + ripple) - f)
        z -= float(np.clip(speed, -max_speed, max_speed)) * dt
        heights.append(z)
    return heights


def test_both_controllers_run_the_same_admittance_as_written_out() -> None:
    snap, peg, loop = _controllers()
    dt = 0.001
    forces = [0.0, 1.0, 4.0, 9.0, 15.0, 7.0, 3.0] * 40
    heights = {}
    for name, controller in (("snap", snap), ("peg", peg)):
        zs = []
        for f in forces:
            controller._admit(dt, f, 8.0, 0.004)
            zs.append(controller.target[2])
        heights[name] = np.array(zs)
    assert np.array_equal(heights["snap"], heights["peg"])
    expected = _admittance_by_hand(loop, forces, 8.0, 0.004, dt)
    np.testing.assert_allclose(heights["snap"], expected, rtol=0, atol=1e-12)
    assert heights["snap"][-1] != heights["snap"][0]  # it moved


def test_both_controllers_filter_forces_and_stop_the_guarded_move_alike() -> None:
    snap, peg, loop = _controllers()
    dt = 0.001
    fz = [0.0] * 20 + [10.0] * 200
    alpha = dt / (loop.force_filter + dt)
    filtered, f = [], 0.0
    for x in fz:
        f += alpha * (x - f)
        filtered.append(f)
    contact_tick = next(i for i, v in enumerate(filtered) if v > loop.contact_force)
    for controller, first, second in ((snap, "approach", "rotation"), (peg, "reach", "search")):
        seen = []
        for i, x in enumerate(fz):
            assert controller.state.phase == (first if i <= contact_tick else second)
            controller.update(i * dt, dt, 0.0, 0.0, x, 0.01)
            seen.append(controller.force)
        assert np.array_equal(seen, filtered)
        assert controller.state.switch_times == [0.0, contact_tick * dt]


def _geom_of_body(model: mujoco.MjModel, body: str) -> int:
    return int(np.flatnonzero(model.geom_bodyid == model.body(body).id)[0])


def test_snap_and_peg_scenes_share_the_arm_and_the_contact_model() -> None:
    snap_cfg, peg_cfg = SimConfig(), PegConfig()
    snap = build_model(snap_cfg, TrialPhysics(friction_scale=1.2))
    peg = build_peg_model(peg_cfg, PegPhysics(friction_scale=1.2))
    for model, p in ((snap, snap_cfg.physics), (peg, peg_cfg.physics)):
        for name in ARM_JOINTS:
            joint = model.joint(f"r_{name}")
            linear = name in ("x", "y", "z")
            kind = mujoco.mjtJoint.mjJNT_SLIDE if linear else mujoco.mjtJoint.mjJNT_HINGE
            assert joint.type[0] == kind
            assert tuple(joint.axis) == AXES[name]
            assert model.dof_damping[joint.dofadr[0]] == (p.arm_kd_lin if linear else p.arm_kd_rot)
            kp = p.arm_kp_lin if linear else p.arm_kp_rot
            assert model.actuator(f"r_{name}").gainprm[0] == kp
        hand = model.body("r_hand")
        assert hand.mass[0] == p.arm_link_mass and model.body_gravcomp[hand.id] == 1
        assert model.sensor("r_force").type[0] == mujoco.mjtSensor.mjSENS_FORCE
    held = (_geom_of_body(snap, "male"), _geom_of_body(peg, "peg"))
    fixed = (snap.geom("floor").id, _geom_of_body(peg, "block"))
    for (s, q), contype in ((held, 1), (fixed, 2)):
        assert snap.geom_contype[s] == peg.geom_contype[q] == contype
        assert snap.geom_conaffinity[s] == peg.geom_conaffinity[q] == 3 - contype
        assert np.array_equal(snap.geom_friction[s], peg.geom_friction[q])
        assert snap.geom_friction[s][0] == np.float64(f"{snap_cfg.physics.friction * 1.2:.6g}")
        assert np.array_equal(snap.geom_solref[s], snap_cfg.physics.contact_solref)
        assert np.array_equal(peg.geom_solref[q], peg_cfg.physics.contact_solref)
        assert np.array_equal(snap.geom_solimp[s, :3], peg.geom_solimp[q, :3])
