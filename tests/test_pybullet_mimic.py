"""URDF ``<mimic>`` joints in PyBullet: the follower keeps ``multiplier * q_leader + offset``.

The Panda (from the example-robot-data package, a test dependency) has one mimic joint: the
second finger copies the first (multiplier 1, offset 0). A two-finger test gripper written here
covers other multipliers, offsets and revolute fingers. The leader is driven by velocity or
position control, the follower only by its gear constraint.
"""

from __future__ import annotations

import math
import sysconfig
from collections.abc import Iterator
from pathlib import Path

import pytest

from pybullet_ref.mimic import Mimic, add_mimic_constraints, mimic_joints
from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

with native_output_silenced((STDOUT, STDERR)):
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

pytestmark = pytest.mark.pybullet

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
needs_panda = pytest.mark.skipif(not PANDA.is_file(), reason="example-robot-data not installed")

DT = 1.0 / 240.0
SETTLE_STEPS = 480  # 2 s per goal
SETTLED_TOL = 1e-5  # m: follower error once the leader has stopped (measured 1.3e-6)
MOVING_TOL = 1e-4  # m: follower error while the leader moves (measured 2e-6)
GOAL_TOL = 1e-3  # m: the leader's own drive reaches its goal
EFFORT = 100.0  # N, the leader's drive

_INERTIAL = (
    '<inertial><mass value="{m}"/>'
    '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'
)
_FINGER = (
    '<joint name="{name}" type="{type}"><parent link="palm"/><child link="{child}"/>'
    '<axis xyz="{axis}"/><limit lower="-0.2" upper="0.2" effort="100" velocity="1"/>{mimic}'
    "</joint>"
)


def gripper_urdf(mimic: str, joint_type: str = "prismatic") -> str:
    """A palm with two fingers on ``joint_type`` joints (range +-0.2 m or rad); ``mimic`` is the
    second finger's ``<mimic>`` element (or "")."""
    links = "".join(
        f'<link name="{name}">{_INERTIAL.format(m=m)}</link>'
        for name, m in (("palm", 1.0), ("left", 0.05), ("right", 0.05))
    )
    left = {"name": "left_joint", "child": "left", "axis": "0 1 0", "mimic": ""}
    right = {"name": "right_joint", "child": "right", "axis": "0 -1 0", "mimic": mimic}
    joints = "".join(_FINGER.format(type=joint_type, **j) for j in (left, right))
    return f'<robot name="gripper">{links}{joints}</robot>'


@pytest.fixture
def client() -> Iterator[BulletClient]:
    """A DIRECT physics client with gravity, disconnected after the test."""
    with native_output_silenced():
        c = BulletClient(connection_mode=pybullet.DIRECT)
    c.setGravity(0.0, 0.0, -9.81)
    c.setTimeStep(DT)
    yield c
    c.disconnect()


def load(client: BulletClient, urdf: Path) -> tuple[int, dict[str, int]]:
    """Load ``urdf`` with a fixed base; return the body and its joint indices by name."""
    with native_output_silenced((STDOUT, STDERR)):  # unresolved package:// meshes
        body = client.loadURDF(
            str(urdf), useFixedBase=True, flags=pybullet.URDF_USE_INERTIA_FROM_FILE
        )
    infos = (client.getJointInfo(body, j) for j in range(client.getNumJoints(body)))
    return body, {info[1].decode(): info[0] for info in infos}


def drive(client: BulletClient, body: int, leader: int, goal: float, mode: str) -> None:
    """Drive the leader joint to ``goal`` (m) for :data:`SETTLE_STEPS` steps.

    Args:
        mode: "velocity" (a proportional velocity target) or "position" (PyBullet's servo).
    """
    for _ in range(SETTLE_STEPS):
        if mode == "velocity":
            q = client.getJointState(body, leader)[0]
            speed = max(-0.2, min(0.2, 5.0 * (goal - q)))
            client.setJointMotorControl2(
                body, leader, pybullet.VELOCITY_CONTROL, targetVelocity=speed, force=EFFORT
            )
        else:
            client.setJointMotorControl2(
                body, leader, pybullet.POSITION_CONTROL, targetPosition=goal, force=EFFORT
            )
        client.stepSimulation()


def follower_error(client: BulletClient, body: int, mimic: Mimic, index: dict[str, int]) -> float:
    """``|q_follower - (multiplier * q_leader + offset)|`` (m or rad)."""
    q_leader = client.getJointState(body, index[mimic.leader])[0]
    q_follower = client.getJointState(body, index[mimic.follower])[0]
    return abs(q_follower - (mimic.multiplier * q_leader + mimic.offset))


