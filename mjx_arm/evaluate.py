"""Evaluate an exported policy in any engine of the contract, with numbers and a video.

- :func:`run_episodes` is the Gymnasium-side runner: any env of the contract (``gymnasium.make
  ("mjx_arm/Reach-v0", engine="mujoco" | "pybullet")`` or your own), any number of episodes,
  an optional video from the env's ``render()``.
- :func:`run_batched` runs the episodes at once on :class:`~mjx_arm.envs.vector.ArmVectorEnv`
  (MJX, or C MuJoCo behind the same JAX interface).
- :func:`evaluate` is what ``mjx-arm eval`` calls: success rate with its 95 % Wilson interval,
  mean return, mean steps to success, mean peak contact force, as a JSON-ready dict.

Episode ``i`` of a CPU engine is reset with ``seed + i``, so MuJoCo and PyBullet see the same
start poses and targets. The batched env draws its episodes from JAX's generator instead.
"""

from __future__ import annotations

import functools
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mjx_arm.names import EVAL_ENGINES as ENGINES
from mjx_arm.names import TASK_IDS
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.task.observation import OBS_KEYS, flatten_obs

Z95 = 1.959963984540054
# Fields of a task that change what an action does; kept from the policy's training config when
# it is evaluated on the other task.
DYNAMICS_FIELDS = ("ctrl_dt", "sim_dt", "action_scale")

if TYPE_CHECKING:
    import gymnasium as gym

Policy = Callable[[Any], np.ndarray]


@dataclass
class EpisodeStats:
    """One episode's numbers.

    Attributes:
        episode_return: sum of rewards. steps: control steps taken.
        success: the success rule held at some step.
        steps_to_success: the first step (1-based) it held, else None.
        peak_contact_force: largest contact force norm (N) over the episode.
        final_distance: ee-to-target distance (m) at the last step.
    """

    episode_return: float
    steps: int
    success: bool
    steps_to_success: int | None
    peak_contact_force: float
    final_distance: float


@dataclass
class EvalRun:
    """What :func:`run_episodes` / :func:`run_batched` return.

    Attributes:
        episodes: per-episode numbers.
        trajectories: each episode's arrays (see :mod:`mjx_arm.replay`), ``T_i`` rows; the
            batched runner records env 0's only.
        frames: frames written to the video (0 without one).
        notes: what was skipped and why (e.g. no renderer).
    """

    episodes: list[EpisodeStats]
    trajectories: list[dict[str, np.ndarray]]
    frames: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def trajectory(self) -> dict[str, np.ndarray]:
        """The first episode's trajectory."""
        return self.trajectories[0]

    def longest_trajectory(self) -> dict[str, np.ndarray]:
        """The trajectory with the most steps (the first of equals)."""
        return max(self.trajectories, key=lambda t: len(t["reward"]))


class _Recorder:
    """Per-step rows of one episode (the trajectory format of :mod:`mjx_arm.replay`)."""

    KEYS = ("obs", "action", "reward", "done", "ee_pos", "contact_force", "distance", "success")

    def __init__(self) -> None:
        self.rows: dict[str, list] = {k: [] for k in self.KEYS}

    def add(
        self,
        flat_obs: np.ndarray,
        action: np.ndarray,
        reward: float,
        done: bool,
        next_obs: dict[str, np.ndarray],
        info: dict[str, Any],
    ) -> None:
        """Record one step: the observation acted on, then what the step produced."""
        values = (
            flat_obs,
            action,
            reward,
            done,
            np.asarray(next_obs["ee_pose"])[:3],
            info["contact_force_norm"],
            info["distance"],
            info["is_success"],
        )
        for key, value in zip(self.KEYS, values, strict=True):
            self.rows[key].append(np.asarray(value))

    def arrays(self) -> dict[str, np.ndarray]:
        """``obs (T, 22)``, ``action (T, 6)``, ``ee_pos (T, 3)``, the rest ``(T,)``."""
        dtypes = {"done": bool, "success": bool}
        return {k: np.asarray(v, dtype=dtypes.get(k, np.float32)) for k, v in self.rows.items()}


