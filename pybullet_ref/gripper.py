"""The gripper's joints in a loaded PyBullet body: what drives it, its pads, where it starts, and
the normal force on each pad."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mjx_arm.arm.gripper import Gripper
from mjx_arm.urdf.spec_edits import PAD_MARGIN

# A pad region: (link index, box centre (3,), link-from-box rotation (3, 3), half sizes (3,)).
PadRegion = tuple[int, np.ndarray, np.ndarray, np.ndarray]


def gripper_ids(
    gripper: Gripper | None, grips: bool, joint: dict[str, int], link: dict[str, int], infos: list
) -> dict:
    """:class:`~pybullet_ref.env.ArmIds` fields of the arm's gripper (none without one).

    Args:
        gripper: the arm's gripper, or None.
        grips: whether the task grips (Lift): its gripper starts open; in the other tasks it
            starts closed, as in the MuJoCo models (``rest_qpos``), but for the shipped gripper
            arm's fingers, which stay at 0 (:attr:`~mjx_arm.arm.gripper.Gripper.rests_closed`).
        joint, link: joint and link index by name; infos: ``getJointInfo`` rows.

    Returns:
        ``finger`` (the driven joint), ``finger_lower`` (its lower limit, m or rad), ``pads``
        (the two pad links, whose contacts make the pad forces), ``pad_regions`` (the fixed
        jaw of a one-jaw gripper, part of its hand link: only contacts inside its fitted box,
        :data:`~mjx_arm.urdf.spec_edits.PAD_MARGIN` larger, count, as MuJoCo's touch site
        counts them) and ``gripper_start`` (``(joint index, position)`` of every gripper joint
        to put at reset; empty for the shipped gripper arm in a task that does not grip, whose
        fingers stay at 0).
    """
    if gripper is None:
        return {}
    finger = joint[gripper.joint]
    pads = tuple(link[name] for name in gripper.pad_links[:2])
    ids = {"finger": finger, "finger_lower": float(infos[finger][8]), "pads": pads}
    if gripper.kind == "jaw":
        hand = gripper.pad_links[1]
        box = gripper.fitted.box(hand)
        if box is not None:
            ids["pad_regions"] = ((link[hand], box.centre, box.rotation, box.half + PAD_MARGIN),)
    if grips or gripper.rests_closed:
        q = gripper.open_q if grips else gripper.closed_q
        ids["gripper_start"] = tuple((joint[n], v) for n, v in gripper.positions(q).items())
    return ids


def pad_forces(
    client, body: int, contacts: Sequence[tuple], pads: tuple[int, ...], regions
) -> list[float]:
    """The normal force (N) on each of ``pads`` (link indices): the sum over the arm's
    ``contacts`` (``getContactPoints`` rows) on that link, as MuJoCo's touch sensor sums them;
    a link with a region (:func:`gripper_ids`' ``pad_regions``) counts only the contacts whose
    point on it lies inside the region's box."""
    forces = []
    for pad in pads:
        rows = [p for p in contacts if p[3] == pad]
        region = next((r for r in regions if r[0] == pad), None)
        if region is not None and rows:
            inside = _inside(client, body, region, rows)
            rows = [p for p, keep in zip(rows, inside, strict=True) if keep]
        forces.append(sum(p[9] for p in rows))
    return forces


def _inside(client, body: int, region: PadRegion, rows: Sequence[tuple]) -> np.ndarray:
    """Whether each contact row's point on the link (world, index 5) lies in ``region``."""
    link, centre, rotation, half = region
    state = client.getLinkState(body, link, computeForwardKinematics=1)
    origin = np.asarray(state[4])
    frame = np.asarray(client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    points = np.array([p[5] for p in rows]) - origin
    local = (points @ frame - centre) @ rotation  # the box's axes
    return np.all(np.abs(local) <= half, axis=1)
