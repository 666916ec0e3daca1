"""An arm's kinematic chain in its URDF: the arm joints (revolute or continuous) from the root
down to the end effector, and the end effector itself where the arm config names none.
"""

from __future__ import annotations

import math

from mjx_arm.urdf.model import Joint, RobotModel

ARM_JOINT_TYPES = ("revolute", "continuous")
MIN_JOINTS, MAX_JOINTS = 5, 7
NAMED_EE_LINK = "ee_link"


class ArmConfigError(ValueError):
    """An arm config that does not fit its URDF (unknown link, wrong joint count, ...)."""


def arm_chain(model: RobotModel, link: str) -> list[Joint]:
    """The arm joints (revolute or continuous) from the root down to ``link``."""
    return [j for j in model.chain_to(link) if j.type in ARM_JOINT_TYPES]


def default_ee_link(model: RobotModel) -> str:
    """``ee_link`` if the URDF names one, else the tip of the longest chain of arm joints.

    A leaf below a prismatic joint (a finger) is no tip. Among tips with equally many arm
    joints, the one with the fewest joints in all wins (the first in file order on a tie).
    Where the chain passes a hand (a link with two or more branches that move: the fingers of
    a gripper, revolute or prismatic), the end effector is the hand: a leaf fixed to it (a TCP
    frame), else the hand link itself. Where it ends in a single jaw (:func:`jaw_joint`), the
    end effector is the link the jaw hangs from.
    """
    if NAMED_EE_LINK in model.links:
        return NAMED_EE_LINK
    parents = {j.parent for j in model.joints.values()}
    leaves = [name for name in model.links if name not in parents]
    tips = [leaf for leaf in leaves if not _below_prismatic(model, leaf)] or leaves
    if not tips:
        raise ArmConfigError(
            f"{model.path}: no leaf link to take the end effector from ({len(model.links)} "
            "links): an empty robot, or a xacro source? Give a URDF with the arm's links and "
            "joints (xacro's output)"
        )
    order = {name: i for i, name in enumerate(model.links)}
    tip = max(
        tips,
        key=lambda n: (len(arm_chain(model, n)), -len(model.chain_to(n)), -order[n]),
    )
    hand = _hand(model, tip)
    if hand is not None:
        return _fixed_leaf(model, hand)
    jaw = jaw_joint(model, tip)
    return tip if jaw is None else jaw.parent


# A gripper's single jaw turns less than this (rad); an arm's last joint turns a full turn or so.
JAW_MAX_RANGE = math.pi


def jaw_joint(model: RobotModel, tip: str) -> Joint | None:
    """The single jaw of a gripper at the end of the chain to ``tip``, or None.

    A jaw is the chain's last revolute joint when it moves a leaf link through less than
    :data:`JAW_MAX_RANGE` and the chain keeps at least 5 arm joints without it (the SO-100's
    and Unitree Z1's grippers, TALOS's hand motor). The end effector is then the link the jaw
    hangs from: the hand, not the moving jaw.
    """
    chain = arm_chain(model, tip)
    if len(chain) <= MIN_JOINTS or chain[-1].child != tip:
        return None
    last = chain[-1]
    if last.type != "revolute" or last.limit is None:
        return None
    parents = {j.parent for j in model.joints.values()}
    small = last.limit.upper - last.limit.lower < JAW_MAX_RANGE
    return last if small and tip not in parents else None


def _children(model: RobotModel) -> dict[str, list[Joint]]:
    out: dict[str, list[Joint]] = {}
    for joint in model.joints.values():
        out.setdefault(joint.parent, []).append(joint)
    return out


def _hand(model: RobotModel, tip: str) -> str | None:
    """The first link on the way to ``tip`` with two or more child branches that move."""
    children = _children(model)

    def moves(joint: Joint) -> bool:
        return joint.movable or any(moves(j) for j in children.get(joint.child, []))

    for link in [model.root_link, *(j.child for j in model.chain_to(tip))]:
        if sum(moves(j) for j in children.get(link, [])) >= 2:
            return link
    return None


def _fixed_leaf(model: RobotModel, hand: str) -> str:
    """The first leaf fixed to ``hand`` (through fixed joints only), else ``hand``."""
    children = _children(model)
    link = hand
    while True:
        fixed = [j for j in children.get(link, []) if j.type == "fixed"]
        if not fixed:
            return link
        link = fixed[0].child


def _below_prismatic(model: RobotModel, link: str) -> bool:
    return any(j.type == "prismatic" for j in model.chain_to(link))