# --------------------------------------------------------------------------- statistics


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Returns:
        ``(low, high)`` in [0, 1]; ``(0, 1)`` when ``n`` is 0.
    """
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def summarize(episodes: list[EpisodeStats]) -> dict[str, Any]:
    """Success rate, its Wilson 95 % interval and the means of the episodes' numbers."""
    n = len(episodes)
    successes = sum(e.success for e in episodes)
    low, high = wilson_interval(successes, n)
    returns = [e.episode_return for e in episodes]
    return {
        "episodes": n,
        "successes": successes,
        "success_rate": successes / n if n else None,
        "success_ci95": [low, high],
        "mean_return": _mean(returns),
        "std_return": float(np.std(returns)) if returns else None,
        "mean_steps_to_success": _mean(
            [e.steps_to_success for e in episodes if e.steps_to_success is not None]
        ),
        "mean_episode_steps": _mean([e.steps for e in episodes]),
        "mean_peak_contact_force": _mean([e.peak_contact_force for e in episodes]),
        "mean_final_distance": _mean([e.final_distance for e in episodes]),
    }


# --------------------------------------------------------------------------- Gymnasium runner


def _flat(obs: Any) -> np.ndarray:
    return flatten_obs(np, {k: np.asarray(obs[k], np.float32) for k in OBS_KEYS})


def run_episode(
    policy: Policy, env: gym.Env, seed: int | None, capture: Callable[[], None] | None = None
) -> tuple[EpisodeStats, dict]:
    """One episode of ``policy`` in a Gymnasium env of the contract.

    Args:
        policy: observation -> action ``(6,)``.
        env: a Gymnasium env with the contract's spaces and ``info`` keys.
        seed: reset seed.
        capture: called after the reset and after every step (e.g. to film ``render()``).

    Returns:
        The episode's numbers and its trajectory arrays.
    """
    obs, _ = env.reset(seed=seed)
    if capture is not None:
        capture()
    rec, ret, first_success, peak = _Recorder(), 0.0, None, 0.0
    steps, done, info = 0, False, {"distance": math.nan}
    while not done:
        action = policy(obs)
        next_obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        rec.add(_flat(obs), action, reward, terminated, next_obs, info)
        ret += float(reward)
        peak = max(peak, float(info["contact_force_norm"]))
        if info["is_success"] and first_success is None:
            first_success = steps
        done, obs = bool(terminated or truncated), next_obs
        if capture is not None:
            capture()
    stats = EpisodeStats(
        ret, steps, first_success is not None, first_success, peak, float(info["distance"])
    )
    return stats, rec.arrays()


def run_episodes(
    policy: Policy,
    env: gym.Env,
    episodes: int,
    seed: int = 0,
    video: str | Path | None = None,
    video_episodes: int = 1,
) -> EvalRun:
    """Run ``episodes`` episodes (episode ``i`` reset with ``seed + i``), optionally filmed.

    Args:
        policy: observation -> action ``(6,)`` (e.g. :func:`mjx_arm.policy.load`'s result).
        env: a Gymnasium env of the contract; for a video, made with ``render_mode="rgb_array"``.
        episodes: number of episodes.
        seed: seed of the first episode.
        video: ``.mp4`` or ``.gif`` path for the first ``video_episodes`` episodes, or None.
        video_episodes: episodes to film.

    Returns:
        Per-episode numbers and trajectories, the frame count and notes.
    """
    writer, notes = _open_video(env, video)
    results, trajectories = [], []
    for i in range(episodes):
        capture = functools.partial(writer.capture, env) if writer and i < video_episodes else None
        try:
            stats, traj = run_episode(policy, env, seed + i, capture)
        except _RenderError as exc:  # the renderer failed: redo the episode without it
            notes.append(f"video stopped: {exc}")
            writer.close()
            writer = None
            stats, traj = run_episode(policy, env, seed + i)
        results.append(stats)
        trajectories.append(traj)
    frames = writer.close() if writer is not None else 0
    return EvalRun(results, trajectories, frames, notes)


class _RenderError(RuntimeError):
    """``render()`` failed."""


class _SafeVideo:
    """A VideoWriter fed by ``env.render()``; any render failure becomes a _RenderError."""

    def __init__(self, writer) -> None:
        self.writer = writer

    def capture(self, env: gym.Env) -> None:
        """Render one frame of ``env`` into the video."""
        try:
            frame = env.render()
        except Exception as exc:  # GL context or driver errors surface as many types
            raise _RenderError(f"{type(exc).__name__}: {exc}") from exc
        if frame is None:
            raise _RenderError("render() returned None: make the env with render_mode='rgb_array'")
        self.writer.append(frame)

    def close(self) -> int:
        """Finish the file; returns the frame count."""
        return self.writer.close()


