"""Brax PPO on the batched arm env, with a run directory, checkpoints and resume.

``train(config, run_dir)`` is what ``mjx-arm train`` calls. Brax's PPO does the learning, on one
device or several (:mod:`mjx_arm.train.loop`, :mod:`mjx_arm.train.learner`); this module builds
the env, wires the callbacks (:mod:`mjx_arm.train.progress`: metrics, checkpoints, transitions,
progress bar) to the run directory and restores a run. Checkpoints hold the params in Brax's
format and, beside them, the optimiser state, the PRNG keys and the envs' state
(:mod:`mjx_arm.train.resume`): a resumed run goes on as the run it continues, on any number of
devices. Where several processes train (:mod:`mjx_arm.train.distributed`), process 0 holds the
run directory; the others read a checkpoint to resume from and write nothing.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import numpy as np

from mjx_arm.arm.resolve import ArmTask, resolve_task
from mjx_arm.engines import CONVERTER_ENGINE
from mjx_arm.envs.backend import make_batched_env, resolve_backend
from mjx_arm.inputs import ConfigError, MissingInputError
from mjx_arm.task.config import TaskConfig
from mjx_arm.train import warm
from mjx_arm.train.checkpoints import (
    CheckpointError,
    latest_checkpoint,
    restore_brax_params,
    unusable_reason,
)
from mjx_arm.train.compile_report import CompileReport, mark
from mjx_arm.train.config import TrainConfig
from mjx_arm.train.distributed import barrier, is_leader
from mjx_arm.train.launch import devices_for_physics
from mjx_arm.train.learner import train_devices
from mjx_arm.train.loop import Callbacks, resolve_partition, run_ppo
from mjx_arm.train.memory import check_training_memory
from mjx_arm.train.progress import Solved, Stopped, _Progress
from mjx_arm.train.resume import has_resume_state, newest_whole_state
from mjx_arm.train.rundir import RunDir, RunDirError, claim


@dataclass
class TrainResult:
    """What a finished run returns: its folder, final step, last metrics and timings (s)."""

    run_dir: Path
    steps: int
    metrics: dict[str, float]
    compile_seconds: float
    train_seconds: float
    steps_per_second: float
    compile_report: dict[str, Any] = field(default_factory=dict)
    compile_summary: str = ""
    best: tuple[float, int] | None = None  # (success, step) of the best evaluation


def full_config(
    config: TrainConfig, task: TaskConfig, physics: dict[str, Any] | None = None, arm=None
) -> dict[str, Any]:
    """Every resolved setting of a run, as saved in ``config.json``.

    Args:
        config: the training config.
        task: the task config as the env resolved it (the arm's home pose and reach scale
            filled in).
        physics: what the env's physics reports of itself (implementation, buffer sizes).
        arm: the env's :class:`~mjx_arm.arm.info.ArmInfo` (default: the config's arm).
    """
    from mjx_arm import __version__
    from mjx_arm.arm.info import arm_info, arm_record
    from mjx_arm.arm.model_io import task_convert_config

    arm = arm or arm_info(config.arm)
    conversion = task_convert_config(task, arm)
    return {
        "mjx_arm_version": __version__,
        "train": config.to_dict(),
        "task": task.to_dict(),
        "arm": arm_record(arm),
        "convert": {
            **{k: v for k, v in vars(conversion).items() if k not in ("package_dirs", "pads")},
            "scene": conversion.scene.name,
            "pads": sorted(conversion.pads.replaced) if conversion.pads else [],  # fitted
        },
        "backend": resolve_backend(config.backend),
        "physics_resolved": physics or {},
        "jax_backend": jax.default_backend(),
        "devices": [str(d) for d in train_devices(config.devices)],
        "processes": jax.process_count(),
        "partition": resolve_partition(config, (physics or {}).get("impl", "")),
    }


def train(
    config: TrainConfig,
    run_dir: str | Path,
    resume: bool = False,
    quiet: bool = False,
    stop_after: int = 0,
) -> TrainResult:
    """Train a PPO policy and fill ``run_dir``.

    Every input is checked before any compilation: the config, the devices, the run directory
    (writable, not in use by another training, no earlier run to overwrite) and, to resume,
    its newest usable checkpoint.

    Args:
        config: the resolved training config.
        run_dir: the run directory (a new run's: new, empty or a run's, rundir.claim).
        resume: continue from the newest checkpoint in ``run_dir`` (on any device count).
        quiet: no progress bar.
        stop_after: stop after this many trained epochs (0: train the whole run); the
            programs are those of the whole run, so a short run fills the compilation caches
            for it (``mjx-arm warmup``, the cold-start benchmark).

    Raises:
        InputError: a bad config, a run directory that cannot take the run, or (to resume) one
            without a usable checkpoint.
    """
    config = _checked(config)
    mark("devices started")
    setup = resolve_run_task(config)
    mark("arm and task resolved")
    if resume:
        _check_run_dir(run_dir)
    if not is_leader():  # process 0 holds the run directory; the others only read it
        barrier("run directory ready")
        step_offset, restore = _start_point(None, config, resume, Path(run_dir))
        return _train(None, config, setup, step_offset, restore, True, stop_after)
    run = RunDir(run_dir if resume else claim(run_dir))  # a new run: never a user's folder
    run.check_writable()  # before the lock file and any compilation (a full disk)
    with run.lock():
        step_offset, restore = _start_point(run, config, resume)
        run.truncate_metrics(step_offset)  # rows a killed run wrote after its last checkpoint
        barrier("run directory ready")
        return _train(run, config, setup, step_offset, restore, quiet, stop_after)


def _checked(config: TrainConfig) -> TrainConfig:
    """``config`` validated, on the physics and devices it can train on here; a deterministic
    run's switches set before any device is touched (:mod:`mjx_arm.train.determinism`)."""
    config.validate()
    if config.deterministic:
        from mjx_arm.train.determinism import deterministic_physics, enable

        config = deterministic_physics(config)
        enable()
    config = devices_for_physics(config)
    config.check_devices(len(train_devices(config.devices)))
    return config


