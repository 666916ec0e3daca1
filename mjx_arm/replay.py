"""Replay a recorded trajectory: a plot of reward, ee position and contact force, and a video.

A trajectory file is an ``.npz`` with, per control step ``t`` (``T`` steps):

- ``obs (T, 22)``: the flat observation the action was computed from (joint angles at
  ``[:, 7:13]``, target point at ``[:, 13:16]``, on a 6-joint arm);
- ``action (T, 6)``, ``reward (T,)``, ``done (T,)``;
- ``ee_pos (T, 3)`` and ``contact_force (T,)`` (force norm, N) after the step;
- ``task_config`` and ``arm_config``: the task and arm it was recorded on, as JSON.

Training writes one into each checkpoint (``transitions.npz``; its arm is the run's, in
``config.json``); ``mjx-arm eval --trajectory`` writes one per run. The video is drawn by
MuJoCo on the arm the trajectory was recorded on: each frame sets the joint angles and the
target of ``obs[t]`` in the CPU MuJoCo env's model and renders it from the scene camera.
"""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mjx_arm.inputs import (
    ConfigError,
    InputFileError,
    MiB,
    read_json_object,
    require_file,
    write_atomic,
)
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.task.observation import decode_joints, n_joints_of, obs_size, obs_slices
from mjx_arm.trajectory_files import (
    TrajectoryError,
    check_steps,
    read_trajectory_members,
    run_config_of,
)
from mjx_arm.video import VideoWriter as VideoWriter  # moved; importable here as before
from mjx_arm.video import fit_framebuffer as fit_framebuffer
from mjx_arm.video import rendering_available, write_video

if TYPE_CHECKING:
    from mjx_arm.arm.config import ArmConfig
    from mjx_arm.arm.resolve import ArmTask

REQUIRED_KEYS = ("obs", "reward", "ee_pos", "contact_force")
# The members a trajectory's reader unpacks (any other is never read), and what they may unpack
# to, each and together. A checkpoint's transitions.npz holds about 13 KiB; a million recorded
# steps of 30 float64 observations are 240 MiB. The limits stop a file that would unpack to
# gigabytes before it is unpacked.
TRAJECTORY_KEYS = frozenset((*REQUIRED_KEYS, "action", "done", "task_config", "arm_config"))
TRAJECTORY_MEMBER_BYTES = 512 * MiB
TRAJECTORY_TOTAL_BYTES = 1024 * MiB
DEFAULT_WIDTH, DEFAULT_HEIGHT = 800, 600
DPI = 100
# A contact-force axis spans at least this (N), so that solver noise (1e-12 N in free space)
# draws as a flat line at zero instead of being scaled up to look like a signal.
FORCE_AXIS_MIN_N = 5.0


# --------------------------------------------------------------------------- files


def load_trajectory(path: str | Path) -> dict[str, Any]:
    """Arrays of a trajectory ``.npz`` (and its ``task`` config, when the file holds one),
    checked: the required keys, one length, numeric finite values, an observation layout;
    read under bounds (:mod:`mjx_arm.trajectory_files`: bytes, elements, steps).

    Raises:
        TrajectoryError: not a readable trajectory file.
    """
    path = require_file(path, "trajectory file")
    traj = read_trajectory_members(
        path, TRAJECTORY_KEYS, TRAJECTORY_MEMBER_BYTES, TRAJECTORY_TOTAL_BYTES
    )
    missing = [k for k in REQUIRED_KEYS if k not in traj]
    if missing:
        raise TrajectoryError(f"{path} is not a trajectory file: it lacks {missing}")
    check_steps(path, {k: v for k, v in traj.items() if not k.endswith("_config")})
    _check_arrays(path, traj)
    if "task_config" in traj:
        try:
            traj["task_config"] = json.loads(str(traj["task_config"]))
        except (ValueError, RecursionError) as err:
            raise TrajectoryError(f"{path}: its task_config is not JSON ({err})") from err
    return traj


