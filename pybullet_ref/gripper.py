"""The gripper's joints in a loaded PyBullet body: what drives it, its pads, where it starts."""

from __future__ import annotations

from mjx_arm.arm.info import Gripper


def gripper_ids(
    gripper: Gripper | None, grips: bool, joint: dict[str, int], link: dict[str, int], infos: list
) -> dict:
    """:class:`~pybullet_ref.env.ArmIds` fields of the arm's gripper (none without one).

    Args:
        gripper: the arm's gripper, or None.
        grips: whether the task grips (Lift): its gripper starts open; a linkage gripper in
            the other tasks starts closed, as in the MuJoCo models (``rest_qpos``).
        joint, link: joint and link index by name; infos: ``getJointInfo`` rows.

    Returns:
        ``finger`` (the driven joint), ``finger_lower`` (its lower limit, m or rad), ``pads``
        (the two pad links, whose contacts make the pad forces) and ``gripper_start``
        (``(joint index, position)`` of every gripper joint to put at reset; empty for a
        parallel gripper in a task that does not grip, whose fingers stay at 0).
    """
    if gripper is None:
        return {}
    finger = joint[gripper.joint]
    pads = tuple(link[name] for name in gripper.pad_links[:2])
    ids = {"finger": finger, "finger_lower": float(infos[finger][8]), "pads": pads}
    if grips or gripper.linkage:
        q = gripper.open_q if grips else gripper.closed_q
        ids["gripper_start"] = tuple((joint[n], v) for n, v in gripper.positions(q).items())
    return ids
