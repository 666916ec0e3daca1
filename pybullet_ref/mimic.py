"""URDF ``<mimic>`` joints held in PyBullet by gear constraints.

PyBullet's URDF loader ignores ``<mimic joint="leader" multiplier="m" offset="o"/>``: the
follower is a free joint with its own default motor. MuJoCo's importer ties the two with a joint
equality. Here each follower gets a ``JOINT_GEAR`` constraint and its motor is switched off
(velocity control with force 0), so the constraint alone moves it.

Bullet's gear constraint (``btMultiBodyGearConstraint``), with the follower as its parent link
and the leader as its child, keeps the joint coordinates at (found by experiment, prismatic and
revolute joints, multipliers -2 to 2)::

    q_follower + gearRatio * q_leader = relativePositionTarget

so ``gearRatio = -multiplier`` and ``relativePositionTarget = offset`` give the URDF's
``q_follower = multiplier * q_leader + offset`` exactly, offset included. The velocities are held
in the solver; the positions only through ``erp`` (the fraction of the position error corrected
per step), which must therefore be above 0. ``gearAuxLink`` is left unset: it names a third joint
whose position is added to the follower's (a differential), which a mimic joint does not have.

Measured at a 1/240 s step, with the leader under velocity or position control: on the Panda's
fingers the follower is 1.3e-6 m from ``multiplier * q_leader + offset`` once settled and at most
2e-6 m while the leader moves; on a two-finger test gripper (multipliers -2 to 1, offsets up to
0.02 m) the settled error is rounding only. The error grows when many other joints of the body are
held by PyBullet's own motors (also constraints, solved together in ``numSolverIterations``
passes): with the Panda's arm joints swinging under velocity control, up to 1.2e-3 m for a step
(RMS 9e-5 m) at the default 50 iterations, 1.4e-4 m at 200; with the arm under torque control,
9e-6 m.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from mjx_arm.urdf.safe_xml import read_xml
from pybullet_ref.quiet import STDERR, native_output_silenced

with native_output_silenced((STDERR,)):  # "pybullet build time: ..."
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

# The constraint's force cap (N or N m): MuJoCo's joint equality has none, so it is far above a
# gripper's effort limit (PyBullet's own examples use the same value).
MAX_FORCE = 1e4
# Fraction of the position error corrected per step. Bullet's default for a gear constraint is 0:
# no position correction, the follower drifts (3e-4 m over 6 s on the Panda's fingers).
ERP = 0.8
_MOVABLE = (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC)


@dataclass(frozen=True)
class Mimic:
    """One URDF ``<mimic>``: ``q_follower = multiplier * q_leader + offset``.

    Attributes:
        follower: name of the joint that carries the ``<mimic>`` element.
        leader: name of the joint it copies.
        multiplier: the URDF's ``multiplier`` (default 1).
        offset: the URDF's ``offset`` (rad or m, default 0).
    """

    follower: str
    leader: str
    multiplier: float = 1.0
    offset: float = 0.0


def mimic_joints(urdf_path: str | Path) -> list[Mimic]:
    """The ``<mimic>`` joints of a URDF, in file order.

    Args:
        urdf_path: the URDF file.

    Returns:
        One :class:`Mimic` per joint with a ``<mimic>`` element; empty if there is none.

    Raises:
        mjx_arm.urdf.safe_xml.XmlError: the file is not safe, well-formed XML.
        ValueError: a ``<mimic>`` without ``joint`` or with a non-numeric attribute.
    """
    path = Path(urdf_path).resolve()
    return list(_mimic_joints_cached(path, path.stat().st_mtime_ns))


@functools.lru_cache(maxsize=32)
def _mimic_joints_cached(path: Path, mtime_ns: int) -> tuple[Mimic, ...]:
    """:func:`mimic_joints` read once per file version (every rebuilt world asks again)."""
    del mtime_ns  # part of the cache key only
    out = []
    for joint in read_xml(path).findall("joint"):
        elem = joint.find("mimic")
        if elem is None:
            continue
        name = joint.get("name", "")
        leader = elem.get("joint")
        if not leader:
            raise ValueError(f"joint {name!r}: <mimic> names no joint")
        try:
            multiplier = float(elem.get("multiplier", "1"))
            offset = float(elem.get("offset", "0"))
        except ValueError as err:
            raise ValueError(f"joint {name!r}: <mimic> attribute is not a number: {err}") from err
        out.append(Mimic(name, leader, multiplier, offset))
    return tuple(out)


def add_mimic_constraints(
    client: BulletClient,
    body_id: int,
    urdf_path: str | Path,
    max_force: float = MAX_FORCE,
    erp: float = ERP,
) -> list[int]:
    """Make the ``<mimic>`` joints of a loaded URDF follow their leaders.

    For each mimic joint: its motor is switched off, it is put at
    ``multiplier * q_leader + offset`` (velocity ``multiplier * qdot_leader``) and a gear
    constraint keeps it there. Call it after ``loadURDF`` and after the leaders' joint states are
    set; a later ``resetJointState`` of a leader should set its follower too (else the constraint
    pulls the follower over by ``erp`` per step). ``resetSimulation`` removes the constraints.

    Args:
        client: the physics client the body lives in.
        body_id: the multibody loaded from ``urdf_path``.
        urdf_path: the URDF file the body was loaded from.
        max_force: the most force (N) or torque (N m) each constraint applies.
        erp: fraction of the position error corrected per step, in ``(0, 1]``.

    Returns:
        The constraint ids, one per mimic joint in file order; empty without mimic joints.

    Raises:
        ValueError: ``erp`` is outside ``(0, 1]``, or a mimic joint or its leader is missing
            from the body or is not a revolute or prismatic joint.
    """
    if not 0.0 < erp <= 1.0:
        raise ValueError(f"erp must be in (0, 1], got {erp}")
    mimics = mimic_joints(urdf_path)
    if not mimics:
        return []
    index = _movable_joints(client, body_id)
    return [_add_one(client, body_id, m, index, max_force, erp) for m in mimics]


def _movable_joints(client: BulletClient, body_id: int) -> dict[str, int | None]:
    """Joint name -> PyBullet joint index (None for a joint that is not revolute or prismatic)."""
    out: dict[str, int | None] = {}
    for j in range(client.getNumJoints(body_id)):
        info = client.getJointInfo(body_id, j)
        out[info[1].decode()] = j if info[2] in _MOVABLE else None
    return out


def _index(index: dict[str, int | None], name: str, role: str) -> int:
    """The PyBullet index of a mimic's joint, or a named error."""
    if name not in index:
        raise ValueError(f"mimic {role} {name!r} is not a joint of the loaded body")
    j = index[name]
    if j is None:
        raise ValueError(f"mimic {role} {name!r} is not a revolute or prismatic joint")
    return j


def _add_one(
    client: BulletClient,
    body_id: int,
    mimic: Mimic,
    index: dict[str, int | None],
    max_force: float,
    erp: float,
) -> int:
    """Free one follower, put it where its leader says, and add its gear constraint."""
    follower = _index(index, mimic.follower, "joint")
    leader = _index(index, mimic.leader, "leader")
    client.setJointMotorControl2(body_id, follower, pybullet.VELOCITY_CONTROL, force=0.0)
    q, qdot = client.getJointState(body_id, leader)[:2]
    m = mimic.multiplier
    client.resetJointState(body_id, follower, m * q + mimic.offset, m * qdot)
    c = client.createConstraint(
        body_id,
        follower,
        body_id,
        leader,
        jointType=pybullet.JOINT_GEAR,
        jointAxis=[1.0, 0.0, 0.0],  # unused by the gear constraint: it acts on the joint axes
        parentFramePosition=[0.0, 0.0, 0.0],
        childFramePosition=[0.0, 0.0, 0.0],
    )
    client.changeConstraint(
        c, gearRatio=-m, relativePositionTarget=mimic.offset, maxForce=max_force, erp=erp
    )
    return c