def _check_arrays(path: Path, traj: dict[str, Any]) -> None:
    """Shapes and values of the required arrays: ``obs (T, k)`` of a known layout,
    ``reward (T,)``, ``ee_pos (T, 3)``, ``contact_force (T,)``, all finite, T >= 1."""
    shapes = {"obs": (2,), "reward": (1,), "ee_pos": (2,), "contact_force": (1, 2)}
    for key, ndims in shapes.items():
        value = traj[key]
        if value.ndim not in ndims or value.dtype.kind not in "fiub" or not len(value):
            raise TrajectoryError(
                f"{path}: {key} must be a non-empty numeric array of {ndims[0]} dimensions, got "
                f"shape {value.shape} ({value.dtype})"
            )
        if not np.all(np.isfinite(value)):
            raise TrajectoryError(f"{path}: {key} holds NaN or infinite numbers")
    lengths = {k: len(traj[k]) for k in REQUIRED_KEYS}
    if len(set(lengths.values())) != 1:
        raise TrajectoryError(f"{path}: arrays differ in length {lengths}")
    if traj["ee_pos"].shape[1] != 3:
        raise TrajectoryError(f"{path}: ee_pos must be (T, 3), got {traj['ee_pos'].shape}")
    try:
        joints = state_layout(traj["obs"].shape[1])[0]
    except ValueError:
        joints = 0
    if not 5 <= joints <= 7:
        raise TrajectoryError(
            f"{path}: obs has {traj['obs'].shape[1]} entries per step, the layout of no task "
            "on an arm of 5 to 7 joints"
        )


def save_trajectory(
    path: str | Path, rows: dict[str, np.ndarray], task: TaskConfig, arm: ArmConfig | None = None
) -> Path:
    """Write a trajectory ``.npz``: the arrays, the task config and (when given) the config of
    the arm it was recorded on, each as JSON."""
    path = Path(path)
    payload = {k: np.asarray(v) for k, v in rows.items()}
    payload["task_config"] = np.array(json.dumps(task.to_dict()))
    if arm is not None:
        payload["arm_config"] = np.array(json.dumps(arm.to_dict()))
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **payload)
    write_atomic(buffer.getvalue(), path)
    return path


def trajectory_task(path: str | Path, traj: dict[str, Any], name: str | None = None):
    """The task a trajectory was recorded in: ``(TaskConfig, where it came from)``.

    Order: the ``name`` given; the file's own ``task_config``; the ``config.json`` of the run
    directory a ``checkpoints/step_N/transitions.npz`` sits in
    (:func:`~mjx_arm.trajectory_files.run_config_of`); else Touch.

    Raises:
        TrajectoryError: the file's task config, or its run's, is not usable.
    """
    if "task_config" in traj:
        task = _task_from(traj["task_config"], f"{path} (its task_config)")
        if name is None or name == task.task:
            return task, "the trajectory file"
    if name is not None:
        return task_config(name), "--task"
    config = run_config_of(path)
    if config is not None:
        try:
            saved = read_json_object(config, "run config")
        except InputFileError as err:
            raise TrajectoryError(str(err)) from err
        return _task_from(saved.get("task"), str(config)), str(config)
    return task_config("touch"), "default (touch): the file names no task"


def _task_from(data: Any, where: str) -> TaskConfig:
    """A :class:`TaskConfig` from a recorded task dict.

    Raises:
        TrajectoryError: not a dict of task fields.
    """
    if not isinstance(data, dict):
        raise TrajectoryError(f"{where}: no task config (a table of fields)")
    try:
        return TaskConfig.from_dict(data)
    except (ConfigError, TypeError) as err:
        raise TrajectoryError(f"{where}: not a usable task config: {err}") from err


def trajectory_arm(path: str | Path, traj: dict[str, Any], source: Any = None):
    """The arm a trajectory was recorded on, ``(ArmConfig, where it came from)``, checked to
    have the joints its observations hold.

    Order: ``source`` (``--arm``: a URDF, an arm file or a shipped arm's name); the file's own
    ``arm_config``; the arm in the ``config.json`` of the run whose checkpoint holds the file
    (:func:`~mjx_arm.trajectory_files.run_config_of`); else the shipped arm. A recorded shipped
    arm is this install's copy.

    Raises:
        TrajectoryError: a recorded arm that is not an arm config, or an arm of other joints.
        MissingInputError: the recorded arm's URDF is not on this machine.
    """
    from mjx_arm.arm.config import ArmConfigError, load_arm, recorded_arm, resolve_arm

    where, record = "default (the shipped arm): the file names no arm", "{}"
    config = run_config_of(path)
    if "arm_config" in traj:
        where, record = "the trajectory file", str(traj["arm_config"])
    elif config is not None:  # the run's arm record: its config, joints, model hash
        saved = read_json_object(config, "run config").get("arm", {})
        saved = saved.get("config", saved) if isinstance(saved, dict) else saved
        where, record = str(config), json.dumps(saved)
    try:
        arm = recorded_arm(json.loads(record), f"{path} was recorded on") if not source else None
    except (ArmConfigError, TypeError, ValueError, RecursionError) as err:
        raise TrajectoryError(f"{path} ({where}): not a usable arm config: {err}") from err
    arm = arm or load_arm(source)
    recorded, joints = state_layout(traj["obs"].shape[1])[0], len(resolve_arm(arm).joints)
    if recorded != joints:
        raise TrajectoryError(
            f"{path} was recorded on an arm of {recorded} joints; {arm.urdf_path.name} has "
            f"{joints}: pass the arm it was recorded on (--arm)"
        )
    return arm, "--arm" if source else where


