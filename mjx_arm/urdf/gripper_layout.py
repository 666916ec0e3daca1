"""What a gripper found in a URDF is made of (:class:`GripperLayout`), and the kinematics its
finders share: every gripper joint's position from the driven one's, link frames with the
gripper at a position, and the cube a gripper of a given opening holds
(:mod:`mjx_arm.urdf.grippers` finds the layouts; :mod:`mjx_arm.urdf.jaw` the one-jaw kind).
Every length in m, every angle in rad.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mjx_arm.urdf.kinematics import link_frames
from mjx_arm.urdf.model import RobotModel
from mjx_arm.urdf.pad_fit import FittedPads, PadAxes

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
        cube_half: half the edge (m) of the cube a jaw holds square (:func:`_jaw_fit`); 0:
            :func:`held_cube_half` of the opening.
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
    cube_half: float = 0.0

    @property
    def held_half(self) -> float:
        """Half the edge (m) of the Lift cube the gripper holds: ``cube_half`` where the
        layout sets one (a jaw), else :func:`held_cube_half` of the opening."""
        return self.cube_half or held_cube_half(self.opening)

    def positions(self, q: float) -> dict[str, float]:
        """Every gripper joint's position with the driven joint at ``q``."""
        return mimic_positions(self.driven, self.followers, q)


def mimic_positions(driven: str, followers: tuple[Follower, ...], q: float) -> dict[str, float]:
    """The driven joint at ``q`` and each follower at ``multiplier * q + offset``."""
    out = {driven: float(q)}
    out.update({f.joint: f.multiplier * float(q) + f.offset for f in followers})
    return out


def followers_of(model: RobotModel, driven: str) -> tuple[Follower, ...]:
    return tuple(
        Follower(j.name, j.mimic_multiplier, j.mimic_offset)
        for j in model.actuated_joints
        if j.mimic == driven
    )


def gripper_drives(model: RobotModel, arm_joints: set[str]) -> list:
    """The joints that could drive a gripper: actuated revolute joints off the arm chain,
    without ``<mimic>`` of their own, with a range to move through."""
    return [
        j
        for j in model.actuated_joints
        if j.name not in arm_joints
        and j.mimic is None
        and j.type == "revolute"
        and j.limit is not None
        and j.limit.upper > j.limit.lower
    ]


def unit_tuple(vector: np.ndarray) -> tuple[float, float, float]:
    """``vector (3,)`` made unit length, as a tuple (rounded to 1e-9: a cache key)."""
    unit = np.asarray(vector, float) / np.linalg.norm(vector)
    return tuple(float(v) for v in np.round(unit, 9))


def layout_frames(model: RobotModel, layout: GripperLayout, q: float) -> dict[str, np.ndarray]:
    """Every link's pose ``(4, 4)`` with the gripper's driven joint at ``q``, others at 0."""
    positions = {j.name: 0.0 for j in model.actuated_joints if j.mimic is None}
    positions.update(layout.positions(q))
    return link_frames(model, positions)


def frame_distance(frames: dict[str, np.ndarray], a: str, b: str) -> float:
    return float(np.linalg.norm(frames[a][:3, 3] - frames[b][:3, 3]))


# m: a gripper opens at least this much wider than the cube it holds (1 cm a side: the SO-101's
# open jaws, 4.7 cm apart, came down on a 3.7 cm cube's top at 7 mm off centre)
CUBE_CLEARANCE = 0.02
# m: a gripper's tips stay this far above the table while the grip point holds a cube resting
# on it (a jaw's grasp centre, :func:`mjx_arm.urdf.jaw.jaw_grasp`; the grip point of the others,
# :func:`mjx_arm.arm.points.with_points`)
TIP_CLEARANCE = 0.005


def held_cube_half(opening: float) -> float:
    """Half the edge (m) of the Lift cube a gripper that opens ``opening`` (m) holds: the
    shipped cube's, or less, so that the gripper opens :data:`CUBE_CLEARANCE` wider than it
    (negative where even a point would not fit)."""
    from mjx_arm.urdf.scene_shapes import CUBE_HALF

    return min(CUBE_HALF, 0.5 * (opening - CUBE_CLEARANCE))
