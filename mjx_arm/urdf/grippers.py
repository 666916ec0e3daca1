"""The gripper of a parsed URDF: its driven joint, the ``<mimic>`` joints that follow it, the two
pad links that close on each other, and how far they open.

Two kinds are found, both moved by one command on one driven joint:

- parallel: prismatic fingers off the arm chain whose child is a leaf, one driven, the others its
  ``<mimic>`` copies (the shipped ``ur5e_gripper.urdf``, the Panda's hand);
- linkage: a driven revolute joint off the arm chain that other joints copy through ``<mimic>``
  (a four-bar of knuckles as on the Robotiq 2F-85, revolute fingers as on the xArm gripper). Its
  pads are the two moved links whose frames close on each other the most.

Pure functions over :class:`~mjx_arm.urdf.model.RobotModel` and
:func:`~mjx_arm.urdf.kinematics.link_frames`; every length in m, every angle in rad.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from mjx_arm.urdf.kinematics import link_frames
from mjx_arm.urdf.model import Joint, RobotModel


@dataclass(frozen=True)
class Follower:
    """A ``<mimic>`` joint of the gripper: ``q = multiplier * q_driven + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class GripperLayout:
    """What a URDF's gripper is made of.

    Attributes:
        kind: "parallel" (prismatic fingers) or "linkage" (revolute knuckles or fingers).
        driven: the joint that takes the gripper command.
        followers: its ``<mimic>`` joints, in URDF order.
        pads: the finger links; the first two close on each other (a parallel gripper lists
            every finger).
        open_q, closed_q: the driven joint's position open and closed: its two limits, the
            one that puts the pads farther apart first.
        opening: the pads' gap open minus closed (m): how much wider than closed they open.
        pad_width: the first pad's collision shape across the closing direction and the
            approach (m), 0 without a box.
    """

    kind: str
    driven: str
    followers: tuple[Follower, ...]
    pads: tuple[str, ...]
    open_q: float
    closed_q: float
    opening: float
    pad_width: float

    def positions(self, q: float) -> dict[str, float]:
        """Every gripper joint's position with the driven joint at ``q``."""
        return mimic_positions(self.driven, self.followers, q)


def mimic_positions(driven: str, followers: tuple[Follower, ...], q: float) -> dict[str, float]:
    """The driven joint at ``q`` and each follower at ``multiplier * q + offset``."""
    out = {driven: float(q)}
    out.update({f.joint: f.multiplier * float(q) + f.offset for f in followers})
    return out


