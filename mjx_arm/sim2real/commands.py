"""What the limiter's commands look like on the wire: URScript ``servoj`` lines and a ROS 2
``trajectory_msgs/JointTrajectory`` message (as a JSON-ready dict)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

NANOSECONDS = 1_000_000_000


@dataclass(frozen=True)
class ServojConfig:
    """Arguments of URScript's ``servoj(q, a, v, t, lookahead_time, gain)``.

    Attributes:
        t: time (s) each ``servoj`` controls the robot (it blocks that long): the control period.
        lookahead_time: smoothing look-ahead (s), URScript range [0.03, 0.2].
        gain: proportional gain of the target following, URScript range [100, 2000].
        a, v: acceleration and velocity; URScript ignores both in ``servoj`` (the limiter bounds
            them), written as given.
    """

    t: float
    lookahead_time: float = 0.1
    gain: float = 300.0
    a: float = 0.0
    v: float = 0.0

    def __post_init__(self) -> None:
        if not self.t > 0:
            raise ValueError(f"t must be positive, got {self.t}")
        if not 0.03 <= self.lookahead_time <= 0.2:
            raise ValueError(f"lookahead_time must be in [0.03, 0.2], got {self.lookahead_time}")
        if not 100 <= self.gain <= 2000:
            raise ValueError(f"gain must be in [100, 2000], got {self.gain}")


def _checked_targets(targets: np.ndarray, joints: int | None = None) -> np.ndarray:
    """Targets as a finite float64 ``(T, n)`` array."""
    q = np.asarray(targets, dtype=np.float64)
    if q.ndim != 2 or (joints is not None and q.shape[1] != joints):
        raise ValueError(f"targets must have shape (T, {joints or 'n'}), got {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError("targets contain NaN or inf")
    return q


def servoj_line(q: Sequence[float], config: ServojConfig) -> str:
    """One URScript call: ``servoj([q1, ..., q6], a, v, t, lookahead_time, gain)``."""
    joints = ", ".join(f"{float(v):.6f}" for v in q)
    return (
        f"servoj([{joints}], {config.a:g}, {config.v:g}, {config.t:.6f}, "
        f"{config.lookahead_time:g}, {config.gain:g})"
    )


def urscript_program(
    targets: np.ndarray,
    config: ServojConfig,
    joint_names: Sequence[str],
    name: str = "mjx_arm_servo",
    stop_deceleration: float = 4.0,
) -> str:
    """A URScript program that streams ``targets`` with ``servoj``, then stops.

    Args:
        targets: joint position commands (rad), ``(T, 6)``, one per control period.
        config: the ``servoj`` arguments (``t`` = the control period).
        joint_names: the joints, in the column order of ``targets`` (written as a comment).
        name: the program's function name.
        stop_deceleration: joint deceleration (rad/s^2) of the closing ``stopj``.

    Returns:
        The program text: ``def name(): ... end`` and the call of it.
    """
    q = _checked_targets(targets, len(joint_names))
    lines = [
        f"def {name}():",
        f"  # {len(q)} joint position targets, one every {config.t:.6f} s",
        f"  # joints: {', '.join(joint_names)} (rad)",
        *(f"  {servoj_line(row, config)}" for row in q),
        f"  stopj({stop_deceleration:g})",
        "end",
        f"{name}()",
    ]
    return "\n".join(lines) + "\n"


def duration(seconds: float) -> dict[str, int]:
    """A ROS ``builtin_interfaces/Duration`` (or ``Time``) as ``{"sec", "nanosec"}``.

    Whole nanoseconds, rounded; ``nanosec`` in [0, 1e9).
    """
    ns = round(seconds * NANOSECONDS)
    return {"sec": ns // NANOSECONDS, "nanosec": ns % NANOSECONDS}


def joint_trajectory_msg(
    targets: np.ndarray,
    dt: float,
    joint_names: Sequence[str],
    velocities: np.ndarray | None = None,
    frame_id: str = "base_link",
    stamp: float = 0.0,
) -> dict[str, Any]:
    """A ``trajectory_msgs/JointTrajectory`` message as a JSON-ready dict.

    Point ``k`` (0-based) is due ``(k + 1) * dt`` after the header stamp: each command is
    reached one control period after it is sent, as with ``servoj``.

    Args:
        targets: joint position commands (rad), ``(T, n)``.
        dt: control period (s).
        joint_names: the ``n`` joint names, in the column order of ``targets``.
        velocities: joint velocities (rad/s) at the points, ``(T, n)``; empty lists if None.
        frame_id: header frame.
        stamp: header time (s); 0 means "start now" to a joint trajectory controller.

    Returns:
        ``{"header": {"stamp", "frame_id"}, "joint_names", "points": [...]}``, each point
        ``{"positions", "velocities", "accelerations", "effort", "time_from_start"}``.
    """
    q = _checked_targets(targets, len(joint_names))
    qd = None if velocities is None else _checked_targets(velocities, len(joint_names))
    if qd is not None and qd.shape != q.shape:
        raise ValueError(f"velocities {qd.shape} do not match targets {q.shape}")
    points = [
        {
            "positions": q[k].tolist(),
            "velocities": [] if qd is None else qd[k].tolist(),
            "accelerations": [],
            "effort": [],
            "time_from_start": duration((k + 1) * dt),
        }
        for k in range(len(q))
    ]
    return {
        "header": {"stamp": duration(stamp), "frame_id": frame_id},
        "joint_names": list(joint_names),
        "points": points,
    }
