"""The gripper of a parsed URDF: its driven joint, the ``<mimic>`` joints that follow it, the two
pad links that close on each other, and how far they open.

Three kinds are found, each moved by one command on one driven joint:

- parallel: prismatic fingers off the arm chain whose child is a leaf, one driven, the others its
  ``<mimic>`` copies (the shipped ``ur5e_gripper.urdf``, the Panda's hand);
- linkage: a driven revolute joint off the arm chain that other joints copy through ``<mimic>``
  (a four-bar of knuckles as on the Robotiq 2F-85, revolute fingers as on the xArm gripper). Its
  pads are the two moved links whose frames close on each other the most;
- jaw: a driven revolute joint off the arm chain with no ``<mimic>`` joints, that turns one
  link with collision shapes (the moving jaw, nothing movable below it) against the link it
  hangs from, whose shapes carry the fixed jaw (the SO-100/101, the Unitree Z1, many low-cost
  arms). Its pads are the moving jaw and the hand; the fixed jaw is cut from the hand's meshes
  (:mod:`mjx_arm.urdf.pad_fit`), and the jaw closes on the limit that brings the moving jaw
  nearest the tool axis.

A pad whose collision is a mesh gets a box fitted to it (:mod:`mjx_arm.urdf.pad_fit`), the same
in every engine; the sizes below are of those boxes.

Pure functions over :class:`~mjx_arm.urdf.model.RobotModel` and
:func:`~mjx_arm.urdf.kinematics.link_frames`; every length in m, every angle in rad.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np

from mjx_arm.urdf.kinematics import link_frames
from mjx_arm.urdf.model import Joint, RobotModel
from mjx_arm.urdf.pad_fit import FittedPads, PadAxes, fit_pads, shape_centre

KINDS = ("parallel", "linkage", "jaw")


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
        kind: "parallel" (prismatic fingers), "linkage" (revolute knuckles or fingers) or
            "jaw" (one revolute jaw against a fixed one).
        driven: the joint that takes the gripper command.
        followers: its ``<mimic>`` joints, in URDF order.
        pads: the finger links; the first two close on each other (a parallel gripper lists
            every finger; a jaw: the moving jaw, then the hand that carries the fixed jaw).
        open_q, closed_q: the driven joint's position open and closed: its two limits, the
            one that puts the pads farther apart first.
        opening: the pads' gap open minus closed (m): how much wider than closed they open
            (a jaw: the widest gap between its pads while they still face each other).
        pad_width: the first pad's collision shape across the closing direction and the
            approach (m), 0 without a box (a jaw: the fixed jaw's).
        axes: how each pad with collision meshes is fitted (:class:`PadAxes`).
        fitted: those pads fitted (:func:`mjx_arm.urdf.pad_fit.fit_pads`).
    """

    kind: str
    driven: str
    followers: tuple[Follower, ...]
    pads: tuple[str, ...]
    open_q: float
    closed_q: float
    opening: float
    pad_width: float
    axes: tuple[PadAxes, ...] = ()
    fitted: FittedPads = field(default_factory=FittedPads)

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
    else a linkage, else a jaw; None where none is found.

    Raises:
        ConversionError: a pad mesh that cannot be read, or a jaw's hand with no fixed jaw to
            cut from its meshes.
    """
    return _parallel(model, arm_joints) or _linkage(model, arm_joints) or _jaw(model, arm_joints)


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
    """The layout with open and closed put on the driven joint's limits, its mesh pads fitted,
    and its sizes."""
    lim = driven.limit
    probe = GripperLayout(kind, driven.name, followers, pads, 0.0, 0.0, 0.0, 0.0)
    gaps = {q: _distance(_frames(model, probe, q), *pads[:2]) for q in (lim.lower, lim.upper)}
    open_q, closed_q = (
        (lim.upper, lim.lower) if gaps[lim.upper] > gaps[lim.lower] else (lim.lower, lim.upper)
    )
    probe = replace(probe, open_q=open_q, closed_q=closed_q)
    axes = _finger_axes(model, probe)
    hand = model.joints[driven.name].parent
    probe = replace(probe, axes=axes, fitted=fit_pads(model, axes, hand))
    return replace(
        probe, opening=gaps[open_q] - gaps[closed_q], pad_width=pad_width(model, probe, open_q)
    )


def _finger_axes(model: RobotModel, layout: GripperLayout) -> tuple[PadAxes, ...]:
    """How each pad with collision meshes is fitted: closing towards the other pads' middle
    and approach from the hand (the driven joint's parent) to the pads, with the gripper closed
    (open where the closed pads' shapes share a centre), each in the pad's frame."""
    meshed = [p for p in layout.pads if any(g.kind == "mesh" for g in model.links[p].collisions)]
    if not meshed:
        return ()
    centres = {p: shape_centre(model, p) for p in layout.pads}
    for q in (layout.closed_q, layout.open_q):
        frames = _frames(model, layout, q)
        world = {p: (frames[p] @ np.append(centres[p], 1.0))[:3] for p in layout.pads}
        if np.linalg.norm(world[layout.pads[0]] - world[layout.pads[1]]) > 1e-3:
            break
    hand = frames[model.joints[layout.driven].parent][:3, 3]
    middle = np.mean(list(world.values()), axis=0)
    out = []
    for pad in meshed:
        others = np.mean([world[p] for p in layout.pads if p != pad], axis=0)
        rotation = frames[pad][:3, :3].T
        closing, approach = rotation @ (others - world[pad]), rotation @ (middle - hand)
        out.append(PadAxes(pad, _unit(closing), _unit(approach)))
    return tuple(out)


def _unit(vector: np.ndarray) -> tuple[float, float, float]:
    """``vector (3,)`` made unit length, as a tuple (rounded to 1e-9: a cache key)."""
    unit = np.asarray(vector, float) / np.linalg.norm(vector)
    return tuple(float(v) for v in np.round(unit, 9))


def _jaw(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """One driven revolute joint off the arm chain without ``<mimic>`` followers, turning a
    link with collision shapes and nothing movable below it (the moving jaw) against the link
    it hangs from, which has collision shapes (the hand, with the fixed jaw)."""
    movable_parents = {j.parent for j in model.joints.values() if j.movable}
    jaws = [
        j
        for j in model.actuated_joints
        if j.name not in arm_joints
        and j.mimic is None
        and j.type == "revolute"
        and j.limit is not None
        and j.limit.upper > j.limit.lower
        and not _followers(model, j.name)
        and not _moves_below(model, j.child, movable_parents)
        and model.links[j.child].collisions
        and model.links[j.parent].collisions
    ]
    arm_chain = [j for j in model.chain_to(jaws[0].parent) if j.name in arm_joints] if jaws else []
    if len(jaws) != 1 or not arm_chain:
        return None
    driven, hand = jaws[0], jaws[0].parent
    approach, anchor = _tool_line(model, hand, arm_chain[-1], driven)
    lim = driven.limit
    probe = GripperLayout("jaw", driven.name, (), (driven.child, hand), 0.0, 0.0, 0.0, 0.0)
    centre = {q: _in_hand(model, probe, q, driven.child) for q in (lim.lower, lim.upper)}
    off_axis = {q: np.linalg.norm(np.cross(c - anchor, approach)) for q, c in centre.items()}
    open_q, closed_q = (
        (lim.upper, lim.lower)
        if off_axis[lim.upper] > off_axis[lim.lower]
        else (lim.lower, lim.upper)
    )
    swing = centre[open_q] - centre[closed_q]
    closing = swing - approach * (swing @ approach)  # hand frame: fixed jaw -> moving jaw
    probe = replace(probe, open_q=open_q, closed_q=closed_q)
    axes = _jaw_axes(model, probe, _unit(closing), _unit(approach))
    probe = replace(probe, axes=axes, fitted=fit_pads(model, axes, hand))
    opening = jaw_opening(model, probe)
    fixed = probe.fitted.box(hand)
    return replace(probe, opening=opening, pad_width=2.0 * float(fixed.half[2]) if fixed else 0.0)


def _moves_below(model: RobotModel, link: str, movable_parents: set[str]) -> bool:
    """Whether a movable joint hangs anywhere below ``link``."""
    if link in movable_parents:
        return True
    return any(
        _moves_below(model, j.child, movable_parents)
        for j in model.joints.values()
        if j.parent == link
    )


def _tool_line(model: RobotModel, hand: str, last: Joint, jaw: Joint):
    """The tool axis in the hand's frame: a unit direction ``(3,)`` towards the jaws and a
    point on it ``(3,)``. The last arm joint's axis through its anchor where it points along
    the jaws (a wrist that turns the tool about its axis), else the line from the hand's origin
    to the moving jaw's shapes."""
    frames = _frames(model, GripperLayout("jaw", jaw.name, (), (), 0.0, 0.0, 0.0, 0.0), 0.0)
    to_hand = np.linalg.inv(frames[hand])
    axis = to_hand[:3, :3] @ frames[last.child][:3, :3] @ np.asarray(last.axis, float)
    anchor = (to_hand @ frames[last.child][:, 3])[:3]
    jaws = (to_hand @ frames[jaw.child] @ np.append(shape_centre(model, jaw.child), 1.0))[:3]
    out = jaws - anchor
    axis /= np.linalg.norm(axis)
    if abs(axis @ out) >= 0.5 * np.linalg.norm(out):
        return axis * np.sign(axis @ out), anchor
    return out / np.linalg.norm(out), np.zeros(3)


def _in_hand(model: RobotModel, layout: GripperLayout, q: float, link: str) -> np.ndarray:
    """The middle of ``link``'s shapes in the hand's frame (``layout.pads[1]``) with the jaw
    at ``q``, ``(3,)``."""
    frames = _frames(model, layout, q)
    world = frames[link] @ np.append(shape_centre(model, link), 1.0)
    return (np.linalg.inv(frames[layout.pads[1]]) @ world)[:3]


def _jaw_axes(
    model: RobotModel, layout: GripperLayout, closing: tuple, approach: tuple
) -> tuple[PadAxes, ...]:
    """The moving jaw's and the fixed jaw's :class:`PadAxes` (the moving jaw's turned into its
    own frame at the closed pose), from the hand-frame ``closing`` and ``approach``."""
    moving, hand = layout.pads
    frames = _frames(model, layout, layout.closed_q)
    turn = frames[moving][:3, :3].T @ frames[hand][:3, :3]
    return (
        PadAxes(moving, _unit(-(turn @ closing)), _unit(turn @ approach)),
        PadAxes(hand, closing, approach, fixed_jaw=True),
    )


JAW_SAMPLES = 24  # jaw angles the opening is looked for at, from closed to open


def jaw_opening(model: RobotModel, layout: GripperLayout) -> float:
    """The widest gap (m) between a jaw's fitted pads while they face each other: over the
    jaw's range, the gap along the closing direction from the fixed pad's inner face to the
    moving pad's nearest point among those in front of the fixed pad (within its extent along
    the approach and across); 0 where the pads are not fitted boxes."""
    moving, fixed = (layout.fitted.box(p) for p in layout.pads)
    if moving is None or fixed is None:
        return 0.0
    grid = np.stack(np.meshgrid(*[np.linspace(-1.0, 1.0, 5)] * 3), axis=-1).reshape(-1, 3)
    points = moving.centre + (grid * moving.half) @ moving.rotation.T  # moving jaw's frame
    best = 0.0
    for q in np.linspace(layout.closed_q, layout.open_q, JAW_SAMPLES):
        frames = _frames(model, layout, float(q))
        to_hand = np.linalg.inv(frames[layout.pads[1]]) @ frames[layout.pads[0]]
        local = ((points @ to_hand[:3, :3].T + to_hand[:3, 3]) - fixed.centre) @ fixed.rotation
        facing = (np.abs(local[:, 1]) <= fixed.half[1]) & (np.abs(local[:, 2]) <= fixed.half[2])
        if facing.any():
            best = max(best, float(local[facing, 0].min() - fixed.half[0]))
    return best


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
    the distance between their faces. Measured between the pads' frames: a jaw's turn about
    its hinge does not move them (:func:`jaw_opening` measures a jaw)."""
    a, b = layout.pads[:2]
    now = _distance(_frames(model, layout, q), a, b)
    return now - _distance(_frames(model, layout, layout.closed_q), a, b)


def grasp_centre(model: RobotModel, layout: GripperLayout, link: str) -> np.ndarray:
    """Where the gripper holds an object, in ``link``'s frame, ``(3,)``: the midpoint of the
    two pads' collision-shape centres (their fitted boxes' where fitted), halfway between open
    and closed. A jaw holds the object against its fixed jaw: :func:`_jaw_grasp`."""
    if layout.kind == "jaw":
        return _jaw_grasp(model, layout, link)
    frames = _frames(model, layout, 0.5 * (layout.open_q + layout.closed_q))
    points = [
        frames[pad] @ np.append(_shape_centre(layout, model, pad), 1.0) for pad in layout.pads[:2]
    ]
    middle = 0.5 * (points[0] + points[1])
    return (np.linalg.inv(frames[link]) @ middle)[:3]


def _jaw_grasp(model: RobotModel, layout: GripperLayout, link: str) -> np.ndarray:
    """A jaw's grasp centre in ``link``'s frame, ``(3,)``: in front of the fixed jaw's inner
    face by half the opening (the middle of the widest gap: the cube it holds,
    :func:`held_cube_half`, has room on both sides as the jaws come down around it; closing
    pushes it against the fixed jaw), as far towards the tip as keeps the tip
    :data:`TIP_CLEARANCE` above the table the cube rests on (the pad's middle, if that is
    further out)."""
    fixed = layout.fitted.box(layout.pads[1])
    if fixed is None:
        return np.zeros(3)
    out = max(0.0, float(fixed.half[1]) - max(held_cube_half(layout.opening), 0.0) + TIP_CLEARANCE)
    middle = 0.5 * layout.opening
    point = fixed.inner_face + fixed.rotation[:, 0] * middle + fixed.rotation[:, 1] * out
    frames = _frames(model, layout, layout.open_q)
    world = frames[layout.pads[1]] @ np.append(point, 1.0)
    return (np.linalg.inv(frames[link]) @ world)[:3]


TIP_CLEARANCE = 0.005  # m: a jaw's tip stays this far above the table while it grasps
# m: a gripper opens at least this much wider than the cube it holds (1 cm a side: the SO-101's
# open jaws, 4.7 cm apart, came down on a 3.7 cm cube's top at 7 mm off centre)
CUBE_CLEARANCE = 0.02


def held_cube_half(opening: float) -> float:
    """Half the edge (m) of the Lift cube a gripper that opens ``opening`` (m) holds: the
    shipped cube's, or less, so that the gripper opens :data:`CUBE_CLEARANCE` wider than it
    (negative where even a point would not fit)."""
    from mjx_arm.urdf.scene_shapes import CUBE_HALF

    return min(CUBE_HALF, 0.5 * (opening - CUBE_CLEARANCE))


def _shape_centre(layout: GripperLayout, model: RobotModel, link: str) -> np.ndarray:
    """The centre of ``link``'s fitted pad box, else the mean centre of its collision shapes,
    in its frame ``(3,)`` (0 without any)."""
    box = layout.fitted.box(link)
    if box is not None:
        return box.centre
    shapes = model.links[link].collisions
    if not shapes:
        return np.zeros(3)
    return np.mean([np.asarray(s.origin.xyz, float) for s in shapes], axis=0)


def pad_width(model: RobotModel, layout: GripperLayout, q: float) -> float:
    """The first pad's collision box extent (m) across the closing direction and the approach
    (from the driven joint's parent frame to the pads), at driven position ``q`` (a fitted
    pad's: its box's across size)."""
    fitted = layout.fitted.box(layout.pads[0])
    if fitted is not None:
        return 2.0 * float(fitted.half[2])
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
