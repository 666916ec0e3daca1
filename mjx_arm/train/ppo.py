"""Brax PPO on the batched arm env, with a run directory, checkpoints and resume.

``train(config, run_dir)`` is what ``mjx-arm train`` calls. Brax's PPO does the learning, on one
device or several (:mod:`mjx_arm.train.loop`, :mod:`mjx_arm.train.learner`); this module builds
the env, wires the callbacks to the run directory (metrics, checkpoints, transitions, progress
bar) and restores a run. Checkpoints hold params only (normaliser, policy, value), in Brax's
format: on resume the optimiser's moment estimates start from zero again (google/brax#655), and
a run resumes on any number of devices.
"""

from __future__ import annotations

import functools
import itertools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from mjx_arm.envs.backend import make_batched_env, resolve_backend
from mjx_arm.envs.mjx_physics import PhysicsOverflowError, overflow_message
from mjx_arm.task.config import TaskConfig, task_config
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.learner import local_devices
from mjx_arm.train.loop import Callbacks, resolve_partition, run_ppo
from mjx_arm.train.rundir import RunDir

TRANSITIONS_KEPT = 100
LOGGED_PREFIXES = ("eval/", "training/")


@dataclass
class TrainResult:
    """What a finished run returns: its folder, final step, last metrics and timings (s)."""

    run_dir: Path
    steps: int
    metrics: dict[str, float]
    compile_seconds: float
    train_seconds: float
    steps_per_second: float


