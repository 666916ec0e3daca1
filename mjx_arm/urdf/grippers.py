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
from dataclasses import replace

import numpy as np

from mjx_arm.urdf.gripper_layout import CUBE_CLEARANCE as CUBE_CLEARANCE
from mjx_arm.urdf.gripper_layout import KINDS as KINDS
from mjx_arm.urdf.gripper_layout import Follower as Follower
from mjx_arm.urdf.gripper_layout import (
    GripperLayout,
    followers_of,
    frame_distance,
    gripper_drives,
    layout_frames,
    unit_tuple,
)
from mjx_arm.urdf.gripper_layout import held_cube_half as held_cube_half
from mjx_arm.urdf.gripper_layout import mimic_positions as mimic_positions
from mjx_arm.urdf.jaw import find_jaw, jaw_gaps, jaw_grasp
from mjx_arm.urdf.jaw import jaw_lever as jaw_lever
from mjx_arm.urdf.jaw import jaw_opening as jaw_opening
from mjx_arm.urdf.model import Joint, RobotModel
from mjx_arm.urdf.pad_fit import PadAxes, fit_pads, shape_centre


def find_layout(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """The gripper of ``model`` off the arm chain ``arm_joints``: parallel where there is one,
    else a linkage, else a jaw; None where none is found.

    Raises:
        ConversionError: a pad mesh that cannot be read, or a jaw's hand with no fixed jaw to
            cut from its meshes.
    """
    return (
        _parallel(model, arm_joints) or _linkage(model, arm_joints) or find_jaw(model, arm_joints)
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
    return _layout(model, "parallel", driven[0], followers_of(model, driven[0].name), pads)


def _linkage(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """One driven revolute joint off the arm chain with ``<mimic>`` followers; its pads are
    the two moved links with a collision shape whose frames close on each other the most."""
    driven = [j for j in gripper_drives(model, arm_joints) if followers_of(model, j.name)]
    if len(driven) != 1:
        return None
    followers = followers_of(model, driven[0].name)
    moved = [model.joints[n].child for n in (driven[0].name, *(f.joint for f in followers))]
    touching = [link for link in moved if model.links[link].collisions]
    lim = driven[0].limit
    probe = GripperLayout("linkage", driven[0].name, followers, (), 0.0, 0.0, 0.0, 0.0)
    low, high = (layout_frames(model, probe, q) for q in (lim.lower, lim.upper))
    best, pair = 0.0, None
    for a, b in itertools.combinations(touching, 2):
        change = abs(frame_distance(low, a, b) - frame_distance(high, a, b))
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
    gaps = {
        q: frame_distance(layout_frames(model, probe, q), *pads[:2]) for q in (lim.lower, lim.upper)
    }
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
        frames = layout_frames(model, layout, q)
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
        out.append(PadAxes(pad, unit_tuple(closing), unit_tuple(approach)))
    return tuple(out)


def pad_gap(model: RobotModel, layout: GripperLayout, q: float) -> float:
    """The pads' gap (m) with the driven joint at ``q`` over their gap closed: 0 closed,
    ``layout.opening`` open. Pads that meet when closed (both shipped linkage grippers) give
    the distance between their faces. Measured between the pads' frames: a jaw's turn about
    its hinge does not move them (:func:`jaw_opening` measures a jaw)."""
    a, b = layout.pads[:2]
    now = frame_distance(layout_frames(model, layout, q), a, b)
    return now - frame_distance(layout_frames(model, layout, layout.closed_q), a, b)


GAP_SAMPLES = 25  # driven-joint positions the pads' gap is tabled at, open to closed


def closure_gaps(model: RobotModel, layout: GripperLayout) -> tuple[tuple[float, float], ...]:
    """The pads' gap (m) against the gripper's closure (0 open, 1 closed), ``((closure, gap),
    ...)`` by closure, the gap never growing as the gripper closes: :func:`pad_gap` at
    :data:`GAP_SAMPLES` positions, a jaw's where its pads can hold a cube
    (:func:`~mjx_arm.urdf.jaw.jaw_gaps`)."""
    span = layout.closed_q - layout.open_q
    if layout.kind == "jaw":
        rows = [((q - layout.open_q) / span, gap) for q, gap, _ in jaw_gaps(model, layout)]
    else:
        closures = np.linspace(0.0, 1.0, GAP_SAMPLES)
        rows = [(c, pad_gap(model, layout, layout.open_q + c * span)) for c in closures]
    if not rows:
        return ()
    rows.sort()
    gaps = np.minimum.accumulate([gap for _, gap in rows])
    return tuple(
        (round(float(c), 6), round(float(g), 6)) for (c, _), g in zip(rows, gaps, strict=True)
    )


def grasp_centre(model: RobotModel, layout: GripperLayout, link: str) -> np.ndarray:
    """Where the gripper holds an object, in ``link``'s frame, ``(3,)``: the midpoint of the
    two pads' collision-shape centres (their fitted boxes' where fitted), halfway between open
    and closed. A jaw holds the object against its fixed jaw: :func:`_jaw_grasp`."""
    if layout.kind == "jaw":
        return jaw_grasp(model, layout, link)
    frames = layout_frames(model, layout, 0.5 * (layout.open_q + layout.closed_q))
    points = [
        frames[pad] @ np.append(_shape_centre(layout, model, pad), 1.0) for pad in layout.pads[:2]
    ]
    middle = 0.5 * (points[0] + points[1])
    return (np.linalg.inv(frames[link]) @ middle)[:3]


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
    frames = layout_frames(model, layout, q)
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