# --------------------------------------------------------------------------- plot


def largest_reward_drop(reward: np.ndarray) -> int | None:
    """Step ``t`` where ``reward[t] - reward[t - 1]`` is most negative; None if none drops."""
    reward = np.asarray(reward, dtype=np.float64)
    if reward.size < 2:
        return None
    diff = np.diff(reward)
    t = int(np.argmin(diff))
    return t + 1 if diff[t] < 0 else None


def plot_trajectory(
    traj: dict[str, Any],
    output: str | Path,
    width: int = DEFAULT_WIDTH,
    height: int = DEFAULT_HEIGHT,
    title: str | None = None,
) -> Path:
    """Plot reward, ee x/y/z (with the target) and contact force per step to a PNG.

    Args:
        traj: arrays as from :func:`load_trajectory`.
        output: the PNG to write, exactly ``width`` x ``height`` pixels.
        title: figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = np.arange(len(traj["reward"]))
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(width / DPI, height / DPI), dpi=DPI)
    _plot_reward(axes[0], steps, traj["reward"])
    _plot_position(axes[1], steps, traj)
    _plot_force(axes[2], steps, np.asarray(traj["contact_force"], dtype=float))
    axes[2].set_xlabel("control step")
    drop = largest_reward_drop(traj["reward"])
    for ax in axes:
        ax.grid(alpha=0.3)
        if drop is not None:
            ax.axvline(drop, color="tab:red", linestyle="--", linewidth=1)
    if title:
        fig.suptitle(title)
    with warnings.catch_warnings():  # a small figure keeps matplotlib's layout, silently
        warnings.filterwarnings("ignore", "Tight layout not applied", UserWarning)
        fig.tight_layout()
    output = Path(output)
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=DPI, format="png")
    plt.close(fig)
    write_atomic(buffer.getvalue(), output)
    return output


def force_axis_limits(force: np.ndarray, span: float = FORCE_AXIS_MIN_N) -> tuple[float, float]:
    """The y range of a contact-force axis for ``force`` ``(T,)`` or ``(T, k)`` (N): from 0 (or
    the lowest value, if below) to the highest value plus 5 %, at least ``span`` N tall, and 2 %
    of that below the lowest value so that a line at zero stays clear of the axis."""
    low, high = min(0.0, float(np.min(force))), float(np.max(force))
    high = max(high + 0.05 * (high - low), low + span)
    return low - 0.02 * (high - low), high


def _plot_force(ax, steps: np.ndarray, force: np.ndarray) -> None:
    ax.plot(steps, force, color="tab:purple")
    ax.set_ylim(*force_axis_limits(force))
    ax.set_ylabel("contact force (N)")


def _plot_reward(ax, steps: np.ndarray, reward: np.ndarray) -> None:
    ax.plot(steps, reward, color="tab:blue")
    ax.set_ylabel("reward")
    drop = largest_reward_drop(reward)
    if drop is None:
        ax.text(0.02, 0.85, "the reward never drops", transform=ax.transAxes, color="tab:gray")
    else:
        delta = float(reward[drop] - reward[drop - 1])
        ax.annotate(
            f"largest drop {delta:+.2f} at step {drop}",
            xy=(drop, reward[drop]),
            xytext=(0.02, 0.85),
            textcoords="axes fraction",
            color="tab:red",
            arrowprops={"arrowstyle": "->", "color": "tab:red"},
        )


def state_layout(size: int) -> tuple[int, tuple]:
    """``(joints, extra keys)`` of a flat state of ``size`` entries: the one reading among the
    registered tasks' layouts with 5 to 7 joints (a gripper task adds its extra keys)."""
    from mjx_arm.task.registry import get_task, task_names

    for extra in dict.fromkeys(get_task(name).extra_obs for name in task_names()):
        n = size - obs_size(0, extra)
        if 5 <= n <= 7:
            return n, extra
    return n_joints_of(size), ()


def _plot_position(ax, steps: np.ndarray, traj: dict[str, Any]) -> None:
    target = traj["obs"][:, obs_slices(*state_layout(traj["obs"].shape[-1]))["target_rel"]]
    colors = ("tab:red", "tab:green", "tab:blue")
    for i, (axis, color) in enumerate(zip("xyz", colors, strict=True)):
        ax.plot(steps, traj["ee_pos"][:, i], color=color, label=f"ee {axis}")
        ax.plot(steps, target[:, i], color=color, linestyle=":", label=f"target {axis}")
    ax.set_ylabel("position (m)")
    ax.legend(ncol=3, fontsize="small", loc="best")


