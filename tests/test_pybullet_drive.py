"""PyBullet's joint drive (:mod:`pybullet_ref.drive`): MuJoCo's implicit servo step applied
through PyBullet's mass matrix, with the contacts' torque observed and joint-limit reactions
kept out of it.

Figures in the comments were measured on this project's 2-core CPU (pybullet 3.2.7, mujoco
4.0.0).
"""

from __future__ import annotations

import sysconfig
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.arm.info import arm_info
from mjx_arm.arm.resolve import task_for_arm
from mjx_arm.task import touch_config
from pybullet_ref import PybulletArmEnv
from pybullet_ref.drive import LIMIT_MARGIN, DriveGains, ExternalTorque, JointLimits, drive_torque

pytestmark = pytest.mark.pybullet

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
Z1 = ROBOTS / "z1_description/urdf/z1.urdf"
DT = 1.0 / 240.0
FREE = JointLimits.of([0.0], [-1.0])  # PyBullet's form of a joint without limits


def _gains(kv, damping, effort, armature) -> DriveGains:
    return DriveGains.of(kv, damping, effort, armature)


def test_one_joint_torque_is_mujocos_step():
    """Hand-worked: M = 0.1, armature 0.05, kv = 24, d = 1, dt = 1/240, u = 1, qdot = 0, no
    external torque, g = 0.5. MuJoCo: qddot = 24 / (0.1 + 0.05 + dt 25) = 94.426230;
    torque on PyBullet's M: 0.1 qddot + g = 9.942623."""
    gains = _gains([24.0], [1.0], [30.0], [0.05])
    (torque,) = drive_torque(gains, [1.0], np.zeros(1), [0.5], np.array([[0.1]]), np.zeros(1), DT)
    assert torque == pytest.approx(9.942623, abs=1e-6)


def test_free_motion_follows_mujocos_integration():
    """Two coupled joints, PyBullet's plant ``M dv = dt (torque - g)``: with the drive's torque
    the velocities equal MuJoCo's ``(M + A + dt K) dv = dt (servo - d v)`` step by step
    (within 1e-12 rad/s over 60 steps), and they settle on the command."""
    mass = np.array([[0.3, 0.28], [0.28, 0.3]])  # strongly coupled (explicit law unstable)
    kv, d, armature = np.array([72.0, 72.0]), np.array([0.5, 0.5]), np.array([0.02, 0.02])
    gains = _gains(kv, d, [1e9, 1e9], armature)
    limits = JointLimits.of([0.0, 0.0], [-1.0, -1.0])
    observer, u, gravity = ExternalTorque(limits), np.array([0.5, -0.2]), np.array([1.0, -2.0])
    bullet, mujoco, q = np.zeros(2), np.zeros(2), np.zeros(2)
    for _ in range(60):
        external = observer.estimate(q, bullet, DT)
        torque = drive_torque(gains, u, bullet, gravity, mass, external, DT)
        observer.applied(mass, bullet, torque, gravity)
        bullet = bullet + DT * np.linalg.solve(mass, torque - gravity)
        lhs = mass + np.diag(armature + DT * (kv + d))
        mujoco = mujoco + DT * np.linalg.solve(lhs, kv * (u - mujoco) - d * mujoco)
        assert np.max(np.abs(bullet - mujoco)) < 1e-12
    assert np.max(np.abs(bullet - u * kv / (kv + d))) < 1e-3


def _blocked(gains: DriveGains, u: float, limits: JointLimits, q: float, steps: int = 200):
    """A joint held still at ``q`` by a wall or a limit: the drive's net torques, one a step."""
    observer, still, gravity, mass = ExternalTorque(limits), np.zeros(1), [0.3], np.array([[0.1]])
    net = []
    for _ in range(steps):
        external = observer.estimate(np.array([q]), still, DT)
        torque = drive_torque(gains, [u], still, gravity, mass, external, DT)
        observer.applied(mass, still, torque, gravity)
        net.append(float(torque[0]) - gravity[0])
    return net


def test_a_joint_blocked_by_a_wall_pushes_its_servo_press():
    """Away from its limits a blocked joint's residual is a contact's: the drive settles on
    MuJoCo's press ``kv u`` (within 1e-9 N m in 200 substeps), not free motion's share."""
    net = _blocked(_gains([24.0], [1.0], [30.0], [0.05]), 0.5, FREE, 0.0)
    assert net[0] < 0.5 * 12.0
    assert net[-1] == pytest.approx(24.0 * 0.5, abs=1e-9)


def test_a_capped_servo_pushes_its_cap_when_blocked():
    net = _blocked(_gains([24.0], [0.0], [5.0], [0.0]), 10.0, FREE, 0.0)
    assert net[-1] == pytest.approx(5.0, abs=1e-9)


@pytest.mark.parametrize(("q", "u"), [(1.0, 0.5), (-1.0, -0.5)])
def test_a_joint_on_its_limit_is_not_pushed_harder(q: float, u: float):
    """On a limit the residual is the limit's reaction and is dropped: the drive keeps free
    motion's torque ``M kv u / (M + A + dt (kv + d))`` (0.1 * 12 / 0.25 = 4.8 N m here) instead
    of climbing to ``kv u`` against the limit, as it does against a wall."""
    limits = JointLimits.of([-1.0], [1.0])
    gains = _gains([24.0], [1.0], [30.0], [0.05])
    net = _blocked(gains, u, limits, q + np.sign(q) * 0.5 * LIMIT_MARGIN)
    free = 0.1 * 24.0 * u / (0.1 + 0.05 + DT * 25.0)
    assert np.allclose(net, free, atol=1e-9)


def test_a_contact_pushing_into_a_limit_stays_observed():
    """Only a residual that pushes a joint off its limit is taken for the limit's: one that
    pushes into it (a contact) is kept."""
    limits = JointLimits.of([-1.0, -1.0], [1.0, 1.0])
    residual = np.array([2.0, -2.0])
    kept = limits.without_reaction(np.array([1.0, 1.0]), residual)
    assert kept.tolist() == [2.0, 0.0]


@pytest.mark.skipif(not Z1.is_file(), reason="example-robot-data not installed")
def test_z1_holds_still_and_follows_a_slow_command():
    """The Unitree Z1's parallel pitch joints: with rotor discs on the links and an explicit
    law they shook at up to 0.71 rad/s while holding still. Over 1 s at home: every joint
    speed stays under 1e-3 rad/s at a zero command, and at 0.05 rad/s each joint moves within
    10 % of the command's distance."""
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
