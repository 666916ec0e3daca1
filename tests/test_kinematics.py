"""The shipped arm against the UR5e's published numbers, through :mod:`mjx_arm.urdf.kinematics`.

Kinematics: UR5e standard DH parameters, ``T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``. The
URDF's ``base_link`` is turned by pi about z against the DH base frame, so the flange frame
(``wrist_3_link``) must equal ``Rz(pi) @ DH(q)``. MuJoCo's forward kinematics of the converted
model must agree with the numpy kinematics. Dynamics: UR5e link masses, joint limits and torques.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mjx_arm.paths import default_arm_urdf
from mjx_arm.sim2real.deploy import UR_JOINTS
from mjx_arm.urdf import load_model, parse_urdf
from mjx_arm.urdf.convert import EE_SITE
from mjx_arm.urdf.inertia import inertia_problem
from mjx_arm.urdf.kinematics import joint_positions, link_frames, link_pose
from mjx_arm.urdf.model import Joint, Link, Origin, RobotModel

# UR5e standard DH parameters (m, rad), base to flange.
DH_D = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
DH_A = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)

JOINTS = UR_JOINTS  # the shipped arm's joints, base to wrist
LINK_MASSES = {  # UR5e link masses (kg)
    "shoulder_link": 3.761,
    "upper_arm_link": 8.058,
    "forearm_link": 2.846,
    "wrist_1_link": 1.37,
    "wrist_2_link": 1.3,
    "wrist_3_link": 0.365,
}
EFFORT = (150.0, 150.0, 150.0, 28.0, 28.0, 28.0)  # N m
N_SAMPLES = 100


@pytest.fixture(scope="module")
def arm() -> RobotModel:
    """The shipped arm, parsed."""
    return parse_urdf(default_arm_urdf())


@pytest.fixture(scope="module")
def configurations() -> np.ndarray:
    """Random joint angles (rad), shape ``(N_SAMPLES, 6)``, within the joint limits."""
    rng = np.random.default_rng(20240601)
    q = rng.uniform(-2 * math.pi, 2 * math.pi, size=(N_SAMPLES, 6))
    q[:, 2] = rng.uniform(-math.pi, math.pi, size=N_SAMPLES)  # the elbow's range
    return q


def dh_flange(q: np.ndarray) -> np.ndarray:
    """Flange pose in the DH base frame from standard DH parameters, shape ``(4, 4)``.

    Args:
        q: joint angles (rad), shape ``(6,)``.
    """
    pose = np.eye(4)
    for theta, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        pose = pose @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return pose


RZ_PI = np.diag([-1.0, -1.0, 1.0, 1.0])  # base_link <- DH base frame


# --------------------------------------------------------------------------- kinematics


def test_flange_matches_ur5e_dh_parameters(arm: RobotModel, configurations: np.ndarray):
    worst_pos = worst_rot = 0.0
    for q in configurations:
        flange = link_frames(arm, q)["wrist_3_link"]
        expected = RZ_PI @ dh_flange(q)
        worst_pos = max(worst_pos, float(np.abs(flange[:3, 3] - expected[:3, 3]).max()))
        worst_rot = max(worst_rot, float(np.abs(flange[:3, :3] - expected[:3, :3]).max()))
    # measured: 2e-13 m and 4e-13 (the URDF writes pi with 12 digits)
    assert worst_pos < 1e-6
    assert worst_rot < 1e-6


def test_flange_at_zero_is_the_dh_zero_pose(arm: RobotModel):
    flange = link_pose(arm, np.zeros(6), "wrist_3_link")
    # all links stretched along -x of the DH base, i.e. +x of base_link
    expected = [0.425 + 0.3922, 0.1333 + 0.0996, 0.1625 - 0.0997]
    np.testing.assert_allclose(flange[:3, 3], expected, atol=1e-9)


def test_link_pose_agrees_with_link_frames_and_mapping_input(
    arm: RobotModel, configurations: np.ndarray
):
    q = configurations[0]
    frames = link_frames(arm, q)
    assert set(frames) == set(arm.links)
    by_name = dict(zip(JOINTS, q, strict=True))
    for link, frame in frames.items():
        np.testing.assert_allclose(link_pose(arm, by_name, link), frame, atol=1e-12)
        rot = frame[:3, :3]
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)


def test_fixed_tool_frames_follow_the_flange(arm: RobotModel, configurations: np.ndarray):
    frames = link_frames(arm, configurations[1])
    np.testing.assert_allclose(frames["tool_link"], frames["wrist_3_link"], atol=1e-12)
    offset = np.linalg.inv(frames["wrist_3_link"]) @ frames["ee_link"]
    np.testing.assert_allclose(offset[:3, 3], [0.0, 0.0, 0.115], atol=1e-12)


def test_joint_positions_reject_wrong_input(arm: RobotModel):
    with pytest.raises(ValueError, match="expected 6"):
        link_frames(arm, np.zeros(5))
    with pytest.raises(ValueError, match="wrist_3_joint"):
        link_frames(arm, dict(zip(JOINTS[:5], np.zeros(5), strict=True)))
    with pytest.raises(KeyError, match="no_such_link"):
        link_pose(arm, np.zeros(6), "no_such_link")


def test_prismatic_and_mimic_joints():
    slide = Joint("slide", "prismatic", "a", "b", Origin((0.0, 0.0, 1.0)), axis=(0.0, 2.0, 0.0))
    copy = Joint("copy", "prismatic", "a", "c", Origin(), axis=(1.0, 0.0, 0.0), mimic="slide")
    links = {name: Link(name, None) for name in "abc"}
    robot = RobotModel("r", None, links, {"slide": slide, "copy": copy})
    assert joint_positions(robot, {"slide": 0.25}) == {"slide": 0.25, "copy": 0.25}
    frames = link_frames(robot, {"slide": 0.25})
    np.testing.assert_allclose(frames["b"][:3, 3], [0.0, 0.25, 1.0])  # unit axis, then origin
    np.testing.assert_allclose(frames["c"][:3, 3], [0.25, 0.0, 0.0])


def test_mujoco_forward_kinematics_agrees_with_numpy(arm: RobotModel, configurations):
    model = load_model(default_arm_urdf())
    data = mujoco.MjData(model)
    qpos_adr = [model.joint(name).qposadr[0] for name in JOINTS]
    bodies = {name: model.body(name).id for name in arm.links}
    ee_site = model.site(EE_SITE).id
    worst = 0.0
    for q in configurations:
        data.qpos[qpos_adr] = q
        mujoco.mj_kinematics(model, data)
        frames = link_frames(arm, q)
        for link, body in bodies.items():
            worst = max(worst, float(np.abs(data.xpos[body] - frames[link][:3, 3]).max()))
            rot = data.xmat[body].reshape(3, 3)
            worst = max(worst, float(np.abs(rot - frames[link][:3, :3]).max()))
        ee = frames["ee_link"]
        worst = max(worst, float(np.abs(data.site_xpos[ee_site] - ee[:3, 3]).max()))
        worst = max(worst, float(np.abs(data.site_xmat[ee_site].reshape(3, 3) - ee[:3, :3]).max()))
    assert worst < 1e-9  # measured: about 1e-15


# --------------------------------------------------------------------------- dynamics


def test_link_masses_are_the_ur5e_values(arm: RobotModel):
    for link, mass in LINK_MASSES.items():
        inertial = arm.links[link].inertial
        assert inertial is not None and inertial.mass == pytest.approx(mass, abs=1e-9), link


def test_joint_limits_velocities_and_efforts(arm: RobotModel):
    joints = arm.actuated_joints
    assert tuple(j.name for j in joints) == JOINTS
    for joint, effort in zip(joints, EFFORT, strict=True):
        lim = joint.limit
        assert lim is not None, joint.name
        bound = math.pi if joint.name == "elbow_joint" else 2 * math.pi
        assert lim.lower == pytest.approx(-bound, abs=1e-9), joint.name
        assert lim.upper == pytest.approx(bound, abs=1e-9), joint.name
        assert lim.velocity == pytest.approx(math.pi, abs=1e-9), joint.name
        assert lim.effort == effort, joint.name
        assert joint.damping is not None and joint.damping > 0, joint.name


def test_every_inertia_is_physical(arm: RobotModel):
    for name, link in arm.links.items():
        assert link.inertial is not None, name
        assert link.inertial.mass > 0, name
        assert inertia_problem(link.inertial.inertia) is None, name


def test_collision_geometry_is_mjx_friendly(arm: RobotModel):
    kinds = [g.kind for link in arm.links.values() for g in link.collisions]
    assert kinds, "the arm has no collision geometry"
    assert set(kinds) <= {"capsule", "sphere", "box"}