# --------------------------------------------------------------------------- video


def render_frames(
    traj: dict[str, Any],
    task: TaskConfig | ArmTask,
    width: int = DEFAULT_WIDTH,
    height: int = DEFAULT_HEIGHT,
    arm: Any = None,
) -> Iterator[np.ndarray]:
    """MuJoCo frames ``(height, width, 3)`` uint8 of each step's joint angles and target:
    ``task`` on its arm (an :class:`~mjx_arm.arm.resolve.ArmTask`), or a task config on ``arm``
    (default: the shipped arm)."""
    import mujoco

    from mjx_arm.envs.mujoco_env import MujocoArmEnv
    from mjx_arm.task import sampling
    from mjx_arm.urdf.scene import TARGET_BODY

    env = MujocoArmEnv(task, arm, render_mode="rgb_array", width=width, height=height)
    task = env.task
    fit_framebuffer(env.model, width, height)
    env.reset(seed=0)
    model, data = env.model, env.data
    mocap = int(model.body_mocapid[model.body(TARGET_BODY).id])
    offset = sampling.target_point(np, np.zeros(3), task)
    s = obs_slices(env.arm.n_joints, env.task_spec.extra_obs)
    width = obs_size(env.arm.n_joints, env.task_spec.extra_obs)
    if np.shape(traj["obs"])[-1] != width:
        env.close()
        raise TrajectoryError(
            f"the trajectory's observations have {np.shape(traj['obs'])[-1]} entries; "
            f"{task.task} on {env.arm.urdf.name} has {width}: pass the task (--task) and the "
            "arm (--arm) it was recorded on"
        )
    try:
        for obs in np.asarray(traj["obs"], dtype=np.float64):
            data.qpos[env.ids.qpos_adr] = decode_joints(obs[s["joint_angles"]], env._coding)
            data.mocap_pos[mocap] = obs[s["target_rel"]] - offset
            if env.grip is not None:
                _pose_gripper_task(env, obs, s)
            mujoco.mj_forward(model, data)
            yield env.render()
    finally:
        env.close()


def _pose_gripper_task(env: Any, obs: np.ndarray, s: dict[str, slice]) -> None:
    """A gripper task's fingers (from the closure) and object (its centre, and its orientation
    relative to the ee turned into the world frame) into the env's ``qpos``."""

    from mjx_arm.task.grip import quat_mul

    grip, data, model = env.grip, env.data, env.model
    gripper = grip.gripper
    finger = gripper.open_q + float(obs[s["gripper"]][0]) * (gripper.closed_q - gripper.open_q)
    for name, value in gripper.positions(finger).items():  # the driven finger and its mimics
        data.qpos[model.joint(name).qposadr[0]] = value
    ee_quat = obs[s["ee_pose"]][3:]
    quat = quat_mul(np, ee_quat, obs[s["object_rel"]][3:])
    grip.place(data.qpos, obs[s["target_rel"]], quat / np.linalg.norm(quat))


# --------------------------------------------------------------------------- the command


def replay(
    path: str | Path,
    output: str | Path,
    video: str | Path | None = None,
    width: int = DEFAULT_WIDTH,
    height: int = DEFAULT_HEIGHT,
    task_name: str | None = None,
    arm: Any = None,
) -> dict[str, Any]:
    """Plot a trajectory and optionally render its video, drawing the arm it was recorded on
    (:func:`trajectory_arm`; ``arm``: a URDF, an arm file or a shipped arm's name instead).

    Returns:
        A summary: the files written, the step count, the largest reward drop, the task and
        (with a video) the arm used, and a note when the video was skipped.
    """
    traj = load_trajectory(path)
    task, task_source = trajectory_task(path, traj, task_name)
    title = f"{Path(path).name} ({task.task}, {len(traj['reward'])} steps)"
    plot = plot_trajectory(traj, output, width, height, title)
    drop = largest_reward_drop(traj["reward"])
    summary: dict[str, Any] = {
        "trajectory": str(path),
        "steps": len(traj["reward"]),
        "return": float(np.sum(traj["reward"])),
        "largest_reward_drop_step": drop,
        "task": task.task,
        "task_from": task_source,
        "plot": str(plot),
        "video": None,
    }
    if video is not None:
        ok, reason = rendering_available()
        if ok:
            config, summary["arm_from"] = trajectory_arm(path, traj, arm)
            summary["arm"] = str(config.urdf_path)
            frames = render_frames(traj, task, width, height, config)
            summary["frames"] = write_video(video, frames, 1.0 / task.ctrl_dt)
            summary["video"] = str(video)
        else:
            summary["video_note"] = f"video skipped: {reason}"
    return summary
