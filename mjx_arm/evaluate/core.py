"""What ``mjx-arm eval`` runs: the policy and task to evaluate, the env, the numbers and the
summary line.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mjx_arm import engines
from mjx_arm.evaluate.fit import check_obs_layout, check_recorded_task
from mjx_arm.evaluate.runners import Policy, check_policy_arm, run_batched, run_episodes
from mjx_arm.evaluate.stats import EvalRun, summarize
from mjx_arm.inputs import ConfigError
from mjx_arm.names import engine_label, env_id
from mjx_arm.task.config import TaskConfig, task_config

# Fields of a task that change what an action does or what an observation reads; kept from the
# policy's training config when it is evaluated on the other task.
DYNAMICS_FIELDS = ("ctrl_dt", "sim_dt", "action_scale", "joint_encoding")

if TYPE_CHECKING:
    import gymnasium as gym

    from mjx_arm.arm.resolve import ArmTask


# --------------------------------------------------------------------------- evaluate


def resolve_policy(source: str | Path, step: int | None = None) -> tuple[Any, str]:
    """A policy from a file (``.npz`` / ``.onnx``) or a run directory.

    A run directory is exported on the fly (newest checkpoint, or ``step``) to a temporary
    ``.npz`` that is loaded into memory and deleted.

    Returns:
        ``(policy, description of where it came from)``.
    """
    from mjx_arm.policy import export_policy, load

    source = Path(source)
    if not source.is_dir():
        return load(source), str(source)
    with tempfile.TemporaryDirectory(prefix="mjx_arm_eval_") as folder:
        policy = load(export_policy(source, Path(folder) / "policy.npz", step))
    step = policy.metadata.get("step")
    return policy, f"{source} (checkpoint {'newest' if step is None else f'step {step:,}'})"


def eval_task(policy: Any, name: str | None = None) -> tuple[TaskConfig, list[str]]:
    """The task to evaluate in: the policy's training task, or preset ``name``.

    When ``name`` is another task than the training one, its preset is used with the
    policy's ``ctrl_dt``, ``sim_dt``, ``action_scale`` and ``joint_encoding`` (so an action
    and an observation mean the same).

    Returns:
        The task config and notes.
    """
    from mjx_arm.policy import PolicyFileError

    trained_dict = getattr(policy, "config", {}).get("task")
    if trained_dict is None:
        check_recorded_task(policy, None)
        return task_config(name or "touch"), ["the policy names no training task"]
    if not isinstance(trained_dict, dict):
        raise PolicyFileError("the policy's config.task is not a table: a damaged policy file")
    try:
        trained = TaskConfig.from_dict(trained_dict)
    except ConfigError as err:
        raise PolicyFileError(f"the policy's training task is not usable: {err}") from err
    check_recorded_task(policy, trained)
    if name is None or name == trained.task:
        return trained, []
    dynamics = {k: getattr(trained, k) for k in DYNAMICS_FIELDS}
    kept = ", ".join(f"{k} {v}" for k, v in dynamics.items())
    note = f"policy trained on {trained.task}, evaluated on {name} (its preset, with {kept})"
    return task_config(name, **dynamics), [note]


def make_eval_env(
    task: TaskConfig | ArmTask,
    engine: str,
    render: bool = False,
    width: int = 640,
    height: int = 480,
    arm: Any = None,
    contact: str | None = None,
) -> gym.Env:
    """A Gymnasium env of ``task`` on a CPU engine (``engine_names("env")``), made through its
    registered id (:func:`mjx_arm.envs.registration.make_env` behind Gymnasium's wrappers: the
    time limit and the checks), with an ``rgb_array`` renderer when ``render``. ``task``: the
    task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`, ``arm`` None), or a task config on
    ``arm`` (a URDF, an arm file or an ArmConfig; default: the shipped arm). ``contact``:
    PyBullet's scene contact ("soft", "rigid" or ``FIXED/CUBE``, :mod:`pybullet_ref.contact`;
    None: the env's default); an engine whose row lists no ``contact`` option ignores it."""
    import gymnasium as gym

    from mjx_arm.arm.resolve import ArmTask
    from mjx_arm.envs.registration import register_envs

    register_envs()  # idempotent; also registers tasks added since import
    kwargs = {"render_mode": "rgb_array", "width": width, "height": height} if render else {}
    if contact is not None and "contact" in engines.engine(engine).env_options:
        kwargs["contact"] = contact
    name = task.task.task if isinstance(task, ArmTask) else task.task
    return gym.make(env_id(name), engine=engine, task=task, arm=arm, **kwargs)


def eval_arm(policy: Any, source: str | Path | None = None) -> Any:
    """The arm to evaluate on: ``source`` (an arm file; a URDF: the arm the policy records,
    with its URDF found there instead), else the arm the policy records (files from before arm
    records: the shipped arm). A recorded arm of ``assets/`` (trained where this package lived
    elsewhere) is this install's copy; the model hash check
    (:func:`mjx_arm.arm.info.check_same_arm`) still compares the two.

    Raises:
        FileNotFoundError: the recorded arm's URDF is not on this machine (pass ``source``; a
            :class:`~mjx_arm.inputs.MissingInputError`).
    """
    from mjx_arm.arm.config import ARM_FILE_SUFFIXES, ArmConfig, load_arm, recorded_arm

    record = getattr(policy, "metadata", {}).get("arm") or {}
    if source is not None:
        given = load_arm(source)
        if Path(source).suffix.lower() in ARM_FILE_SUFFIXES or not record:
            return given
        arm = ArmConfig.from_dict(record.get("config", {}))
        return arm.replace(urdf=given.urdf)  # the recorded arm, its URDF found elsewhere
    return recorded_arm(record.get("config", {}), "the policy was trained on")


def evaluate(
    policy: Policy,
    engine: str,
    task: TaskConfig,
    episodes: int = 50,
    seed: int = 0,
    video: str | Path | None = None,
    width: int = 640,
    height: int = 480,
    backend: str | None = None,
    video_episodes: int = 1,
    impl: str = "auto",
    arm: Any = None,
    contact: str | None = None,
) -> tuple[dict[str, Any], EvalRun]:
    """Evaluate ``policy`` on ``engine`` and summarise.

    Args:
        policy: observation -> action (single or batched).
        engine: a Gymnasium env on a CPU or ``mjx`` (the batched env):
            :func:`mjx_arm.engines.eval_engines`.
        task: the task configuration.
        episodes, seed: how many episodes; the first one's seed (CPU) or the batch key's (mjx).
        video: a video (.mp4 or .gif) of the first ``video_episodes`` episodes, or None
            (mjx: env 0's episode, re-rendered in CPU MuJoCo).
        width, height: video frame size (pixels).
        backend: for ``engine="mjx"``: "mjx" (default) or "mujoco" (C MuJoCo, fast on a CPU).
        impl: for the MJX backend: "auto" (Warp on a GPU where installed), "jax" or "warp".
        arm: the arm (a URDF, an arm file or an ArmConfig; default: the shipped arm). A policy
            that records another arm raises :class:`~mjx_arm.arm.info.ArmMismatchError`.
        contact: PyBullet's scene contact (see :func:`make_eval_env`); None: the default.

    Returns:
        The JSON-ready summary and the raw :class:`EvalRun`.
    """
    _check_inputs(policy, engine, task, arm)  # before the task meets the arm
    start = time.monotonic()
    setup = _resolved(task, arm)  # once: every env below takes it as it is
    options = _RunOptions(video, video_episodes, (width, height), backend, impl, contact)
    run, physics = _run(policy, setup, engine, episodes, seed, options)
    result = {"engine": engine, "task": task.task, "seed": seed, **summarize(run.episodes)}
    return _finish(result, physics, start, video, run), run


@dataclass(frozen=True)
class _RunOptions:
    """How :func:`evaluate` runs: the ``video`` of its first ``video_episodes`` episodes with
    frames of ``size`` (width, height) pixels; the batched ``backend`` and ``impl``; the
    PyBullet ``contact``. :func:`evaluate` documents each."""

    video: str | Path | None
    video_episodes: int
    size: tuple[int, int]
    backend: str | None
    impl: str
    contact: str | None


def _check_inputs(policy: Policy, engine: str, task: TaskConfig, arm: Any) -> None:
    """Check that ``engine`` evaluates and that ``policy`` fits ``task`` on ``arm``."""
    from mjx_arm.arm.info import arm_info

    _check_engine(engine)
    check_policy_fits(policy, task, arm_info(arm))


def _resolved(task: TaskConfig, arm: Any) -> ArmTask:
    """``task`` on ``arm``, resolved once (:func:`mjx_arm.arm.resolve.resolve_task`)."""
    from mjx_arm.arm.resolve import resolve_task

    return resolve_task(task, arm)


def _run(
    policy: Policy, setup: ArmTask, engine: str, episodes: int, seed: int, options: _RunOptions
) -> tuple[EvalRun, dict[str, str]]:
    """Run ``episodes`` episodes of ``setup`` on ``engine``; (the run, its physics settings)."""
    if engine in engines.batch_engines():
        run = _run_batch(policy, setup, episodes, seed, options)
        return run, _batch_physics(options.backend, options.impl)
    width, height = options.size
    filmed = options.video is not None
    env = make_eval_env(setup, engine, filmed, width, height, None, options.contact)
    try:
        run = run_episodes(policy, env, episodes, seed, options.video, options.video_episodes)
    finally:
        env.close()
    return run, _env_physics(env.unwrapped, engine)


def _finish(
    result: dict[str, Any],
    physics: dict[str, str],
    start: float,
    video: str | Path | None,
    run: EvalRun,
) -> dict[str, Any]:
    """``result`` with the physics settings, the seconds since ``start``, the video's path (if
    any frame was filmed), the run's notes and its episodes one by one."""
    result.update(physics)
    result["wall_seconds"] = time.monotonic() - start
    result["video"] = str(video) if video is not None and run.frames else None
    result["video_frames"], result["video_episodes"] = run.frames, run.filmed
    result["notes"] = run.notes
    result["per_episode"] = [asdict(e) for e in run.episodes]
    return result


def _run_batch(
    policy: Policy, setup: ArmTask, episodes: int, seed: int, options: _RunOptions
) -> EvalRun:
    """:func:`run_batched` of ``setup`` (an :class:`~mjx_arm.arm.resolve.ArmTask`), and its
    env 0's episode filmed in CPU MuJoCo (frames of ``options.size``: width, height) where a
    video is asked for. ``options.backend`` None: "mjx"."""
    run = run_batched(policy, setup, episodes, seed, options.backend or "mjx", options.impl)
    if options.video is not None:
        run.frames, note = _replay_video(run.trajectory, setup, options.video, *options.size)
        run.notes += [note] if note else []
        run.filmed = int(run.frames > 0)
    return run


def check_policy_fits(policy: Any, task: TaskConfig, arm: Any) -> None:
    """Check that ``policy`` was trained on ``arm`` (an :class:`~mjx_arm.arm.info.ArmInfo`;
    :func:`~mjx_arm.evaluate.runners.check_policy_arm`) and takes the observation and gives
    the action of ``task`` on it (sizes, and the observation keys its metadata names:
    :func:`~mjx_arm.evaluate.fit.check_obs_layout`).

    Raises:
        ArmMismatchError: another arm's policy.
        PolicyFileError: its layer sizes or observation keys do not fit (another task's
            policy, or a damaged file).
    """
    from mjx_arm.envs.base import action_size
    from mjx_arm.policy import PolicyFileError
    from mjx_arm.task.observation import obs_layout, obs_size

    check_policy_arm(policy, arm)
    want = (obs_size(arm.n_joints, task.spec.extra_obs), action_size(arm, task))
    have = (getattr(policy, "obs_size", want[0]), getattr(policy, "action_size", want[1]))
    if have != want:
        raise PolicyFileError(
            f"the policy takes {have[0]} observations and gives {have[1]} actions; {task.task} "
            f"on {arm.urdf.name} has {want[0]} and {want[1]}: pass the task (--task) and arm "
            "(--arm) it was trained on"
        )
    layout = obs_layout(arm.n_joints, task.spec.extra_obs)
    check_obs_layout(policy, layout, f"{task.task} on {arm.urdf.name}")


def _check_engine(engine: str) -> None:
    choices = engines.eval_engines()
    if engine not in choices:
        raise ConfigError(f"engine must be one of {choices}, got {engine!r}")


def _env_physics(env: Any, engine: str) -> dict[str, str]:
    """The engine-only settings (``env_options`` of its registry row) a CPU evaluation ran
    with, for its summary: ``{"contact": ...}`` on the PyBullet reference, else ``{}``."""
    options = engines.engine(engine).env_options
    return {name: str(getattr(env, name)) for name in options}


def _batch_physics(backend: str | None, impl: str) -> dict[str, str]:
    """The ``backend`` (and MJX ``impl``) an ``mjx`` evaluation ran on, for its summary."""
    from mjx_arm.envs.physics_config import resolve_impl

    out = {"backend": backend or "mjx"}
    if out["backend"] == "mjx":
        out["impl"] = resolve_impl(impl)
    return out


def _replay_video(
    traj: dict[str, np.ndarray], setup: ArmTask, video: str | Path, width: int, height: int
) -> tuple[int, str]:
    """Film a batched env's trajectory of ``setup`` through the CPU MuJoCo renderer."""
    from mjx_arm.replay import render_frames, rendering_available, write_video

    ok, reason = rendering_available()
    if not ok:
        return 0, f"video skipped: {reason}"
    rate = 1.0 / setup.task.ctrl_dt
    frames = write_video(video, render_frames(traj, setup, width, height), rate)
    return frames, "video: env 0's episode re-rendered in CPU MuJoCo from its joint angles"


def format_summary(result: dict[str, Any]) -> str:
    """A few human-readable lines of an :func:`evaluate` result."""
    low, high = result["success_ci95"]

    def num(key: str, fmt: str) -> str:
        value = result.get(key)
        return "n/a" if value is None else format(value, fmt)

    lines = [
        f"{engine_label(result['engine'], result.get('backend'))}, task {result['task']}: "
        f"{result['episodes']} episodes in {result['wall_seconds']:.1f} s",
        f"  success rate      {result['success_rate']:.3f}  (95% CI {low:.3f} - {high:.3f})",
        f"  mean return       {num('mean_return', '.2f')}",
        f"  steps to success  {num('mean_steps_to_success', '.1f')}",
        f"  peak contact (N)  {num('mean_peak_contact_force', '.2f')}",
        f"  final distance    {num('mean_final_distance', '.4f')} m",
    ]
    lines += [f"  note: {n}" for n in result.get("notes", [])]
    return "\n".join(lines)
