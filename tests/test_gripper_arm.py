"""The shipped arm with a parallel-jaw gripper (assets/ur5e_gripper.urdf): it is the shipped arm
up to the flange, it validates and converts in every engine, and it holds a cube in both.

The hold check closes the fingers on a 4.5 cm, 0.1 kg cube at the home pose and measures how far
the cube slips against the gripper over the next 2 s (the slip goal of a grasp: 5 mm).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from mjx_arm.envs.arm import arm_info
from mjx_arm.paths import asset
from mjx_arm.urdf.arm_config import SHIPPED_HOME_QPOS
from mjx_arm.urdf.convert import build_spec, to_mjcf
from mjx_arm.urdf.model import parse_urdf
from mjx_arm.urdf.scene_shapes import SCENE_CONAFFINITY, SCENE_CONTYPE
from mjx_arm.urdf.validate import validate

GRIPPER = asset("ur5e_gripper.urdf")
CUBE_HALF, CUBE_MASS = 0.0225, 0.1
SLIP_GOAL = 0.005  # m over 2 s of holding
NEAR_CLOSED = 0.019  # finger position (m) 1 mm short of the cube on each side
DT = 1.0 / 240.0


def test_the_arm_part_is_the_shipped_arm() -> None:
    arm, gripper = parse_urdf(asset("ur5e.urdf")), parse_urdf(GRIPPER)
    for name in arm.actuated_joints:
        a, g = arm.joints[name.name], gripper.joints[name.name]
        assert (a.origin, a.axis, a.limit, a.parent, a.child) == (
            g.origin,
            g.axis,
            g.limit,
            g.parent,
            g.child,
        )
        mine, theirs = arm.links[a.child].inertial, gripper.links[g.child].inertial
        assert (mine.mass, mine.origin) == (theirs.mass, theirs.origin)
        np.testing.assert_array_equal(mine.inertia, theirs.inertia)


def test_validates_and_converts_with_the_mimic_finger() -> None:
    report = validate(GRIPPER, engine="all")
    assert report.ok, report.format()
    model = mujoco.MjModel.from_xml_string(to_mjcf(GRIPPER))
    names = [model.actuator(i).name for i in range(model.nu)]
    assert "left_finger_joint" in names and "right_finger_joint" not in names
    assert model.neq == 1 and model.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT
    info = arm_info(GRIPPER)
    assert info.joint_names == tuple(j.name for j in parse_urdf(asset("ur5e.urdf")).actuated_joints)
    assert info.ft_joint == "ft_sensor_joint" and info.ee_link == "ee_link"
    assert info.tool.mass == pytest.approx(0.925 + 2 * 0.06 + 0.001)
    np.testing.assert_allclose(info.home_qpos, SHIPPED_HOME_QPOS)


def _mujoco_slip() -> tuple[float, float]:
    """(slip over 2 s in m, finger force in N) of a cube held in C MuJoCo at the home pose."""
    arm = arm_info(GRIPPER)
    spec = build_spec(arm.urdf, arm.convert_config(self_collision=False))
    probe = spec.copy().compile()
    data = mujoco.MjData(probe)
    data.qpos[[probe.joint(n).qposadr[0] for n in arm.joint_names]] = arm.home_qpos
    mujoco.mj_forward(probe, data)
    cube = spec.worldbody.add_body()
    cube.name, cube.pos = "cube", data.site_xpos[probe.site("ee").id].copy()
    cube.add_freejoint()
    geom = cube.add_geom()
    geom.type, geom.size, geom.mass = mujoco.mjtGeom.mjGEOM_BOX, [CUBE_HALF] * 3, CUBE_MASS
    geom.contype, geom.conaffinity = SCENE_CONTYPE, SCENE_CONAFFINITY
    model = spec.compile()
    data = mujoco.MjData(model)
    data.qpos[[model.joint(n).qposadr[0] for n in arm.joint_names]] = arm.home_qpos
    for name in ("left_finger_joint", "right_finger_joint"):
        data.qpos[model.joint(name).qposadr[0]] = NEAR_CLOSED
    act = model.actuator("left_finger_joint")
    data.ctrl[act.id] = 0.15  # close at the finger's full speed: the servo presses at its cap
    ee, body = model.site("ee").id, model.body("cube").id
    mujoco.mj_step(model, data, nstep=240)
    before = data.xpos[body] - data.site_xpos[ee]
    mujoco.mj_step(model, data, nstep=480)
    after = data.xpos[body] - data.site_xpos[ee]
    force = float(act.gainprm[0]) * 0.15
    return float(np.linalg.norm(after - before)), min(force, float(act.forcerange[1]))


def _pybullet_slip(force: float) -> float:
    """Slip over 2 s (m) of the same cube held in PyBullet, the finger pressing with ``force``."""
    from pybullet_utils.bullet_client import BulletClient

    from pybullet_ref.env import pybullet
    from pybullet_ref.mimic import add_mimic_constraints

    client = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        client.setGravity(0, 0, -9.81)
        client.setTimeStep(DT)
        body = client.loadURDF(str(GRIPPER), useFixedBase=True)
        joints = {
            client.getJointInfo(body, j)[1].decode(): j for j in range(client.getNumJoints(body))
        }
        arm = arm_info(GRIPPER)
        for name, q in zip(arm.joint_names, arm.home_qpos, strict=True):
            client.resetJointState(body, joints[name], float(q))
        arm_ids = [joints[n] for n in arm.joint_names]
        client.setJointMotorControlArray(
            body, arm_ids, pybullet.POSITION_CONTROL, targetPositions=list(arm.home_qpos)
        )
        for name in ("left_finger_joint", "right_finger_joint"):
            client.resetJointState(body, joints[name], NEAR_CLOSED)
        add_mimic_constraints(client, body, GRIPPER)
        ee = joints["ee_joint"]
        start = client.getLinkState(body, ee, computeForwardKinematics=1)[4]
        shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[CUBE_HALF] * 3)
        cube = client.createMultiBody(CUBE_MASS, shape, basePosition=start)
        for link in range(-1, client.getNumJoints(body)):
            client.changeDynamics(body, link, lateralFriction=1.0)
        client.changeDynamics(cube, -1, lateralFriction=1.0)
        client.setJointMotorControl2(
            body, joints["left_finger_joint"], pybullet.VELOCITY_CONTROL,
            targetVelocity=0.15, force=force,
        )  # fmt: skip

        def relative() -> np.ndarray:
            tool = client.getLinkState(body, ee, computeForwardKinematics=1)[4]
            return np.array(client.getBasePositionAndOrientation(cube)[0]) - np.array(tool)

        for _ in range(240):
            client.stepSimulation()
        before = relative()
        for _ in range(480):
            client.stepSimulation()
        return float(np.linalg.norm(relative() - before))
    finally:
        client.disconnect()


def test_the_gripper_holds_a_cube_in_both_engines() -> None:
    slip_mujoco, force = _mujoco_slip()
    assert 10.0 < force <= 120.0  # N: the finger servo's press, inside the URDF effort
    assert slip_mujoco < SLIP_GOAL, slip_mujoco
    slip_bullet = _pybullet_slip(force)
    assert slip_bullet < SLIP_GOAL, slip_bullet
