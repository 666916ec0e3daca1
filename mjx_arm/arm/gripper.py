"""An arm's gripper, as every engine and task sees it: one driven joint, its ``<mimic>`` copies,
its stroke, its pads (fitted boxes where they are meshes) and where they hold an object."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from mjx_arm.arm.config import ResolvedArm, is_shipped
from mjx_arm.urdf.grippers import (
    Follower,
    closure_gaps,
    find_layout,
    grasp_centre,
    jaw_lever,
    mimic_positions,
)
from mjx_arm.urdf.pad_fit import FittedPads


@dataclass(frozen=True)
class Gripper:
    """A gripper moved by one command: one driven joint, the others its ``<mimic>`` copies
    (:mod:`mjx_arm.urdf.grippers`): prismatic fingers, a linkage of revolute knuckles, or one
    revolute jaw against a fixed one.

    Attributes:
        joint: the driven joint (its actuator takes the gripper command).
        pad_links: the finger links that get a touch sensor in the task model (the first two
            close on each other).
        v_max: the driven joint's speed limit (m/s, or rad/s for a linkage).
        stroke: the driven joint's travel (m or rad): its upper limit minus its lower.
        open_q, closed_q: the driven joint's position with the gripper open and closed:
            its lower and upper limit, or the other way round (the Panda's fingers close
            towards 0), whichever puts the pads farther apart open.
        followers: the ``<mimic>`` joints with their multiplier and offset.
        linkage: the driven joint is revolute (a linkage or a jaw), not prismatic fingers.
        pad_opening: the pads' gap open minus closed (m), from the URDF's kinematics.
        pad_width: the pad's width across the closing direction (m).
        grasp_offset: where the pads hold an object, in the ee link's frame (m), ``(3,)``.
        kind: "parallel", "linkage" or "jaw" (:data:`mjx_arm.urdf.grippers.KINDS`).
        fitted: the pads fitted to their meshes (:mod:`mjx_arm.urdf.pad_fit`); empty where
            every pad is made of primitives.
        rests_closed: the gripper is held closed in the tasks that do not grip (Reach, Touch):
            every arm's but the shipped gripper arm's, whose fingers stay at 0 (open).
        effort_cap: the driven joint's effort (N m) where the models cap it below the URDF's;
            0 keeps the URDF's. A jaw presses at most :data:`JAW_PRESS` at its grasp centre.
        cube_half: half the edge (m) of the largest Lift cube it holds
            (:attr:`mjx_arm.urdf.grippers.GripperLayout.held_half`).
        closure_gaps: the pads' gap (m) against the closure (0 open, 1 closed),
            ``((closure, gap), ...)`` (:func:`mjx_arm.urdf.grippers.closure_gaps`).
    """

    joint: str
    pad_links: tuple[str, ...]
    v_max: float
    stroke: float
    open_q: float = 0.0
    closed_q: float = 0.0
    followers: tuple[Follower, ...] = ()
    linkage: bool = False
    pad_opening: float = 0.0
    pad_width: float = 0.0
    grasp_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: str = "parallel"
    fitted: FittedPads = dataclasses.field(default_factory=FittedPads)
    rests_closed: bool = True
    effort_cap: float = 0.0
    cube_half: float = 0.0
    closure_gaps: tuple[tuple[float, float], ...] = ()

    @property
    def rest_q(self) -> float:
        """The driven joint's position in the tasks that do not grip: closed, or 0."""
        return self.closed_q if self.rests_closed else 0.0

    @property
    def closing_sign(self) -> float:
        """+1 where the finger closes towards its upper limit, -1 towards its lower."""
        return 1.0 if self.closed_q >= self.open_q else -1.0

    def closure(self, q):
        """How closed the gripper is at finger position ``q`` (m): 0 open, 1 closed."""
        return (q - self.open_q) / (self.closed_q - self.open_q)

    @property
    def opening(self) -> float:
        """The widest gap (m) the two fingers open between them: each prismatic finger moves
        by the stroke; a linkage's or a jaw's pads by what its kinematics give."""
        return self.pad_opening if self.linkage else 2.0 * self.stroke

    @property
    def pad_speed(self) -> float:
        """The mean speed (m/s) the pads close at with the driven joint at ``v_max``."""
        return self.opening * self.v_max / self.stroke if self.stroke > 0 else 0.0

    def positions(self, q: float) -> dict[str, float]:
        """Every gripper joint's position (driven and followers) with the driven one at ``q``."""
        return mimic_positions(self.joint, self.followers, q)


def find_gripper(resolved: ResolvedArm) -> Gripper | None:
    """The arm's gripper (:func:`mjx_arm.urdf.grippers.find_layout`): parallel prismatic
    fingers, a linkage or a jaw, one joint driven; None where there is none."""
    layout = find_layout(resolved.model, set(resolved.joint_names))
    if layout is None:
        return None
    lim = resolved.model.joints[layout.driven].limit
    return Gripper(
        joint=layout.driven,
        pad_links=layout.pads,
        v_max=lim.velocity or resolved.config.default_velocity,
        stroke=lim.upper - lim.lower,
        open_q=layout.open_q,
        closed_q=layout.closed_q,
        followers=layout.followers,
        linkage=layout.kind != "parallel",
        pad_opening=layout.opening,
        pad_width=layout.pad_width,
        grasp_offset=tuple(
            float(v) for v in grasp_centre(resolved.model, layout, resolved.ee_link)
        ),
        kind=layout.kind,
        fitted=layout.fitted,
        rests_closed=not is_shipped(resolved.config),
        effort_cap=_jaw_cap(resolved, layout),
        cube_half=layout.held_half,
        closure_gaps=closure_gaps(resolved.model, layout),
    )


# N: the most a jaw presses at its grasp centre. The shipped parallel gripper presses 24 N; the
# SO-101's URDF effort (10 N m at a 6 cm lever) pressed a 4 cm cube with about 150 N, into
# which MuJoCo's soft contacts let the jaws sink 1 cm, and the cube turned out of the grip.
JAW_PRESS = 30.0


def _jaw_cap(resolved: ResolvedArm, layout) -> float:
    """A jaw's effort cap (N m): :data:`JAW_PRESS` at its lever, where that is below the
    URDF's effort; 0 for the other grippers (and a jaw the URDF already holds to it)."""
    if layout.kind != "jaw":
        return 0.0
    effort = resolved.model.joints[layout.driven].limit.effort or resolved.config.default_effort
    cap = JAW_PRESS * jaw_lever(resolved.model, layout)
    return round(cap, 6) if 0.0 < cap < effort else 0.0
