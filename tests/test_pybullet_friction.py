"""Joint dry friction (MuJoCo's ``frictionloss``) in PyBullet's drive (:mod:`pybullet_ref.drive`).

The xArm6 of pybullet_data has ``<dynamics friction="1.0">`` on every joint. MuJoCo's URDF
importer makes that 1 N m of ``frictionloss``; without it in PyBullet, the same commands turned
the two engines' joints apart by up to 0.04 rad in 1 s (0.002 rad for the shipped arm, which
has none), and a Lift policy trained in MJX struck the table with its fingers in PyBullet.
"""

from __future__ import annotations

import numpy as np
import pytest

from pybullet_ref.drive import DriveGains, drive_torque

DT = 1.0 / 240.0


def _gains(friction: float) -> DriveGains:
    return DriveGains.of([24.0], [1.0], [30.0], [0.05], [friction])


def test_friction_holds_a_joint_that_the_servo_pushes_less_than_it():
    """At rest, a command whose push ``kv u`` (0.48 N m) is under the friction (1 N m): the
    step leaves the joint at rest, so the torque is the gravity compensation alone."""
    mass, gravity = np.array([[0.1]]), [0.5]
    (torque,) = drive_torque(_gains(1.0), [0.02], np.zeros(1), gravity, mass, np.zeros(1), DT)
    assert torque == pytest.approx(0.5, abs=1e-12)


def test_friction_takes_its_cap_off_a_moving_joint():
    """Moving at 1 rad/s with a command of 2 rad/s: the friction costs exactly its 1 N m, so
    MuJoCo's step is ``qddot = (kv (u - v) - d v - f) / (M + A + dt (kv + d))``."""
    mass, qdot = np.array([[0.1]]), np.array([1.0])
    (torque,) = drive_torque(_gains(1.0), [2.0], qdot, [0.0], mass, np.zeros(1), DT)
    qddot = (24.0 * 1.0 - 1.0 * 1.0 - 1.0) / (0.1 + 0.05 + DT * 25.0)
    assert torque == pytest.approx(0.1 * qddot, rel=1e-12)
    (free,) = drive_torque(_gains(0.0), [2.0], qdot, [0.0], mass, np.zeros(1), DT)
    assert free > torque


@pytest.mark.pybullet
def test_xarm6_joints_follow_the_same_commands_in_both_engines(monkeypatch, tmp_path):
    """The same constant commands for 1 s (Reach on pybullet_data's xArm6): every joint of
    PyBullet within 2e-3 rad of MuJoCo's (0.010-0.040 rad before the drive had the friction)."""
    pybullet_data = pytest.importorskip("pybullet_data")
    from mjx_arm.evaluate.core import make_eval_env
    from mjx_arm.task import task_config

    monkeypatch.setenv("ROS_PACKAGE_PATH", pybullet_data.getDataPath())
    arm = tmp_path / "xarm6.toml"
    arm.write_text('urdf = "package://xarm/xarm6_robot.urdf"\nrepair_inertia = true\n')
    angles = {}
    for engine in ("mujoco", "pybullet"):
        env = make_eval_env(task_config("reach"), engine, arm=arm)
        obs, _ = env.reset(seed=3)
        action = np.array([0.5, -0.5, 0.5, -0.5, 0.5, -0.5], dtype=np.float32)
        for _ in range(30):
            obs, *_ = env.step(action)
        angles[engine] = np.asarray(obs["joint_angles"])
        env.close()
    assert np.abs(angles["pybullet"] - angles["mujoco"]).max() < 2e-3
