"""Seeds benchmark: a training claim over seeds, not one run.

``mjx-arm bench seeds --task touch --preset fast --seeds 0-9`` trains the preset once per seed
and reads each run's ``metrics.csv``. On a GPU host every seed trains in its own process on one
GPU, as many seeds at once as there are GPUs (``--devices``: how many to use), so a seed's
memory is given back when it ends and never starves the next; on a CPU the seeds train one
after another in this process (the compilation caches are warm after the first seed). It reports

- per seed: the evaluation success of the run's final policy (its last checkpoint: the best
  evaluation where the run ended on its budget, ``TrainConfig.keep_best``) and the best one,
  the env steps and wall time from that seed's start to the first evaluation at ``threshold``
  (or "not reached"), compile time and training steps/s;
- overall: the fraction of seeds that reached ``threshold``, and the median and interquartile
  range of the time to it, over every seed (a seed that never reached it counts as infinitely
  slow, so a median over a minority of solved seeds reads "not reached") and over the warm
  seeds (those started after a seed had ended and so had filled the caches).

It writes ``NAME.md`` and ``NAME.json`` (with the resolved config of every seed and the
machine); asked for, ``NAME.png`` (each seed's success against wall time and against env steps).
"""

from __future__ import annotations

import math
import re
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.bench.seed_servers import check_server_settings
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig, parse_seeds
from mjx_arm.bench.seeds_summary import seed_line, start_up_line
from mjx_arm.inputs import ConfigError
from mjx_arm.names import EXIT_STOPPED

SUCCESS_KEY = "eval/episode_success"

# Called with the seed runs finished so far and their saved configs (a partial report).
SeedsDone = Callable[[list[SeedRun], list[dict[str, Any]]], None]


def read_curve(run_dir: Path, start: float) -> list[tuple[float, int, float]]:
    """``(seconds since start, step, success)`` of each evaluation in a run's metrics.csv (a
    row without one, an epoch before ``eval_from_step``, is left out)."""
    from mjx_arm.train.rundir import RunDir

    rows = RunDir(run_dir).read_metrics()
    rows = [r for r in rows if math.isfinite(r.get(SUCCESS_KEY, math.nan))]
    return [(r["time"] - start, int(r["step"]), r[SUCCESS_KEY]) for r in rows]


def final_policy_success(run_dir: Path, curve: list[tuple[float, int, float]]) -> float:
    """Evaluation success of the params in the run's last checkpoint: the last evaluation's,
    or the best one's where the run kept it (``TrainConfig.keep_best``)."""
    from mjx_arm.train.rundir import RunDir

    latest = RunDir(run_dir).latest_checkpoint()
    meta = RunDir.load_meta(latest) if latest is not None else {}
    if "params_success" in meta:
        return float(meta["params_success"])
    return curve[-1][2] if curve else math.nan


def first_at(curve: list[tuple[float, int, float]], threshold: float) -> tuple[float, int] | None:
    """(seconds, step) of the first evaluation at ``threshold`` or more, or None."""
    return next(((t, s) for t, s, v in curve if v >= threshold), None)


def train_seed(
    config: SeedsConfig, seed: int, out: Path, overrides: tuple[str, ...] = (), start=None
) -> tuple[SeedRun, dict[str, Any]]:
    """Train ``config.preset`` on ``config.task`` with ``seed``; its result and full config.

    Args:
        config: the benchmark settings.
        seed: the PRNG seed of the run.
        out: folder of the run directories.
        overrides: ``key=value`` changes to the preset (exploration; empty: as shipped).
        start: ``time.time()`` the seed's times count from (default: now).
    """
    from mjx_arm.arm.config import load_arm
    from mjx_arm.train.ppo import train
    from mjx_arm.train.presets import load_config
    from mjx_arm.train.rundir import RunDir

    items = [f"task={config.task}", f"backend={config.backend}", *overrides, f"seed={seed}"]
    if config.devices:
        items.append(f"devices={config.devices}")
    if config.deterministic:
        items.append("deterministic=true")
    train_config = load_config(config.preset, None, items)
    if config.arm:
        train_config = train_config.replace(arm=load_arm(config.arm))
    run_dir = seed_run_dir(config, seed, out)
    start = time.time() if start is None else start
    result = train(train_config, run_dir, quiet=True)
    wall = time.time() - start
    curve = read_curve(run_dir, start)
    hit = first_at(curve, config.threshold)
    run = SeedRun(
        seed=seed,
        final_success=final_policy_success(run_dir, curve),
        best_success=max((v for _, _, v in curve), default=math.nan),
        steps_to_threshold=hit[1] if hit else None,
        time_to_threshold=hit[0] if hit else None,
        total_steps=result.steps,
        wall_s=wall,
        compile_s=result.compile_seconds,
        training_steps_per_s=result.steps_per_second,
        curve=curve,
        compile_report=with_time_before_training(result.compile_report, start),
    )
    return run, RunDir(run_dir).load_config()


