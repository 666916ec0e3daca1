"""One-jaw grippers: a driven revolute jaw that closes on a jaw that is part of the hand (the
SO-100/101, the Unitree Z1, many low-cost arms). Found from the URDF (:func:`find_jaw`), its pads
fitted to the meshes (the fixed jaw cut off the hand's, :mod:`mjx_arm.urdf.pad_fit`), its
opening, the cube it holds square, its grasp centre and its lever. Every length in m, every
angle in rad.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mjx_arm.urdf.gripper_layout import (
    CUBE_CLEARANCE,
    TIP_CLEARANCE,
    GripperLayout,
    followers_of,
    gripper_drives,
    held_cube_half,
    layout_frames,
    unit_tuple,
)
from mjx_arm.urdf.model import Joint, RobotModel
from mjx_arm.urdf.pad_fit import PadAxes, fit_pads, shape_centre


def find_jaw(model: RobotModel, arm_joints: set[str]) -> GripperLayout | None:
    """One driven revolute joint off the arm chain without ``<mimic>`` followers, turning a
    link with collision shapes and nothing movable below it (the moving jaw) against the link
    it hangs from, which has collision shapes (the hand, with the fixed jaw)."""
    movable_parents = {j.parent for j in model.joints.values() if j.movable}
    jaws = [
        j
        for j in gripper_drives(model, arm_joints)
        if not followers_of(model, j.name)
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
    probe = _jaw_fit(model, probe, unit_tuple(closing), unit_tuple(approach))
    fixed = probe.fitted.box(hand)
    return replace(probe, pad_width=2.0 * float(fixed.half[2]) if fixed else 0.0)


def _jaw_fit(model: RobotModel, layout: GripperLayout, closing, approach) -> GripperLayout:
    """``layout`` with its pads fitted (the moving jaw's box along its face at the closed
    pose, :func:`_jaw_axes`), its opening (the widest gap where the pads can hold a cube,
    :func:`jaw_gaps`) and the cube it holds: the widest gap at which the pads' faces are
    within :data:`JAW_WEDGE` of parallel, if that is less than :func:`held_cube_half` of the
    opening (a revolute jaw's face turns as it closes: the SO-101's met a 3.8 cm cube 14
    degrees askew, with its top edge only, and the cube slid out of the grip)."""
    axes = _jaw_axes(model, layout, closing, approach, layout.closed_q)
    layout = replace(layout, axes=axes, fitted=fit_pads(model, axes, layout.pads[1]))
    gaps = jaw_gaps(model, layout)
    opening = max((gap for _, gap, _ in gaps), default=0.0)
    square = [gap for _, gap, wedge in gaps if wedge <= math.radians(JAW_WEDGE)]
    half = min(held_cube_half(opening), 0.5 * max(square, default=0.0))
    return replace(layout, opening=opening, cube_half=half)


JAW_WEDGE = 10.0  # degrees: a jaw holds a cube where its pads' faces are this near parallel


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
    frames = layout_frames(model, GripperLayout("jaw", jaw.name, (), (), 0.0, 0.0, 0.0, 0.0), 0.0)
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
    frames = layout_frames(model, layout, q)
    world = frames[link] @ np.append(shape_centre(model, link), 1.0)
    return (np.linalg.inv(frames[layout.pads[1]]) @ world)[:3]


def _jaw_axes(
    model: RobotModel,
    layout: GripperLayout,
    closing: tuple,
    approach: tuple,
    q: float,
    tip: float = 0.0,
) -> tuple[PadAxes, ...]:
    """The moving jaw's and the fixed jaw's :class:`PadAxes` from the hand-frame ``closing``
    and ``approach``, the moving jaw's turned into its own frame with the jaw at ``q`` (its
    pad the last ``tip`` towards its tip; 0: all of it, along its face)."""
    moving, hand = layout.pads
    frames = layout_frames(model, layout, q)
    turn = frames[moving][:3, :3].T @ frames[hand][:3, :3]
    return (
        PadAxes(moving, unit_tuple(-(turn @ closing)), unit_tuple(turn @ approach), tip=tip),
        PadAxes(hand, closing, approach, fixed_jaw=True),
    )


JAW_SAMPLES = 24  # jaw angles the opening is looked for at, from closed to open


def jaw_opening(model: RobotModel, layout: GripperLayout) -> float:
    """The widest gap (m) between a jaw's fitted pads where they can hold a cube between them
    (:func:`jaw_gaps`); 0 where the pads are not fitted boxes."""
    return max((gap for _, gap, _ in jaw_gaps(model, layout)), default=0.0)


def jaw_gaps(model: RobotModel, layout: GripperLayout) -> list[tuple[float, float, float]]:
    """``(q, gap, wedge)`` from closed to open (:data:`JAW_SAMPLES` angles) where a jaw's
    pads can hold a cube: the wedge (rad) between their faces, and the gap (m) along the
    closing direction from the fixed pad's inner face to
    the nearest point of the moving pad's inner face in front of the fixed pad's last
    ``2 CUBE_HALF`` towards its tip (where the shipped cube stands) and within its width, at
    the angles where that part of the moving face spans at least ``CUBE_HALF`` along the
    approach (half the cube's height: less only touches its top edge)."""
    from mjx_arm.urdf.scene_shapes import CUBE_HALF

    moving, fixed = (layout.fitted.box(p) for p in layout.pads)
    if moving is None or fixed is None:
        return []
    zone = fixed.half[1] - min(2.0 * CUBE_HALF, 2.0 * fixed.half[1])  # along the approach
    side = np.linspace(-1.0, 1.0, 9)
    grid = np.stack(np.meshgrid([1.0], side, side), axis=-1).reshape(-1, 3)  # its inner face
    points = moving.centre + (grid * moving.half) @ moving.rotation.T  # moving jaw's frame
    out = []
    for q in np.linspace(layout.closed_q, layout.open_q, JAW_SAMPLES):
        frames = layout_frames(model, layout, float(q))
        to_hand = np.linalg.inv(frames[layout.pads[1]]) @ frames[layout.pads[0]]
        local = ((points @ to_hand[:3, :3].T + to_hand[:3, 3]) - fixed.centre) @ fixed.rotation
        along = np.clip(local[:, 1], zone, fixed.half[1])
        facing = (local[:, 1] == along) & (np.abs(local[:, 2]) <= fixed.half[2])
        if facing.any() and along.max() - along.min() >= CUBE_HALF:
            normal = -(to_hand[:3, :3] @ moving.rotation[:, 0]) @ fixed.rotation[:, 0]
            wedge = float(np.arccos(np.clip(normal, -1.0, 1.0)))
            out.append((float(q), float(local[facing, 0].min() - fixed.half[0]), wedge))
    return out


# m: the room a jaw's grasp centre leaves between the fixed jaw and the cube it comes down
# around. Closing pushes the cube against the fixed jaw, so a held cube's centre sits this much
# (and the pads' give, about 2 mm in C MuJoCo) off the grasp centre, and Lift's ``cradle`` and
# ``stray`` ask it to stay within the cube's half edge of it. At half of CUBE_CLEARANCE (1 cm)
# the SO-101's held 2.3 cm cube sat 12 mm off, past that half edge (11.5 mm): lifting it turned
# ``cradle`` off and ``stray`` on, and a Lift seed learned to hold it pressed to the table.
FIXED_SIDE_ROOM = 0.25 * CUBE_CLEARANCE


def jaw_grasp(model: RobotModel, layout: GripperLayout, link: str) -> np.ndarray:
    """A jaw's grasp centre in ``link``'s frame, ``(3,)``: in front of the fixed jaw's inner
    face by half the cube it holds (:attr:`GripperLayout.held_half`) and :data:`FIXED_SIDE_ROOM`,
    or half the opening where that is less (the cube has room on both sides as the jaws come
    down around it; closing pushes it against the fixed jaw), as far towards the tip as keeps
    the tip :data:`TIP_CLEARANCE` above the table the cube rests on (the pad's middle, if that
    is further out)."""
    fixed = layout.fitted.box(layout.pads[1])
    if fixed is None:
        return np.zeros(3)
    out = max(0.0, float(fixed.half[1]) - max(layout.held_half, 0.0) + TIP_CLEARANCE)
    middle = min(0.5 * layout.opening, layout.held_half + FIXED_SIDE_ROOM)
    point = fixed.inner_face + fixed.rotation[:, 0] * middle + fixed.rotation[:, 1] * out
    frames = layout_frames(model, layout, layout.open_q)
    world = frames[layout.pads[1]] @ np.append(point, 1.0)
    return (np.linalg.inv(frames[link]) @ world)[:3]


def jaw_lever(model: RobotModel, layout: GripperLayout) -> float:
    """How far (m) a jaw's grasp centre (:func:`grasp_centre`) lies from its hinge axis: the
    lever its joint torque presses the object with."""
    hand, moving = layout.pads[1], layout.pads[0]
    frames = layout_frames(model, layout, layout.open_q)
    to_hand = np.linalg.inv(frames[hand]) @ frames[moving]
    axis = to_hand[:3, :3] @ np.asarray(model.joints[layout.driven].axis, float)
    out = jaw_grasp(model, layout, hand) - to_hand[:3, 3]
    return float(np.linalg.norm(np.cross(out, axis / np.linalg.norm(axis))))