def _check_run_dir(run_dir: str | Path) -> None:
    """Check that ``run_dir`` is a run directory to resume (it holds a ``config.json``)."""
    config = Path(run_dir) / "config.json"
    if not (config.exists() or config.is_symlink()):  # anything else there is read, and named
        raise MissingInputError(
            f"cannot resume {run_dir}: no checkpoint, it is not a run directory (no "
            "config.json); give the RUN_DIR of an earlier mjx-arm train"
        )


def resolve_run_task(config: TrainConfig) -> ArmTask:
    """The run's task on its arm, resolved once before any env is built
    (:func:`~mjx_arm.arm.resolve.resolve_task`): the arm validated, the task checked to fit
    it (a gripper task needs a gripper, a home pose needs one angle per joint) and filled in.

    Raises:
        InputError: an arm that does not validate or resolve, or a task that does not fit it.
    """
    return resolve_task(config.task_config(), config.arm, CONVERTER_ENGINE)


def _start_point(
    run: RunDir | None, config: TrainConfig, resume: bool, path: Path | None = None
) -> tuple[int, Any]:
    """(step to start from, what to restore: the checkpoint folder, its params, or None).

    A checkpoint with the training state is returned as its folder (read once the run's
    structure is known, :func:`_restore_state`); an older one as its params, with a warning.
    ``run`` None: a process other than process 0, which reads ``path`` without changing it.

    Raises:
        InputError: a new run on a folder that holds one, or a resume without a usable
            checkpoint or with nothing left to train.
    """
    if run is None and not resume:
        return 0, None
    folder = path if run is None else run.path
    latest = latest_checkpoint(folder / "checkpoints")  # process 0 restored any .old- first
    if not resume:
        if latest is not None:
            raise RunDirError(
                f"{run.path} already holds a run (checkpoint {latest.name}); resume it with "
                "--resume, or choose another --run-dir"
            )
        return 0, None
    if latest is None:
        why = unusable_reason(folder / "checkpoints")
        raise CheckpointError(f"no checkpoint to resume from in {folder}{why}")
    step_offset = int(RunDir.load_meta(latest)["step"])
    if step_offset >= config.num_timesteps:
        raise ConfigError(
            f"nothing to resume: {latest.parent.parent} already has {step_offset} of its "
            f"{config.num_timesteps} steps"
        )
    if has_resume_state(latest):
        whole = newest_whole_state(latest.parent)
        if whole is not None and whole != latest:  # exact: go back to the envs' last state
            return int(RunDir.load_meta(whole)["step"]), whole
        return step_offset, latest
    return step_offset, _params_only(latest)


def _params_only(latest: Path) -> Any:
    """The Brax PPO params of checkpoint ``latest``, one of an older version that holds no
    training state; a warning that the run resumes without its optimiser, keys and envs."""
    raw = RunDir.load_params(latest)
    try:
        params = restore_brax_params(raw)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise CheckpointError(f"checkpoint {latest} holds no Brax PPO params ({err})") from err
    if is_leader():  # once the params are read: a damaged checkpoint is an error, not this
        warnings.warn(
            f"{latest.name} holds params only (a checkpoint of an older version): the run "
            "resumes with fresh optimiser moments, new keys and reset envs",
            stacklevel=3,
        )
    return params