def with_time_before_training(report: dict[str, Any], start: float) -> dict[str, Any]:
    """A seed's compile report with a first stage, ``before training``: the seconds from
    ``start`` (``time.time()`` the seed's times count from) to the trainer's start (its
    report's ``opened_at``): a process's imports and CUDA's start, for a seed trained in a
    process of its own; then, where the report has ``marks``, the seconds from each start-up
    step to the next ("of it trainer imported": from the step before to the trainer's
    imports). A report without ``opened_at`` is returned as it is."""
    if "opened_at" not in report:
        return report
    before = {"before training": round(report["opened_at"] - start, 3)}
    last = start
    for name, at in sorted(report.get("marks", {}).items(), key=lambda kv: kv[1]):
        if at < start:  # the process's own start, before this seed (seeds trained in turn)
            continue
        before[f"of it {name}"] = round(at - last, 3)
        last = at
    if len(before) > 1:
        before["of it up to the trainer's report"] = round(report["opened_at"] - last, 3)
    return {**report, "stages": {**before, **report.get("stages", {})}}


def seed_run_dir(config: SeedsConfig, seed: int, out: Path) -> Path:
    """The run directory of ``seed`` under ``out``."""
    arm_tag = f"{Path(config.arm).stem}-" if config.arm else ""
    return out / f"{arm_tag}{config.task}-{config.preset}-seed{seed}"


def seed_command(
    config: SeedsConfig, seed: int, run_dir: Path, overrides: tuple[str, ...] = ()
) -> list[str]:
    """The ``mjx-arm train`` command line that trains ``seed`` in a process of its own."""
    command = [sys.executable, "-m", "mjx_arm.cli", "train", "--task", config.task]
    devices = str(config.gpus_per_seed)
    command += ["--preset", config.preset, "--backend", config.backend, "--devices", devices]
    command += ["--set", *overrides, f"seed={seed}", "--run-dir", str(run_dir), "--quiet"]
    command += ["--deterministic"] if config.deterministic else []
    return command + (["--arm", config.arm] if config.arm else [])


def read_seed_run(
    config: SeedsConfig, seed: int, run_dir: Path, start: float, end: float
) -> SeedRun:
    """A seed's result from its run directory (trained by another process), times from
    ``start``."""
    from mjx_arm.train.rundir import RunDir

    curve = read_curve(run_dir, start) if (run_dir / "metrics.csv").is_file() else []
    hit = first_at(curve, config.threshold)
    starts = RunDir(run_dir).compile_reports()
    report = with_time_before_training(starts[-1] if starts else {}, start)
    speeds = [r.get("training/sps", math.nan) for r in RunDir(run_dir).read_metrics()]
    speeds = [v for v in speeds if math.isfinite(v)]
    return SeedRun(
        seed=seed,
        final_success=final_policy_success(run_dir, curve),
        best_success=max((v for _, _, v in curve), default=math.nan),
        steps_to_threshold=hit[1] if hit else None,
        time_to_threshold=hit[0] if hit else None,
        total_steps=curve[-1][1] if curve else 0,
        wall_s=end - start,
        compile_s=float(report.get("compile_s", math.nan)),
        training_steps_per_s=float(np.median(speeds)) if speeds else math.nan,
        curve=curve,
        compile_report=report,
    )


_RAISED = re.compile(r"^(?:[A-Za-z_][\w.]*\.)?\w*(?:Error|Exception|Interrupt)\b.*$", re.M)


def log_error(log: str, chars: int = 400) -> str:
    """What a failed seed's log says went wrong: its last line naming an exception
    (``jax.errors.JaxRuntimeError: ...``, ``RuntimeError: ...``), else its last three lines,
    at most ``chars`` characters. The last three lines alone were a traceback's code line for
    a GPU out of memory."""
    raised = _RAISED.findall(log)
    text = raised[-1].strip() if raised else " | ".join(log.splitlines()[-3:])
    return text if len(text) <= chars else text[: chars - 3] + "..."


