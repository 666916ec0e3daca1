"""Touch on gripper arms with no arm file: the gripper is held closed and the ee point is where
the closed tool meets the box, or, where shapes beside the tool axis would meet it first, the
tool's deepest point. Pressing straight down onto the box's top, both CPU engines read the box
pushing the tool up once the ee point reaches the box's top.

Arms: the SO-101 (a jaw; tests/data), pybullet_data's xArm6 with its maker's linkage gripper
(the fingers' tips), and the Kinova Jaco 2 (tests/data: its open fingers reach past its palm
beside the axis, so a fingertip, 10.5 cm off the axis, is its ee point).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.verdict import task_verdict
from mjx_arm.task.touch import touch_config

DATA = Path(__file__).parent / "data" / "example-robot-data" / "robots"
pybullet_data = pytest.importorskip("pybullet_data")
ARMS = {
    "so101": ArmConfig(urdf=str(DATA / "so_arm_description/urdf/so101.urdf"), repair_inertia=True),
    "xarm6_gripper": ArmConfig(
        urdf=str(Path(pybullet_data.getDataPath()) / "xarm/xarm6_with_gripper.urdf"),
        repair_inertia=True,
    ),
    "kinova": ArmConfig(urdf=str(DATA / "kinova_description/robots/kinova.urdf")),
}
GAP = 0.01  # m: the box's top starts this far below the ee point
SPEED = 0.02  # m/s: the scripted press moves the ee point down at this speed
TOUCH_TOL = 0.005  # m: the ee point's height over the box's top when the press starts


def _press(env, obs: dict, top: float) -> tuple[float, float, np.ndarray]:
    """From observation ``obs``, move the ee point straight down at :data:`SPEED` (the arm
    model's Jacobian, the tool's orientation held) until the wrist reads over 1 N; returns the
    ee point's height then over ``top`` (the box's top, m), the force (N) and its direction in
    the world ``(3,)``."""
    import mujoco

    from mjx_arm.arm.model_io import arm_model
    from mjx_arm.task.observation import decode_joints

    arm, task = env.arm, env.task
    model = arm_model(arm, task)
    data = mujoco.MjData(model)
    adr = [model.joint(n).qposadr[0] for n in arm.joint_names]
    dofs = [model.joint(n).dofadr[0] for n in arm.joint_names]
    site, coding = model.site("ee").id, arm.joint_coding(task)
    info = {"contact_force_norm": 0.0}
    for _ in range(int(3 * GAP / SPEED / task.ctrl_dt)):
        data.qpos[adr] = decode_joints(obs["joint_angles"].astype(float), coding)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacSite(model, data, jacp, jacr, site)
        jac = np.vstack([jacp[:, dofs], jacr[:, dofs]])
        twist = np.array([0.0, 0.0, -SPEED, 0.0, 0.0, 0.0])
        qdot = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), twist)
        obs, _, _, _, info = env.step((qdot / task.joint_speeds(arm.v_max)).astype(np.float32))
        if info["contact_force_norm"] > 1.0:
            break
    world = _world(obs["ee_pose"][3:], obs["contact_force"][:3])
    return float(obs["ee_pose"][2]) - top, info["contact_force_norm"], world


def _world(quat: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``vector (3,)`` of the ee frame in the world, the ee's orientation ``quat`` (w, x, y, z)."""
    import mujoco

    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, np.asarray(vector, float), np.asarray(quat, float))
    return out


@pytest.mark.parametrize("name", list(ARMS))
def test_check_says_yes_to_touch(name: str) -> None:
    ok, why = task_verdict(arm_info(ARMS[name]), touch_config())
    assert ok, why


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
@pytest.mark.parametrize("name", list(ARMS))
def test_a_press_down_meets_the_box_at_the_ee_point(name: str, engine: str) -> None:
    """The box's top put GAP under the ee point at the Touch home, the ee point driven straight
    down: the wrist reads the box pushing up once the ee point is within TOUCH_TOL of its
    top."""
    from mjx_arm.urdf.scene_shapes import box_top_offset

    env = gym.make("mjx_arm/Touch-v0", engine=engine, arm=ARMS[name]).unwrapped
    try:
        obs, _ = env.reset(seed=0)
        tip = obs["ee_pose"][:3].astype(np.float64)
        box = tip - np.array([0.0, 0.0, box_top_offset() + GAP])
        obs, _ = env.reset(seed=0, options={"target": box})
        height, force, world = _press(env, obs, box[2] + box_top_offset())
    finally:
        env.close()
    assert force > 1.0, (name, engine, height)  # N: the box presses the tool
    assert abs(height) < TOUCH_TOL, (name, engine, height)
    assert world[2] > 0.8 * force, world  # the box pushes the tool up