def _open_video(env: gym.Env, video: str | Path | None) -> tuple[_SafeVideo | None, list[str]]:
    from mjx_arm.replay import VideoWriter, fit_framebuffer, rendering_available

    if video is None:
        return None, []
    if getattr(env, "render_mode", None) != "rgb_array":
        return None, ["video skipped: the env was not made with render_mode='rgb_array'"]
    ok, reason = rendering_available()
    if not ok and getattr(env.unwrapped, "engine", "") == "mujoco":
        return None, [f"video skipped: {reason}"]
    model = getattr(env.unwrapped, "model", None)
    if model is not None and hasattr(model, "vis"):  # MuJoCo: room for frames over 640 x 480
        fit_framebuffer(model, env.unwrapped.width, env.unwrapped.height)
    fps = env.metadata.get("render_fps", 30)
    return _SafeVideo(VideoWriter(video, fps)), []


# --------------------------------------------------------------------------- batched runner


def run_batched(
    policy: Policy,
    task: TaskConfig,
    episodes: int,
    seed: int = 0,
    backend: str = "mjx",
    impl: str = "auto",
) -> EvalRun:
    """Run ``episodes`` episodes at once, one per env of an :class:`ArmVectorEnv`.

    Each env's first episode counts; envs that finish early are reset by the vector env and
    ignored until the slowest one ends (at most ``task.episode_steps`` steps).

    Args:
        policy: batched observation Dict -> actions ``(episodes, 6)``.
        task: the task configuration.
        episodes: number of envs (= episodes).
        seed: seed of the batch's PRNG key.
        backend: "mjx" (MJX: slow on a CPU), "mujoco" (C MuJoCo) or "auto".
        impl: MJX implementation: "auto", "jax" or "warp".
    """
    from mjx_arm.envs.physics_config import PhysicsConfig
    from mjx_arm.envs.vector import ArmVectorEnv

    env = ArmVectorEnv(task, episodes, backend, PhysicsConfig(impl=impl))
    obs, _ = env.reset(seed=seed)
    acc = _BatchAccumulator(episodes)
    rec = _Recorder()
    while acc.active.any():
        actions = np.asarray(policy(obs), dtype=np.float32).reshape(episodes, 6)
        next_obs, rewards, terminated, truncated, info = env.step(actions)
        final = info.get("final_obs", next_obs)
        if acc.active[0]:
            row = {k: v[0] for k, v in info.items() if k in ("contact_force_norm", "distance")}
            row["is_success"] = info["is_success"][0]
            rec.add(
                _flat({k: v[0] for k, v in obs.items()}),
                actions[0],
                rewards[0],
                terminated[0],
                {"ee_pose": final["ee_pose"][0]},
                row,
            )
        acc.add(rewards, terminated | truncated, info)
        obs = next_obs
    env.close()
    return EvalRun(acc.episodes(), [rec.arrays()])


class _BatchAccumulator:
    """Running per-env sums of a batch of first episodes."""

    def __init__(self, n: int) -> None:
        self.active = np.ones(n, bool)
        self.ret = np.zeros(n)
        self.steps = np.zeros(n, int)
        self.first_success = np.zeros(n, int)
        self.peak = np.zeros(n)
        self.distance = np.full(n, np.nan)

    def add(self, rewards: np.ndarray, done: np.ndarray, info: dict[str, Any]) -> None:
        """Add one step's numbers to the envs still in their first episode."""
        a = self.active
        self.ret[a] += np.asarray(rewards)[a]
        self.steps[a] += 1
        new = a & np.asarray(info["is_success"]) & (self.first_success == 0)
        self.first_success[new] = self.steps[new]
        self.peak[a] = np.maximum(self.peak[a], np.asarray(info["contact_force_norm"])[a])
        self.distance[a] = np.asarray(info["distance"])[a]
        self.active = a & ~np.asarray(done)

    def episodes(self) -> list[EpisodeStats]:
        """One :class:`EpisodeStats` per env."""
        return [
            EpisodeStats(
                float(self.ret[i]),
                int(self.steps[i]),
                bool(self.first_success[i] > 0),
                int(self.first_success[i]) if self.first_success[i] > 0 else None,
                float(self.peak[i]),
                float(self.distance[i]),
            )
            for i in range(len(self.ret))
        ]


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
    return policy, f"{source} (checkpoint step {policy.metadata['step']})"