def find_layout(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """The gripper of ``model`` off the arm chain ``arm_joints``: parallel where there is one,
    else a linkage; None where neither is found."""
    return _parallel(model, arm_joints) or _linkage(model, arm_joints)


def _followers(model: RobotModel, driven: str) -> tuple[Follower, ...]:
    return tuple(
        Follower(j.name, j.mimic_multiplier, j.mimic_offset)
        for j in model.actuated_joints
        if j.mimic == driven
    )


def _parallel(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """Prismatic fingers whose child is a leaf, exactly one of them driven."""
    parents = {j.parent for j in model.joints.values()}
    fingers = [
        j
        for j in model.actuated_joints
        if j.type == "prismatic" and j.name not in arm_joints and j.child not in parents
    ]
    driven = [j for j in fingers if j.mimic is None]
    if len(fingers) < 2 or len(driven) != 1 or driven[0].limit is None:
        return None
    pads = tuple(j.child for j in fingers)
    return _layout(model, "parallel", driven[0], _followers(model, driven[0].name), pads)


def _linkage(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """One driven revolute joint off the arm chain with ``<mimic>`` followers; its pads are
    the two moved links with a collision shape whose frames close on each other the most."""
    driven = [
        j
        for j in model.actuated_joints
        if j.name not in arm_joints
        and j.mimic is None
        and j.type == "revolute"
        and j.limit is not None
        and j.limit.upper > j.limit.lower
        and _followers(model, j.name)
    ]
    if len(driven) != 1:
        return None
    followers = _followers(model, driven[0].name)
    moved = [model.joints[n].child for n in (driven[0].name, *(f.joint for f in followers))]
    touching = [link for link in moved if model.links[link].collisions]
    lim = driven[0].limit
    probe = GripperLayout("linkage", driven[0].name, followers, (), 0.0, 0.0, 0.0, 0.0)
    low, high = (_frames(model, probe, q) for q in (lim.lower, lim.upper))
    best, pair = 0.0, None
    for a, b in itertools.combinations(touching, 2):
        change = abs(_distance(low, a, b) - _distance(high, a, b))
        if change > best + 1e-9:
            best, pair = change, (a, b)
    if pair is None:
        return None
    return _layout(model, "linkage", driven[0], followers, pair)


def _layout(model, kind: str, driven: Joint, followers, pads: tuple[str, ...]) -> GripperLayout:
    """The layout with open and closed put on the driven joint's limits, and its sizes."""
    lim = driven.limit
    probe = GripperLayout(kind, driven.name, followers, pads, 0.0, 0.0, 0.0, 0.0)
    gaps = {q: _distance(_frames(model, probe, q), *pads[:2]) for q in (lim.lower, lim.upper)}
    open_q, closed_q = (
        (lim.upper, lim.lower) if gaps[lim.upper] > gaps[lim.lower] else (lim.lower, lim.upper)
    )
    width = pad_width(model, probe, open_q)
    return GripperLayout(
        kind, driven.name, followers, pads, open_q, closed_q, gaps[open_q] - gaps[closed_q], width
    )


def _frames(model: RobotModel, layout: GripperLayout, q: float) -> dict[str, np.ndarray]:
    """Every link's pose ``(4, 4)`` with the gripper's driven joint at ``q``, others at 0."""
    positions = {j.name: 0.0 for j in model.actuated_joints if j.mimic is None}
    positions.update(layout.positions(q))
    return link_frames(model, positions)


def _distance(frames: dict[str, np.ndarray], a: str, b: str) -> float:
    return float(np.linalg.norm(frames[a][:3, 3] - frames[b][:3, 3]))


def pad_gap(model: RobotModel, layout: GripperLayout, q: float) -> float:
    """The pads' gap (m) with the driven joint at ``q`` over their gap closed: 0 closed,
    ``layout.opening`` open. Pads that meet when closed (both shipped linkage grippers) give
    the distance between their faces."""
    a, b = layout.pads[:2]
    now = _distance(_frames(model, layout, q), a, b)
    return now - _distance(_frames(model, layout, layout.closed_q), a, b)


def grasp_centre(model: RobotModel, layout: GripperLayout, link: str) -> np.ndarray:
    """Where the gripper holds an object, in ``link``'s frame, ``(3,)``: the midpoint of the
    two pads' collision-shape centres, halfway between open and closed."""
    frames = _frames(model, layout, 0.5 * (layout.open_q + layout.closed_q))
    points = [frames[pad] @ np.append(_shape_centre(model, pad), 1.0) for pad in layout.pads[:2]]
    middle = 0.5 * (points[0] + points[1])
    return (np.linalg.inv(frames[link]) @ middle)[:3]


def _shape_centre(model: RobotModel, link: str) -> np.ndarray:
    """The mean centre of ``link``'s collision shapes in its frame ``(3,)`` (0 without any)."""
    shapes = model.links[link].collisions
    if not shapes:
        return np.zeros(3)
    return np.mean([np.asarray(s.origin.xyz, float) for s in shapes], axis=0)


def pad_width(model: RobotModel, layout: GripperLayout, q: float) -> float:
    """The first pad's collision box extent (m) across the closing direction and the approach
    (from the driven joint's parent frame to the pads), at driven position ``q``."""
    frames = _frames(model, layout, q)
    a, b = layout.pads[:2]
    closing = frames[b][:3, 3] - frames[a][:3, 3]
    root = frames[model.joints[layout.driven].parent][:3, 3]
    approach = 0.5 * (frames[a][:3, 3] + frames[b][:3, 3]) - root
    across = np.cross(closing, approach)
    boxes = [g for g in model.links[a].collisions if g.kind == "box"]
    if not boxes or not np.linalg.norm(across) > 0:
        return 0.0
    across /= np.linalg.norm(across)
    box = boxes[0]
    rotation = frames[a][:3, :3] @ box.origin.matrix()[:3, :3]
    return float(np.abs(rotation.T @ across) @ np.asarray(box.size, float))
