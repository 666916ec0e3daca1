"""Run a policy for episodes: one Gymnasium env at a time (with an optional video), or the
whole batch at once on the JAX vector env.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mjx_arm.evaluate.stats import EpisodeStats, EvalRun
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.observation import flatten_obs

if TYPE_CHECKING:
    import gymnasium as gym

    from mjx_arm.arm.resolve import ArmTask

Policy = Callable[[Any], np.ndarray]


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


# --------------------------------------------------------------------------- Gymnasium runner


def _flat(obs: Any) -> np.ndarray:
    """The flat state of an observation dict: the contract's keys, then a task's extra ones."""
    return flatten_obs(np, {k: np.asarray(v, np.float32) for k, v in obs.items()})


def run_episode(
    policy: Policy, env: gym.Env, seed: int | None, capture: Callable[[], None] | None = None
) -> tuple[EpisodeStats, dict]:
    """One episode of ``policy`` in a Gymnasium env of the contract.

    Args:
        policy: observation -> action ``(n,)``.
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
        policy: observation -> action ``(n,)`` (e.g. :func:`mjx_arm.policy.load`'s result).
        env: a Gymnasium env of the contract; for a video, made with ``render_mode="rgb_array"``.
        episodes: number of episodes.
        seed: seed of the first episode.
        video: ``.mp4`` or ``.gif`` path for the first ``video_episodes`` episodes, or None.
        video_episodes: episodes to film.

    Returns:
        Per-episode numbers and trajectories, the frame count and notes.
    """
    writer, notes = _open_video(env, video)
    results, trajectories, filmed = [], [], 0
    heartbeat = Heartbeat(episodes, "episodes")
    for i in range(episodes):
        capture = functools.partial(writer.capture, env) if writer and i < video_episodes else None
        try:
            stats, traj = run_episode(policy, env, seed + i, capture)
            filmed += capture is not None
        except _RenderError as exc:  # the renderer failed: redo the episode without it
            notes.append(f"video stopped: {exc}")
            writer.close()
            writer = None
            stats, traj = run_episode(policy, env, seed + i)
        results.append(stats)
        trajectories.append(traj)
        heartbeat(i + 1)
    frames = writer.close() if writer is not None else 0
    return EvalRun(results, trajectories, frames, notes, filmed if frames else 0)


class Heartbeat:
    """Says on stderr how far a long loop has come, at most every ``every`` seconds and never
    in its first ``every`` seconds: an evaluation of 50 PyBullet episodes with a video ran 51 s
    on 2 cores with nothing printed.

    Args:
        total: how many items the loop runs.
        what: the items' name ("episodes").
        every: seconds between two lines.
        clock: the time source (tests pass their own).
    """

    def __init__(self, total: int, what: str, every: float = 15.0, clock=time.monotonic):
        self.total, self.what, self.every, self.clock = total, what, every, clock
        self.start = self.last = clock()

    def __call__(self, done: int) -> None:
        """Note that ``done`` items are finished; print a line if one is due."""
        now = self.clock()
        if now - self.last >= self.every and done < self.total:
            elapsed = now - self.start
            print(f"  {done} of {self.total} {self.what} ({elapsed:.0f} s)", file=sys.stderr)
            sys.stderr.flush()
            self.last = now


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
    model = getattr(env.unwrapped, "model", None)
    if model is not None and hasattr(model, "vis"):  # an env that draws with MuJoCo
        ok, reason = rendering_available()
        if not ok:
            return None, [f"video skipped: {reason}"]
        fit_framebuffer(model, env.unwrapped.width, env.unwrapped.height)  # frames over 640x480
    fps = env.metadata.get("render_fps", 30)
    return _SafeVideo(VideoWriter(video, fps)), []


def check_policy_arm(policy: Any, arm: Any) -> None:
    """Raise :class:`~mjx_arm.arm.info.ArmMismatchError` when ``policy`` (with ``metadata``)
    was trained on another arm than ``arm`` (an :class:`~mjx_arm.arm.info.ArmInfo`)."""
    from mjx_arm.arm.info import check_same_arm

    metadata = getattr(policy, "metadata", None)
    if metadata is not None:
        check_same_arm(metadata.get("arm"), arm)


# --------------------------------------------------------------------------- batched runner


def run_batched(
    policy: Policy,
    task: TaskConfig | ArmTask,
    episodes: int,
    seed: int = 0,
    backend: str = "mjx",
    impl: str = "auto",
    arm=None,
) -> EvalRun:
    """Run ``episodes`` episodes at once, one per env of an :class:`ArmVectorEnv`.

    Each env's first episode counts; envs that finish early are reset by the vector env and
    ignored until the slowest one ends (at most ``task.episode_steps`` steps).

    Args:
        policy: batched observation Dict -> actions ``(episodes, n)``.
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration resolved with ``arm``.
        episodes: number of envs (= episodes).
        seed: seed of the batch's PRNG key.
        backend: "mjx" (MJX: slow on a CPU), "mujoco" (C MuJoCo) or "auto".
        impl: MJX implementation: "auto", "jax" or "warp".
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig;
            default: the shipped arm); None with an ArmTask.
    """
    from mjx_arm.envs.physics_config import PhysicsConfig
    from mjx_arm.envs.vector import ArmVectorEnv

    clock = _compile_clock(backend, episodes)  # its lines end once the first step ran
    try:
        env = ArmVectorEnv(task, episodes, backend, PhysicsConfig(impl=impl), arm)
        check_policy_arm(policy, env.env.arm)
        acc, rec = _run_first_episodes(policy, env, seed, clock)
    finally:
        clock.stop()
    env.close()
    return EvalRun(acc.episodes(), [rec.arrays()])


def _run_first_episodes(policy: Policy, env: Any, seed: int, clock: Any) -> tuple:
    """Step the vector ``env`` from a reset with ``seed`` until each env's first episode
    ended (``clock`` stopped after the first step); (their numbers, env 0's recording)."""
    obs, _ = env.reset(seed=seed)
    acc, rec = _BatchAccumulator(env.num_envs), _Recorder()
    while acc.active.any():
        actions = np.asarray(policy(obs), dtype=np.float32).reshape(env.action_space.shape)
        next_obs, rewards, terminated, truncated, info = env.step(actions)
        clock.stop()
        if acc.active[0]:
            final = info.get("final_obs", next_obs)
            _record_first(rec, obs, (actions, rewards, terminated), final, info)
        acc.add(rewards, terminated | truncated, info)
        obs = next_obs
    return acc, rec


def _compile_clock(backend: str, episodes: int):
    """The :class:`~mjx_arm.jax_cache.CompileClock` of a batch of ``episodes`` envs on
    ``backend``; on a CPU, MJX's says it takes minutes and what is faster."""
    import jax

    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.jax_cache import CompileClock

    name = resolve_backend(backend)
    slow = name == "mjx" and jax.default_backend() == "cpu"
    hint = "MJX on a CPU: a few minutes; --backend mujoco compiles in seconds" if slow else ""
    return CompileClock(f"the batched env ({episodes} envs, backend {name})", hint)


def _record_first(
    rec: _Recorder, obs: dict, step: tuple[np.ndarray, ...], final: dict, info: dict
) -> None:
    """Record env 0's transition of a batched step: its observation (``obs``: Dict of
    ``(episodes, ...)``), the step's ``(actions (episodes, n), rewards (episodes,),
    terminated (episodes,))``, the ``final`` observation's ee pose and the info it reports."""
    actions, rewards, terminated = step
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