def eval_task(policy: Any, name: str | None = None) -> tuple[TaskConfig, list[str]]:
    """The task to evaluate in: the policy's training task, or preset ``name``.

    When ``name`` is another task than the training one, its preset is used with the
    policy's ``ctrl_dt``, ``sim_dt`` and ``action_scale`` (so an action means the same).

    Returns:
        The task config and notes.
    """
    trained_dict = getattr(policy, "config", {}).get("task")
    if trained_dict is None:
        return task_config(name or "touch"), ["the policy names no training task"]
    trained = TaskConfig.from_dict(trained_dict)
    if name is None or name == trained.task:
        return trained, []
    dynamics = {k: getattr(trained, k) for k in DYNAMICS_FIELDS}
    note = f"policy trained on {trained.task}, evaluated on {name} (its preset; {dynamics})"
    return task_config(name, **dynamics), [note]


def make_env(
    task: TaskConfig, engine: str, render: bool = False, width: int = 640, height: int = 480
) -> gym.Env:
    """A Gymnasium env of ``task`` on a CPU engine ("mujoco" or "pybullet")."""
    import gymnasium as gym

    import mjx_arm  # noqa: F401  (registers the ids)

    kwargs = {"render_mode": "rgb_array", "width": width, "height": height} if render else {}
    return gym.make(TASK_IDS[task.task], engine=engine, task=task, **kwargs)


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
) -> tuple[dict[str, Any], EvalRun]:
    """Evaluate ``policy`` on ``engine`` and summarise.

    Args:
        policy: observation -> action (single or batched).
        engine: "mujoco", "pybullet" (Gymnasium envs) or "mjx" (the batched env).
        task: the task configuration.
        episodes: number of episodes.
        seed: first episode's seed (CPU engines) or the batch key's seed (mjx).
        video: a video (.mp4 or .gif) of the first ``video_episodes`` episodes, or None
            (mjx: env 0's episode, re-rendered in CPU MuJoCo).
        width, height: video frame size (pixels).
        backend: for ``engine="mjx"``: "mjx" (default) or "mujoco" (C MuJoCo, fast on a CPU).
        impl: for the MJX backend: "auto" (Warp on a GPU where installed), "jax" or "warp".

    Returns:
        The JSON-ready summary and the raw :class:`EvalRun`.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    start = time.monotonic()
    if engine == "mjx":
        run = run_batched(policy, task, episodes, seed, backend or "mjx", impl)
        if video is not None:
            run.frames, note = _replay_video(run.trajectory, task, video, width, height)
            run.notes += [note] if note else []
    else:
        env = make_env(task, engine, render=video is not None, width=width, height=height)
        try:
            run = run_episodes(policy, env, episodes, seed, video, video_episodes)
        finally:
            env.close()
    result = {"engine": engine, "task": task.task, "seed": seed, **summarize(run.episodes)}
    if engine == "mjx":
        from mjx_arm.envs.physics_config import resolve_impl

        result["backend"] = backend or "mjx"
        if result["backend"] == "mjx":
            result["impl"] = resolve_impl(impl)
    result["wall_seconds"] = time.monotonic() - start
    result["video"] = str(video) if video is not None and run.frames else None
    result["notes"] = run.notes
    result["per_episode"] = [asdict(e) for e in run.episodes]
    return result, run


def _replay_video(
    traj: dict[str, np.ndarray], task: TaskConfig, video: str | Path, width: int, height: int
) -> tuple[int, str]:
    """Film a batched env's trajectory through the CPU MuJoCo renderer."""
    from mjx_arm.replay import render_frames, rendering_available, write_video

    ok, reason = rendering_available()
    if not ok:
        return 0, f"video skipped: {reason}"
    frames = write_video(video, render_frames(traj, task, width, height), 1.0 / task.ctrl_dt)
    return frames, "video: env 0's episode re-rendered in CPU MuJoCo from its joint angles"


def format_summary(result: dict[str, Any]) -> str:
    """A few human-readable lines of an :func:`evaluate` result."""
    low, high = result["success_ci95"]

    def num(key: str, fmt: str) -> str:
        value = result.get(key)
        return "n/a" if value is None else format(value, fmt)

    lines = [
        f"{result['engine']} ({result['task']}): {result['episodes']} episodes "
        f"in {result['wall_seconds']:.1f} s",
        f"  success rate      {result['success_rate']:.3f}  (95% CI {low:.3f} - {high:.3f})",
        f"  mean return       {num('mean_return', '.2f')}",
        f"  steps to success  {num('mean_steps_to_success', '.1f')}",
        f"  peak contact (N)  {num('mean_peak_contact_force', '.2f')}",
        f"  final distance    {num('mean_final_distance', '.4f')} m",
    ]
    lines += [f"  note: {n}" for n in result.get("notes", [])]
    return "\n".join(lines)