# Exit codes of a seed's process that a SIGTERM ended: killed by it, or the trainer's own exit
# on it. A deadline's ``timeout`` signals its whole process group, the seeds' processes with
# the benchmark, so such a seed was stopped from outside: it is left out of the report like a
# seed never started, not counted as a seed that failed to learn.
STOPPED_EXIT_CODES = (-int(signal.SIGTERM), EXIT_STOPPED)


def failed_seed(seed: int, gpu: str, wall: float, error: str) -> SeedRun:
    """The result of a seed whose process failed: not solved, the error kept."""
    nan = math.nan
    return SeedRun(seed, nan, nan, None, None, 0, wall, nan, nan, [], {}, gpu, error)


def stopped_from_outside(run: SeedRun) -> bool:
    """Whether ``run`` is a seed whose process a SIGTERM ended (:data:`STOPPED_EXIT_CODES`,
    read from the error :func:`failed_seed` keeps, so reports written before the rule too)."""
    return any(run.error.startswith(f"exit code {code}:") for code in STOPPED_EXIT_CODES)


def check_seed_settings(
    config: SeedsConfig, overrides: tuple[str, ...] = (), devices: int | None = None
) -> None:
    """Check everything the seeds' trainings take before the first starts: the preset with
    the task, backend and ``overrides`` (:func:`~mjx_arm.train.presets.load_config`), the
    device count of each seed's run (``devices``; default: ``config.devices`` local devices)
    and the arm; with ``--server``, the settings a warm trainer takes.

    Raises:
        InputError: a bad override, an arm that does not validate, a bad device count, a
            training that stops under ``config.threshold`` (no seed could count as solved), or
            ``--server`` with settings it cannot take (:func:`check_server_settings`).
    """
    check_server_settings(config)
    from mjx_arm.arm.info import validated_arm_info
    from mjx_arm.arm.resolve import default_arm
    from mjx_arm.engines import CONVERTER_ENGINE
    from mjx_arm.train.learner import local_devices
    from mjx_arm.train.presets import load_config

    items = [f"task={config.task}", f"backend={config.backend}", *overrides]
    train_config = load_config(config.preset, None, items)
    _check_stop(train_config.stop_at_success, config.threshold)
    count = devices if devices is not None else len(local_devices(config.devices))
    train_config.scaled_for_devices(count).check_devices(count)
    arm = config.arm or train_config.arm
    validated_arm_info(default_arm(train_config.task_config(), arm), CONVERTER_ENGINE)


def _check_stop(stop: float, threshold: float) -> None:
    """Refuse a training that stops at ``stop`` (``stop_at_success``; 0: never) under the
    benchmark's ``threshold``: its seeds would end before they could count as solved."""
    if 0 < stop < threshold:
        raise ConfigError(
            f"the training stops at its first evaluation at {stop:g} success "
            f"(stop_at_success), under --threshold {threshold:g}, so no seed could count as "
            f"solved: give --threshold {stop:g}, or --set stop_at_success={threshold:g}"
        )


def run_seeds(
    config: SeedsConfig,
    runs_dir: Path,
    overrides: tuple[str, ...] = (),
    first_start: float | None = None,
    log=print,
    on_seed: SeedsDone | None = None,
) -> tuple[list[SeedRun], list[dict[str, Any]]]:
    """Train every seed of ``config`` in turn; the results and each run's saved config.

    The first seed's times count from ``first_start`` (the command's start: imports and any
    cold compilation included), the others' from their own start. ``on_seed`` is called with
    the seeds finished so far each time one finishes. With ``config.server`` this process keeps
    the envs and programs from one seed to the next (:mod:`mjx_arm.train.warm`).
    """
    seeds = parse_seeds(config.seeds)
    runs, configs = [], []
    if config.server:  # the seeds train in turn in this process, which keeps what they share
        from mjx_arm.train import warm

        warm.enable()
    for i, seed in enumerate(seeds):
        log(f"seed {seed} ({i + 1} of {len(seeds)}): training {config.task} / {config.preset}")
        start = first_start if i == 0 else None
        run, saved = train_seed(config, seed, runs_dir, overrides, start)
        run.warm = i > 0
        runs.append(run)
        configs.append(saved)
        log_run(log, config, run)
        if on_seed is not None:
            on_seed(list(runs), list(configs))
    return runs, configs


def log_run(log, config: SeedsConfig, run: SeedRun) -> None:
    """A finished seed's result line, then its start-up line."""
    log(seed_line(config, run))
    log(f"seed {run.seed} {start_up_line(run.compile_report)}")