def _train(
    run: RunDir | None,
    config: TrainConfig,
    setup: ArmTask,
    step_offset: int,
    restore: Any,
    quiet: bool,
    stop_after: int = 0,
) -> TrainResult:
    """Build the envs of ``setup`` and run PPO from ``step_offset`` (the checks are done)."""
    report = CompileReport().open()
    start = time.monotonic()
    task = setup.task  # with the arm's home pose, reach scale and episode length
    try:  # a run that fails (a checkpoint that does not fit) leaves nothing open
        env, eval_env, restore = _envs_and_restore(run, config, setup, restore, report)
        progress = _Progress(run, config, setup, step_offset, quiet, stop_after)
        progress.physics = env.physics.describe()
        progress.watch_compile(report)
        if not quiet:
            progress.start_up_summary = report.summary
        progress.times.append((start, step_offset))
        callbacks = Callbacks(progress.progress, progress.policy_params, progress.snapshot)
        try:
            with contextlib.suppress(Solved, Stopped):  # a run solved or stopped early
                run_ppo(
                    config, env, eval_env, task.episode_steps, callbacks, restore, step_offset,
                    report,
                )  # fmt: skip
            progress.finish()  # the last checkpoint on disk (a failed save raises here)
        finally:
            progress.close()
    finally:
        report.close()
        if run is not None:
            run.close()
    return _result(run, config, progress, report, start)


def _result(
    run: RunDir | None,
    config: TrainConfig,
    progress: _Progress,
    report: CompileReport,
    start: float,
) -> TrainResult:
    """The finished run's result: its steps, last metrics and timings since ``start``; the
    compile report saved in the run directory."""
    total = time.monotonic() - start
    _, sps = _timings(progress.times, config)
    compile_s = report.compile_seconds  # the one compile figure (compile_report)
    steps = progress.times[-1][1]  # rounded up to whole epochs
    record = report.to_dict()
    if run is not None:
        run.save_compile_report(record)
    return TrainResult(
        Path(run.path if run is not None else "."),
        steps,
        progress.last_metrics,
        compile_s,
        total,
        sps,
        record,
        report.summary(),
        progress.best[:2] if progress.best is not None else None,
    )


def _envs_and_restore(
    run: RunDir | None, config: TrainConfig, setup: ArmTask, restore: Any, report: CompileReport
) -> tuple[Any, Any, Any]:
    """The training and evaluation envs (their build timed into ``report``) and what to
    restore (a checkpoint folder read: :func:`_restore_state`); a new run's config saved."""
    with report.stage("build env"):
        build = functools.partial(make_envs, config, setup, background_compile=True)
        env, eval_env, kept = warm.envs(config, setup, build)
    check_training_memory(config, env)  # before the config is saved and anything allocated
    if kept:
        report.kept.append("envs")
    for name, seconds in ({} if kept else env.build_seconds).items():
        report.add(f"of it {name}", seconds)
    if restore is None and run is not None:
        run.save_config(full_config(config, setup.task, env.physics.describe(), setup.arm))
    if isinstance(restore, Path):
        restore = _restore_state(restore, config, env)
    return env, eval_env, restore


def _restore_state(folder: Path, config: TrainConfig, env: Any):
    """The :class:`~mjx_arm.train.resume.ResumeState` of a checkpoint, read into the
    structure of this config's fresh state (shapes only: nothing is compiled or run)."""
    from mjx_arm.envs.wrappers import wrap_for_training
    from mjx_arm.train.learner import Learner, make_mesh
    from mjx_arm.train.resume import env_leaf_paths, load_resume_state, select_leaves

    mesh = make_mesh(train_devices(config.devices))
    learner = Learner(config, env.observation_size, env.action_size, mesh, env.contact_force_dims)
    key = jax.random.PRNGKey(0)
    template = jax.eval_shape(learner._fresh_state, key, key)
    wrapped = wrap_for_training(env, config.task_config().episode_steps)
    keys = jax.ShapeDtypeStruct((config.num_envs, *key.shape), key.dtype)
    env_shape = jax.eval_shape(wrapped.reset, keys)
    paths = env_leaf_paths(env_shape, config.num_envs, env.physics.splits)
    return load_resume_state(folder, template, np.asarray(key), select_leaves(env_shape, paths))


def make_envs(
    config: TrainConfig, setup: ArmTask, background_compile: bool = False
) -> tuple[Any, Any]:
    """The training env (randomised as configured) and the evaluation env (nominal), both of
    the run's resolved task and arm ``setup`` (:func:`resolve_run_task`).

    Warp's contact pool is sized for the larger of the training and evaluation batches. With
    ``background_compile``, MuJoCo Warp's kernels compile on a background thread: wait with
    ``env.physics.wait_precompiled()`` before the first step runs.
    """
    batch = max(config.num_envs, config.num_eval_envs)
    train_env = make_batched_env(
        setup,
        config.backend,
        config.physics,
        batch,
        config.randomization,
        background_compile=background_compile,
    )
    if not config.randomization.enabled:
        return train_env, train_env
    eval_env = make_batched_env(setup, config.backend, config.physics, config.num_eval_envs)
    return train_env, eval_env


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