def check_follows(
    client: BulletClient, urdf: Path, goals: tuple[float, ...], mode: str
) -> list[float]:
    """Load ``urdf``, add its one mimic constraint, drive the leader to each goal and check the
    follower there. Returns the settled follower errors, one per goal."""
    body, index = load(client, urdf)
    (mimic,) = mimic_joints(urdf)
    assert len(add_mimic_constraints(client, body, urdf)) == 1
    errors = []
    for goal in goals:
        drive(client, body, index[mimic.leader], goal, mode)
        assert client.getJointState(body, index[mimic.leader])[0] == pytest.approx(
            goal, abs=GOAL_TOL
        )
        errors.append(follower_error(client, body, mimic, index))
    assert max(errors) < SETTLED_TOL, errors
    return errors


# --------------------------------------------------------------------------- the Panda


@needs_panda
def test_panda_has_one_mimic_finger() -> None:
    assert mimic_joints(PANDA) == [Mimic("panda_finger_joint2", "panda_finger_joint1", 1.0, 0.0)]


@needs_panda
@pytest.mark.parametrize("mode", ["velocity", "position"])
def test_panda_fingers_move_together(client: BulletClient, mode: str) -> None:
    check_follows(client, PANDA, (0.03, 0.01, 0.035), mode)


@needs_panda
def test_panda_finger_follows_while_moving(client: BulletClient) -> None:
    body, index = load(client, PANDA)
    (mimic,) = mimic_joints(PANDA)
    leader = index[mimic.leader]
    client.resetJointState(body, leader, 0.02)  # before: the follower is put there too
    add_mimic_constraints(client, body, PANDA)
    worst = 0.0
    for i in range(4 * SETTLE_STEPS):
        goal = 0.02 + 0.015 * math.sin(5.0 * i * DT)  # inside the 0 to 0.04 m range
        client.setJointMotorControl2(
            body, leader, pybullet.POSITION_CONTROL, targetPosition=goal, force=EFFORT
        )
        client.stepSimulation()
        worst = max(worst, follower_error(client, body, mimic, index))
    assert worst < MOVING_TOL


# --------------------------------------------------------------------------- a test gripper


@pytest.mark.parametrize(
    ("multiplier", "offset"), [(1.0, 0.0), (-1.0, 0.0), (0.5, 0.01), (-2.0, -0.02)]
)
@pytest.mark.parametrize("mode", ["velocity", "position"])
@pytest.mark.parametrize("joint_type", ["prismatic", "revolute"])
def test_gripper_follower_keeps_multiplier_and_offset(
    client: BulletClient,
    tmp_path: Path,
    multiplier: float,
    offset: float,
    mode: str,
    joint_type: str,
) -> None:
    urdf = tmp_path / "gripper.urdf"
    mimic = f'<mimic joint="left_joint" multiplier="{multiplier}" offset="{offset}"/>'
    urdf.write_text(gripper_urdf(mimic, joint_type))
    assert mimic_joints(urdf) == [Mimic("right_joint", "left_joint", multiplier, offset)]
    check_follows(client, urdf, (0.05, -0.04, 0.02), mode)


def test_follower_starts_where_its_leader_puts_it(client: BulletClient, tmp_path: Path) -> None:
    urdf = tmp_path / "gripper.urdf"
    urdf.write_text(gripper_urdf('<mimic joint="left_joint" multiplier="-1" offset="0.03"/>'))
    body, index = load(client, urdf)
    client.resetJointState(body, index["left_joint"], 0.05)
    add_mimic_constraints(client, body, urdf)
    assert client.getJointState(body, index["right_joint"])[0] == pytest.approx(-0.02)


def test_no_mimic_joints_no_constraints(client: BulletClient, tmp_path: Path) -> None:
    urdf = tmp_path / "gripper.urdf"
    urdf.write_text(gripper_urdf(""))
    body, _ = load(client, urdf)
    assert mimic_joints(urdf) == []
    assert add_mimic_constraints(client, body, urdf) == []
    assert client.getNumConstraints() == 0


def test_a_missing_leader_is_a_named_error(client: BulletClient, tmp_path: Path) -> None:
    urdf = tmp_path / "gripper.urdf"
    urdf.write_text(gripper_urdf('<mimic joint="thumb_joint"/>'))
    body, _ = load(client, urdf)
    with pytest.raises(ValueError, match="'thumb_joint' is not a joint"):
        add_mimic_constraints(client, body, urdf)


@pytest.mark.parametrize("erp", [0.0, 1.5])
def test_erp_outside_its_range_is_refused(client: BulletClient, tmp_path: Path, erp: float) -> None:
    urdf = tmp_path / "gripper.urdf"
    urdf.write_text(gripper_urdf('<mimic joint="left_joint"/>'))
    body, _ = load(client, urdf)
    with pytest.raises(ValueError, match="erp"):
        add_mimic_constraints(client, body, urdf, erp=erp)
