"""The gripper's finger in PyBullet moves as MuJoCo's servo moves it.

MuJoCo drives the finger with a velocity servo ``kv (u - v)`` against the joint damping of both
fingers (the mimic follower's moves with it), so a free finger settles at ``u kv / (kv + d)``,
0.89 ``u`` on the shipped gripper (kv 158.1 N s/m, d 10 + 10 N s/m). PyBullet's velocity
motor reached ``u`` itself: the fingers closed 12.5 % faster than in MuJoCo, and the Lift
policies closed on the cube earlier, higher up its sides.
"""

from __future__ import annotations

import numpy as np
import pytest

from mjx_arm.arm.info import arm_info
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.paths import asset
from mjx_arm.task.lift import lift_config
from pybullet_ref.arm_model import joint_servo
from pybullet_ref.env import PybulletArmEnv

pytestmark = pytest.mark.pybullet

# the cube far from the fingers (the ee starts 0.15 m above the table): the fingers move freely
CUBE_AWAY = np.array([0.39, 0.23, 0.0225])
STEPS = 8  # control steps; a full command closes the fingers in about 10
SPEED_TOLERANCE = 0.03  # relative: the closing speed per step, PyBullet against MuJoCo


def test_the_servo_reads_the_damping_of_both_fingers() -> None:
    task = lift_config()
    servo = joint_servo(arm_info(asset("ur5e_gripper.urdf")), task.spec.servo_dt)
    kv, damping = servo.finger.kv, servo.finger.damping
    assert damping == pytest.approx(20.0)  # N s/m: 10 on the driven finger, 10 on its mimic
    assert servo.finger_speed(0.15) == pytest.approx(0.15 * kv / (kv + 20.0))
    assert servo.finger_speed(-0.15) == pytest.approx(-servo.finger_speed(0.15))


def _closure(env_cls, command: float) -> np.ndarray:
    env = env_cls(task=lift_config(), arm=asset("ur5e_gripper.urdf"))
    try:
        env.reset(seed=3, options={"target": CUBE_AWAY})
        action = np.zeros(env.action_space.shape, np.float32)
        action[-1] = command
        out = []
        for _ in range(STEPS):
            env.step(action)
            out.append(env._reading.grip[0])
        return np.array(out)
    finally:
        env.close()


@pytest.mark.parametrize("command", [1.0, 0.3])
def test_the_fingers_close_as_fast_as_in_mujoco(command: float) -> None:
    mj, pb = _closure(MujocoArmEnv, command), _closure(PybulletArmEnv, command)
    assert mj[-1] < 1.0 and pb[-1] < 1.0  # neither reached the closed stop
    # the steady speed (closure per step) after the first two steps' start-up
    mj_speed = (mj[-1] - mj[2]) / (STEPS - 3)
    pb_speed = (pb[-1] - pb[2]) / (STEPS - 3)
    assert abs(pb_speed / mj_speed - 1.0) < SPEED_TOLERANCE, (mj, pb)
    assert np.max(np.abs(pb - mj)) < 0.04, (mj, pb)  # closure (0 open, 1 closed)
