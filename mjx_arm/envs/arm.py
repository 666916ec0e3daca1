"""What every engine needs to know about the arm, read once from the URDF."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjx_arm.paths import default_arm_urdf
from mjx_arm.task.wrench import ToolInertia, tool_inertia
from mjx_arm.urdf.model import parse_urdf

EE_LINK = "ee_link"
FT_JOINT = "ft_sensor_joint"
N_JOINTS = 6


@dataclass(frozen=True)
class ArmInfo:
    """Joint names and limits, tool frames and tool mass properties of a 6-joint arm.

    Attributes:
        urdf: path of the URDF.
        joint_names: the six actuated joints, base to wrist.
        lower, upper: position limits (rad), shape ``(6,)``.
        v_max: velocity limits (rad/s), shape ``(6,)``.
        effort: torque limits (N m), shape ``(6,)``.
        ee_link: the end-effector link; ft_joint: the fixed joint of the F/T reading.
        tool: mass properties of the tool below the F/T joint.
    """

    urdf: Path
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    v_max: np.ndarray
    effort: np.ndarray
    ee_link: str
    ft_joint: str
    tool: ToolInertia


@functools.cache
def _arm_info_cached(path: Path, mtime: float) -> ArmInfo:
    model = parse_urdf(path)
    joints = model.actuated_joints
    if len(joints) != N_JOINTS:
        raise ValueError(f"{path}: the task needs {N_JOINTS} actuated joints, found {len(joints)}")
    for name in (EE_LINK,):
        if name not in model.links:
            raise ValueError(f"{path}: the task needs a link named {name!r} (the ee point)")
    if FT_JOINT not in model.joints:
        raise ValueError(f"{path}: the task needs a fixed joint named {FT_JOINT!r} (wrist F/T)")
    limits = [j.limit for j in joints]
    return ArmInfo(
        urdf=path,
        joint_names=tuple(j.name for j in joints),
        lower=np.array([lim.lower for lim in limits]),
        upper=np.array([lim.upper for lim in limits]),
        v_max=np.array([lim.velocity for lim in limits]),
        effort=np.array([lim.effort for lim in limits]),
        ee_link=EE_LINK,
        ft_joint=FT_JOINT,
        tool=tool_inertia(model, FT_JOINT, EE_LINK),
    )


def arm_info(urdf: str | Path | None = None) -> ArmInfo:
    """Arm facts of ``urdf`` (default: the shipped arm), cached per file version."""
    path = Path(urdf or default_arm_urdf()).resolve()
    return _arm_info_cached(path, path.stat().st_mtime)


def validated_arm_info(urdf: str | Path | None, engine: str) -> ArmInfo:
    """Validate ``urdf`` (default: the shipped arm) for ``engine``, then read its arm facts.

    Validation comes first, so a broken file fails with the validator's report instead of a
    parse error.
    """
    from mjx_arm.urdf.validate import validated

    path = Path(urdf).expanduser().resolve() if urdf is not None else default_arm_urdf()
    validated(path, engine)
    return arm_info(path)
