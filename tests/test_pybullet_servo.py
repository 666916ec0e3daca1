"""PyBullet's joint servo: the MuJoCo model's velocity servo, implicit in the joint velocity
(``pybullet_ref.arm_model.JointServo.torque``).

Figures in the comments were measured on this project's 2-core CPU (pybullet 3.2.7, mujoco
4.0.0).
"""

from __future__ import annotations

import sysconfig
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.envs.arm import arm_info
from mjx_arm.envs.base import task_for_arm
from mjx_arm.task import touch_config
from pybullet_ref import PybulletArmEnv
from pybullet_ref.arm_model import JointServo

pytestmark = pytest.mark.pybullet

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
Z1 = ROBOTS / "z1_description/urdf/z1.urdf"
DT = 1.0 / 240.0


def _servo(kv, damping, effort) -> JointServo:
    n = len(kv)
    return JointServo(tuple(kv), tuple(damping), tuple(effort), (0.0,) * n)


def test_one_joint_torque_is_the_implicit_step():
    """Hand-worked: m = 0.1, kv = 24, d = 1, dt = 1/240, u = 1, qdot = 0.
    v = dt (kv u) / (m + dt (kv + d)) = 0.1 / 0.2041667 = 0.4897959;
    torque = kv (u - v) - d v + g = 12.244898 - 0.4897959 + 0.5 = 12.255102."""
    servo = _servo([24.0], [1.0], [30.0])
    (torque,) = servo.torque([1.0], [0.0], [0.5], np.array([[0.1]]), DT)
    assert torque == pytest.approx(12.255102, abs=1e-5)


def test_capped_servo_pushes_its_cap():
    """A servo past its cap gives the cap (the damping still acts on the reached velocity)."""
    servo = _servo([24.0], [0.0], [5.0])
    (torque,) = servo.torque([10.0], [0.0], [0.0], np.array([[0.1]]), DT)
    assert torque == pytest.approx(5.0)


def test_coupled_joints_settle_where_an_explicit_law_diverges():
    """Two strongly coupled joints whose explicit law is unstable (largest eigenvalue of
    ``dt M^-1 kv`` about 3.4): stepping ``qdot += dt M^-1 torque`` with the implicit torque
    reaches the command within 1e-6 rad/s in 40 steps, the explicit one grows."""
    mass = np.array([[0.3, 0.28], [0.28, 0.3]])
    kv = np.array([0.3, 0.3]) / DT  # diagonal of dt M^-1 kv: about 7.7
    servo = _servo(kv, [0.0, 0.0], [1e9, 1e9])
    assert np.max(np.linalg.eigvals(DT * np.linalg.solve(mass, np.diag(kv))).real) > 2.0
    u, implicit, explicit = np.array([0.5, -0.2]), np.zeros(2), np.zeros(2)
    for _ in range(40):
        torque = np.array(servo.torque(u, implicit, [0.0, 0.0], mass, DT))
        implicit = implicit + DT * np.linalg.solve(mass, torque)
        explicit = explicit + DT * np.linalg.solve(mass, kv * (u - explicit))
    assert np.max(np.abs(implicit - u)) < 1e-6
    assert np.max(np.abs(explicit - u)) > 1.0


@pytest.mark.skipif(not Z1.is_file(), reason="example-robot-data not installed")
def test_z1_holds_still_and_follows_a_slow_command():
    """The Unitree Z1's parallel pitch joints, coupled by their rotor discs (largest eigenvalue
    of ``dt M^-1 (kv + d)`` 2.15 at home): with the explicit law they chattered at up to
    0.71 rad/s against their caps while holding still. Now, over 1 s at home: every joint
    speed stays under 1e-3 rad/s at a zero command, and at 0.05 rad/s each joint moves within
    10 % of the command's distance (measured: 3-6 % short, the servo's lag at the start)."""
    arm = arm_info(Z1)
    task = task_for_arm(touch_config(), arm)
    env = PybulletArmEnv(task, Z1)
    try:
        home, away = np.asarray(task.home_qpos), np.array([0.8, 0.5, -0.5])
        for command, check in ((0.0, "speed"), (0.05, "distance")):
            env._physics_reset(home, away)
            env._physics_set_velocity_targets(np.full(6, command))
            speeds = []
            for _ in range(30):
                env._physics_step(task.n_substeps)
                speeds.append(np.abs(env._physics_read().qvel))
            moved = env._physics_read().qpos - home
            if check == "speed":
                assert np.max(speeds) < 1e-3
            else:
                assert np.max(np.abs(moved - command * 1.0)) < 0.1 * command
    finally:
        env.close()
