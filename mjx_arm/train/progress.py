"""What a training run does at each evaluation: log the metrics, show the progress bar, write
checkpoints and transitions, keep the best evaluation, and stop once the run is solved.

Where several processes train, every process makes the same decisions (from the evaluation
figures process 0 shares) and takes part in gathering the env state for a checkpoint, but only
process 0 (``run`` given) writes.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from mjx_arm.arm.resolve import ArmTask
from mjx_arm.envs.mjx_physics import PhysicsOverflowError
from mjx_arm.envs.warp_buffers import overflow_message
from mjx_arm.task.config import TaskConfig
from mjx_arm.train.compile_report import CompileReport, expected_compile, remember_compile
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.divergence import rollout_guard
from mjx_arm.train.episode import CheckpointEpisode
from mjx_arm.train.learner import EpochSizes
from mjx_arm.train.resume import ENV_STATE_FILE, ResumeState, resume_arrays
from mjx_arm.train.rundir import RunDir
from mjx_arm.train.saver import CheckpointSaver, host_copy

LOGGED_PREFIXES = ("eval/", "training/")


class Solved(Exception):
    """An evaluation reached ``stop_at_success``: training stops early."""


class Stopped(Exception):
    """The run trained the epochs it was asked to stop after (``train(stop_after=N)``)."""


def planned_steps(config: TrainConfig, step_offset: int = 0) -> int:
    """The env step a run from ``step_offset`` ends on: ``num_timesteps`` rounded up to whole
    epochs (:class:`~mjx_arm.train.learner.EpochSizes`), as the training loop runs them."""
    epoch = EpochSizes.of(config, config.num_timesteps).env_steps_per_epoch
    return step_offset + math.ceil(max(config.num_timesteps - step_offset, 0) / epoch) * epoch


def compiling_text(elapsed: float, expected: float | None) -> str:
    """What the bar says while the run compiles: seconds so far, and the last run's figure."""
    last = f"; the last run of this setup compiled in {expected:.0f} s" if expected else ""
    return f"compiling {elapsed:.0f} s{last}"