def full_config(
    config: TrainConfig, task: TaskConfig, physics: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Every resolved setting of a run, as saved in ``config.json``.

    ``physics``: what the env's physics reports of itself (implementation, buffer sizes).
    """
    from mjx_arm import __version__
    from mjx_arm.envs.model_io import task_convert_config

    conversion = task_convert_config(task)
    return {
        "mjx_arm_version": __version__,
        "train": config.to_dict(),
        "task": task.to_dict(),
        "convert": {k: v for k, v in vars(conversion).items() if k != "package_dirs"},
        "backend": resolve_backend(config.backend),
        "physics_resolved": physics or {},
        "jax_backend": jax.default_backend(),
        "devices": [str(d) for d in local_devices(config.devices)],
        "partition": resolve_partition(config, (physics or {}).get("impl", "")),
    }


class Solved(Exception):
    """An evaluation reached ``stop_at_success``: training stops early."""


class _Progress:
    """Run callbacks: metrics to the run dir, a progress bar, checkpoints at an interval.

    Steps are the run's global env steps. Each evaluation's metrics row is written before the
    checkpoint of the same step, so a run killed between the two loses no row: it resumes from
    the checkpoint before and drops the rows after it (:meth:`RunDir.truncate_metrics`).
    """

    def __init__(
        self, run: RunDir, config: TrainConfig, task: TaskConfig, step_offset: int, quiet: bool
    ) -> None:
        from tqdm import tqdm

        self.run, self.config, self.task = run, config, task
        self.physics: dict[str, Any] = {}
        self.total = config.num_timesteps
        self.bar = tqdm(
            total=self.total,
            initial=step_offset,
            unit="step",
            unit_scale=True,
            disable=quiet,
            desc=f"train {config.task}",
            dynamic_ncols=True,
        )
        self.evals = 0
        self.latest: tuple | None = None
        # (success, step, params on the host) of the best evaluation after training started
        self.best: tuple[float, int, Any] | None = None
        self.times: list[tuple[float, int]] = []
        self.last_metrics: dict[str, float] = {}

    def policy_params(self, step: int, make_policy, params) -> None:
        """Keep the newest params (saved by :meth:`progress` when a checkpoint is due)."""
        self.latest = (make_policy, params)

    def progress(self, step: int, metrics: dict[str, Any]) -> None:
        """Log one evaluation; save a checkpoint every ``checkpoint_every`` and at the end."""
        self.times.append((time.monotonic(), int(step)))
        row = {
            k: float(np.asarray(v).mean())
            for k, v in metrics.items()
            if k.startswith(LOGGED_PREFIXES)
        }
        self.last_metrics = row
        self.run.log_metrics(step, row)
        self._show(step, row)
        overflow = row.get("eval/episode_physics_overflow", 0.0)
        if overflow > 0:
            raise PhysicsOverflowError(overflow_message(overflow, self.physics))
        goal = self.config.stop_at_success
        solved = goal > 0 and row.get("eval/episode_success", 0.0) >= goal
        if not any("training/" in k for k in row):  # the evaluation before training
            return
        self.evals += 1
        success = row.get("eval/episode_success", 0.0)
        self._remember_best(step, success)
        due = self.evals % self.config.checkpoint_every == 0
        if (due or solved or step >= self.total) and self.latest is not None:
            make_policy, params = self.latest
            meta: dict[str, Any] = {}
            if step >= self.total and not solved and self._best_is_better(success):
                best_success, best_step, params = self.best
                meta = {"params_step": best_step, "params_success": best_success}
                self.bar.write(
                    f"the final checkpoint keeps the params of step {best_step} "
                    f"(evaluation success {best_success:.3f}, last {success:.3f})"
                )
            self._save(step, make_policy, params, meta)
        if solved:
            raise Solved(step)

    def _remember_best(self, step: int, success: float) -> None:
        """Keep a host copy of the params of the best evaluation so far (ties: the later)."""
        if not self.config.keep_best or self.latest is None:
            return
        if self.best is None or success >= self.best[0]:
            self.best = (success, step, jax.tree.map(np.asarray, self.latest[1]))

    def _best_is_better(self, success: float) -> bool:
        return self.config.keep_best and self.best is not None and self.best[0] > success

    def _show(self, step: int, row: dict[str, float]) -> None:
        self.bar.n = step
        self.bar.set_postfix(
            reward=f"{row.get('eval/episode_reward', float('nan')):.1f}",
            success=f"{row.get('eval/episode_success', float('nan')):.2f}",
        )
        self.bar.refresh()

    def _save(self, step: int, make_policy, params, meta: dict[str, Any] | None = None) -> None:
        params = jax.tree.map(np.asarray, params)
        transitions = rollout_transitions(make_policy, params, self.task, seed=step)
        meta = {"task": self.config.task, **(meta or {})}
        self.run.save_checkpoint(step, params, meta, transitions)

    def close(self) -> None:
        self.bar.close()


def rollout_transitions(make_policy, params, task: TaskConfig, seed: int) -> dict[str, np.ndarray]:
    """One evaluation episode in the CPU MuJoCo env; the last 100 transitions as arrays.

    Returns:
        obs ``(T, 22)``, action ``(T, 6)``, reward ``(T,)``, done ``(T,)``, ee_pos ``(T, 3)``,
        contact_force ``(T,)`` with T <= 100.
    """
    from mjx_arm.envs.mujoco_env import MujocoArmEnv
    from mjx_arm.task.observation import flatten_obs

    policy = jax.jit(make_policy(params, deterministic=True))
    env = MujocoArmEnv(task)
    obs, _ = env.reset(seed=int(seed) % (2**31))
    key = jax.random.PRNGKey(0)
    rows: dict[str, list] = {
        k: [] for k in ("obs", "action", "reward", "done", "ee_pos", "contact_force")
    }
    for _ in range(task.episode_steps):
        flat = flatten_obs(np, obs)
        action = np.asarray(policy(flat, key)[0], dtype=np.float32)
        obs, reward, terminated, _, info = env.step(action)
        for name, value in (
            ("obs", flat),
            ("action", action),
            ("reward", reward),
            ("done", terminated),
            ("ee_pos", obs["ee_pose"][:3]),
            ("contact_force", info["contact_force_norm"]),
        ):
            rows[name].append(value)
        if terminated:
            break
    env.close()
    return {k: np.asarray(v[-TRANSITIONS_KEPT:]) for k, v in rows.items()}


def train(
    config: TrainConfig, run_dir: str | Path, resume: bool = False, quiet: bool = False
) -> TrainResult:
    """Train a PPO policy and fill ``run_dir``.

    Args:
        config: the resolved training config.
        run_dir: the run directory (created if missing).
        resume: continue from the newest checkpoint in ``run_dir`` (on any device count).
        quiet: no progress bar.
    """
    config.validate()
    task = task_config(config.task, **config.task_overrides)
    run = RunDir(run_dir)
    step_offset, restore = 0, None
    if resume:
        latest = run.latest_checkpoint()
        if latest is None:
            raise FileNotFoundError(f"no checkpoint to resume from in {run.path}")
        step_offset = int(RunDir.load_meta(latest)["step"])
        restore = restore_brax_params(RunDir.load_params(latest))
    if step_offset >= config.num_timesteps:
        raise ValueError(f"run already has {step_offset} of {config.num_timesteps} steps")
    run.check_writable()  # before any compilation
    run.truncate_metrics(step_offset)  # rows a killed run wrote after its last checkpoint

    env, eval_env = make_envs(config, task)
    progress = _Progress(run, config, task, step_offset, quiet)
    progress.physics = env.physics.describe()
    if not resume:
        run.save_config(full_config(config, task, env.physics.describe()))
    start = time.monotonic()
    progress.times.append((start, step_offset))
    try:
        run_ppo(
            config,
            env,
            eval_env,
            task.episode_steps,
            Callbacks(progress.progress, progress.policy_params),
            restore=restore,
            step_offset=step_offset,
        )
    except Solved:
        pass
    finally:
        progress.close()
        run.close()
    total = time.monotonic() - start
    compile_s, sps = _timings(progress.times, config)
    steps = progress.times[-1][1]  # rounded up to whole epochs
    return TrainResult(run.path, steps, progress.last_metrics, compile_s, total, sps)


def make_envs(config: TrainConfig, task: TaskConfig) -> tuple[Any, Any]:
    """The training env (randomised as configured) and the evaluation env (nominal).

    Warp's contact pool is sized for the larger of the training and evaluation batches.
    """
    batch = max(config.num_envs, config.num_eval_envs)
    train_env = make_batched_env(task, config.backend, config.physics, batch, config.randomization)
    if not config.randomization.enabled:
        return train_env, train_env
    eval_env = make_batched_env(task, config.backend, config.physics, config.num_eval_envs)
    return train_env, eval_env


def restore_brax_params(raw: Any) -> tuple:
    """Brax's (normalizer, policy, value) from a checkpoint read back without a target.

    orbax returns plain dicts; Brax needs its running-statistics dataclass (with the UInt64
    sample count) for the normaliser. Policy and value params are plain dicts already.
    """
    from brax.training import types as brax_types
    from brax.training.acme import running_statistics

    norm, policy, value = raw
    count = norm["count"]
    if isinstance(count, dict):
        count = brax_types.UInt64(hi=jnp.asarray(count["hi"]), lo=jnp.asarray(count["lo"]))
    state = running_statistics.RunningStatisticsState(
        mean=jnp.asarray(norm["mean"]),
        std=jnp.asarray(norm["std"]),
        count=count,
        summed_variance=jnp.asarray(norm["summed_variance"]),
        std_eps=float(np.asarray(norm.get("std_eps", 0.0))),
    )
    to_jax = functools.partial(jax.tree.map, jnp.asarray)
    return state, to_jax(policy), to_jax(value)


def _timings(times: list[tuple[float, int]], config: TrainConfig) -> tuple[float, float]:
    """(compile seconds, steady env steps/s) from ``(time, step)`` marks.

    The marks are the start, then every evaluation. The first trained epoch carries the
    compilation (of the training epoch and of the evaluation); later epochs are steady. Compile
    time is the time from the start to the end of the first trained epoch less what its steps
    take at the steady rate (evaluations included).
    """
    first = next((i for i, (_, s) in enumerate(times) if s > times[0][1]), None)
    if first is None or len(times) < first + 2:
        return float("nan"), float("nan")
    steady = [
        (b[1] - a[1]) / (b[0] - a[0]) for a, b in itertools.pairwise(times[first:]) if b[0] > a[0]
    ]
    sps = float(np.median(steady))
    (t0, s0), (t1, s1) = times[0], times[first]
    return max((t1 - t0) - (s1 - s0) / sps, 0.0), sps