class CompileClock:
    """Says on the progress bar that the run is compiling, once a second, until the first
    program runs (the report's ``first reset run`` stage) or :meth:`compiled`, then gives the
    bar its name back and redraws it every ``HEARTBEAT_S`` seconds until :meth:`stop`: the bar
    moves only at an evaluation, and an epoch on a CPU can run for minutes (its clock moves).

    Args:
        bar: the tqdm bar.
        desc: the bar's own description (``train reach``).
        report: the run's :class:`CompileReport`, read for the end of the compile.
        expected: the compile time of the last run of the same setup (s), or None.
    """

    DONE = "first reset run"  # the stage that follows every compile stage
    HEARTBEAT_S = 10.0  # after the compile: seconds between two redraws of the bar

    def __init__(self, bar: Any, desc: str, report: CompileReport, expected: float | None):
        self.bar, self.desc, self.report, self.expected = bar, desc, report, expected
        self.start = time.monotonic()
        self._stop, self._compiled = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._run, name="compile-clock", daemon=True)

    def text(self) -> str:
        """The bar's description now."""
        return f"{self.desc}: {compiling_text(time.monotonic() - self.start, self.expected)}"

    def begin(self) -> CompileClock:
        """Show the clock and update it every second; returns self."""
        self.bar.set_description_str(self.text())
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(1.0):
            if self.DONE in self.report.stages or self._compiled.is_set():
                break
            self.bar.set_description_str(self.text())
        self.bar.set_description_str(self.desc)
        while not self._stop.wait(self.HEARTBEAT_S):
            self.bar.refresh()

    def compiled(self) -> None:
        """The first epoch has run: the bar gets its name back, and its redraws go on."""
        self._compiled.set()

    def stop(self) -> None:
        """Stop updating (the bar's name is given back); waits for the clock's thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()


def compile_setup(config: TrainConfig) -> str:
    """The setup a compile time is remembered for: task, backend, env counts, arm, device."""
    import jax

    from mjx_arm.envs.backend import resolve_backend

    device = jax.devices()[0].device_kind
    arm = config.arm.urdf_path.name
    envs = f"{config.num_envs}/{config.num_eval_envs} envs"
    return f"{config.task} {resolve_backend(config.backend)} {envs} {arm} {device}"


class _Progress:
    """Run callbacks: metrics to the run dir, a progress bar, checkpoints at an interval.

    Steps are the run's global env steps. Each evaluation's metrics row is written before the
    checkpoint of the same step, so a run killed between the two loses no row: it resumes from
    the checkpoint before and drops the rows after it (:meth:`RunDir.truncate_metrics`).
    ``run`` None: a process other than process 0, which writes nothing and shows no bar.
    """

    def __init__(
        self,
        run: RunDir | None,
        config: TrainConfig,
        task: TaskConfig | ArmTask,
        step_offset: int,
        quiet: bool,
        stop_after: int = 0,
    ) -> None:
        from tqdm import tqdm

        self.run, self.config = run, config
        # the run's task on its arm, as the trainer resolved it (a task config alone: on
        # ``config.arm``, resolved where a snapshot's episode is rolled out)
        self.setup = task if isinstance(task, ArmTask) else None
        self.task = task.task if isinstance(task, ArmTask) else task
        self.physics: dict[str, Any] = {}
        self.total = config.num_timesteps  # the run ends on the first evaluation at or past it
        planned = planned_steps(config, step_offset)
        if stop_after:  # a run stopped after its first epochs (warmup's one): the bar ends there
            epoch = EpochSizes.of(config, config.num_timesteps).env_steps_per_epoch
            planned = min(planned, step_offset + stop_after * epoch)
        self.bar = tqdm(
            total=planned,
            initial=step_offset,
            unit="step",
            unit_scale=True,
            disable=quiet or run is None,
            desc=f"train {config.task}",
            dynamic_ncols=True,
        )
        self.evals = 0
        self.stop_after = stop_after
        self.start_up_summary: Any = None  # () -> the start-up line, shown after epoch one
        self.latest: tuple | None = None
        # (success, step, params on the host) of the best evaluation after training started
        self.best: tuple[float, int, Any] | None = None
        self.times: list[tuple[float, int]] = []
        self.last_metrics: dict[str, float] = {}
        # (with_envs) -> ResumeState of the newest epoch, a collective where several processes run
        self.take_snapshot: Any = None
        self.report: CompileReport | None = None
        self.clock: CompileClock | None = None
        self.episode: CheckpointEpisode | None = None  # records each checkpoint's episode
        self.saver = CheckpointSaver()  # writes checkpoints while the next epoch trains

    def watch_compile(self, report: CompileReport) -> None:
        """Show on the bar that the run compiles (seconds so far, the last run's compile time);
        remember this run's compile time once its first epoch has run."""
        self.report = report
        if not self.bar.disable:
            expected = expected_compile(compile_setup(self.config))
            self.clock = CompileClock(self.bar, self.bar.desc, report, expected).begin()

    def snapshot(self, step: int, take) -> None:
        """Keep the function that gathers the newest epoch's state (called at a checkpoint)."""
        self.take_snapshot = take

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
        if self.run is not None:
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
        if self.evals == 1:
            self._start_up_done()
        success = row.get("eval/episode_success", 0.0)
        if "eval/episode_success" in row:  # an epoch before eval_from_step has no evaluation
            self._remember_best(step, success)
        due = self.evals % self.config.checkpoint_every == 0
        if (due or solved or step >= self.total) and self.latest is not None:
            self._checkpoint(step, success, solved)
        if solved:
            raise Solved(step)
        if self.stop_after and self.evals >= self.stop_after:
            raise Stopped(step)

    def _checkpoint(self, step: int, success: float, solved: bool) -> None:
        """Save the checkpoint of ``step`` (the envs' state every ``env_state_every``; at the
        budget's end, the best evaluated params where they beat the last); the first one's
        seconds are a start-up stage."""
        take = self.take_snapshot
        resume = take(self.evals % self.config.env_state_every == 0) if take else None
        make_policy, params = self.latest
        meta: dict[str, Any] = {}
        if step >= self.total and not solved and self._best_is_better(success):
            best_success, best_step, params = self.best
            meta = {"params_step": best_step, "params_success": best_success}
            self.bar.write(
                f"the final checkpoint keeps the params of step {best_step} "
                f"(evaluation success {best_success:.3f}, last {success:.3f})"
            )
        if self.run is not None:
            saving = time.monotonic()
            self.saver.submit(self._save_job(step, make_policy, params, meta, resume))
            if solved or step >= self.total:
                self.saver.wait()  # the run's last checkpoint is on disk before it ends
            if self.evals == 1 and self.report is not None:
                self.report.add("first checkpoint", time.monotonic() - saving)

    def _start_up_done(self) -> None:
        """After the first epoch: the start-up line, and the compile time kept for next time."""
        if self.clock is not None:
            self.clock.compiled()
        if self.start_up_summary is not None:
            self.bar.write(self.start_up_summary())
        if self.report is not None and self.run is not None:
            remember_compile(compile_setup(self.config), self.report.compile_seconds)

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
        if "eval/episode_success" in row:  # else the last evaluation's figures stay
            self.bar.set_postfix(
                reward=f"{row.get('eval/episode_reward', float('nan')):.1f}",
                success=f"{row['eval/episode_success']:.2f}",
            )
        self.bar.refresh()

    def _save_job(
        self,
        step: int,
        make_policy,
        params,
        meta: dict[str, Any],
        resume: ResumeState | None = None,
    ) -> Callable[[], None]:
        """The save of the checkpoint of ``step``, for :attr:`saver`. The host copies of the
        params and state are made here, in the training thread (the next epoch reuses their
        GPU buffers); the job records the episode and writes the files."""
        params = host_copy(params)
        arrays = host_copy(resume_arrays(resume)) if resume is not None else None
        # the envs' state is kept in the newest checkpoint that has it, only
        envs = resume is not None and resume.env_leaves is not None
        newest_only = (ENV_STATE_FILE,) if envs else ()
        meta = {"task": self.config.task, **meta}
        episode = self._episode(make_policy)
        run, config = self.run, self.config

        def job() -> None:
            with rollout_guard(config, step):  # the recorded episode acts with the policy
                transitions = episode.record(params, seed=step)
            run.save_checkpoint(
                step, host_params(params), meta, transitions, arrays, newest_only=newest_only
            )

        return job

    def _episode(self, make_policy) -> CheckpointEpisode:
        """The recorder of every checkpoint's episode (the policy's network is the run's)."""
        if self.episode is None:
            if self.setup is not None:
                self.episode = CheckpointEpisode(make_policy, self.setup)
            else:
                self.episode = CheckpointEpisode(make_policy, self.task, self.config.arm)
        return self.episode

    def finish(self) -> None:
        """Wait for the pending checkpoint; raise its error, if its save failed."""
        self.saver.wait()

    def close(self) -> None:
        self.saver.close()
        if self.clock is not None:
            self.clock.stop()
        if self.episode is not None:
            self.episode.close()
        self.bar.close()


def host_params(params: Any) -> tuple:
    """(normaliser, policy, value) as nested dicts of numpy arrays, as a checkpoint stores
    them (Brax's ``UInt64`` sample count turns its halves back into JAX arrays, which orbax
    will not save where several processes train)."""
    from flax import serialization

    return tuple(jax.tree.map(np.asarray, serialization.to_state_dict(p)) for p in params)
