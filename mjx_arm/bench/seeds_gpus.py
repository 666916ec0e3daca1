"""The seeds benchmark on a GPU host: each seed trains in a process of its own, one per GPU at a
time (with ``--server``, a ``train --server`` command run by its GPU's warm trainer).

A SIGTERM (a deadline's ``timeout``) stops the benchmark without losing what it has: the seeds
whose processes have ended are read, those still training are stopped as Ctrl-C stops a run,
the warm trainers are stopped, and :func:`train_seeds` hands back the finished seeds with the
count left out, so that the report says which were cut. Without it a seed that ended in the
last half second before the signal was lost with its benchmark, and the warm trainers stayed
behind on their GPUs.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mjx_arm.bench.seed_servers import SeedServers, gpu_env
from mjx_arm.bench.seeds import (
    SeedsDone,
    failed_seed,
    log_error,
    log_run,
    read_seed_run,
    run_seeds,
    seed_command,
    seed_run_dir,
    stopped_from_outside,
)
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig, parse_seeds
from mjx_arm.train.launch import stop_processes

STOP_WAIT_S = 20  # for a stopped seed's process to save and end, before it is killed


class SeedsStopped(Exception):
    """A SIGTERM stopped the benchmark; ``runs`` and ``configs``: the seeds that finished, in
    seed order."""

    def __init__(self, runs: list[SeedRun], configs: list[dict[str, Any]]) -> None:
        super().__init__(f"stopped by SIGTERM after {len(runs)} seeds")
        self.runs, self.configs = runs, configs


@contextlib.contextmanager
def _sigterm_requests_stop() -> Iterator[dict[str, bool]]:
    """Within: a SIGTERM sets ``["stop"]`` of the yielded dict instead of ending the process
    (only where this is the main thread, which alone may take signals)."""
    flag = {"stop": False}
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    before = signal.signal(signal.SIGTERM, lambda *_: flag.update(stop=True))
    try:
        yield flag
    finally:
        signal.signal(signal.SIGTERM, before)


def train_seeds(config, runs_dir: Path, gpus: list[str], overrides, start: float, log, report):
    """Train the seeds (a process per seed on ``gpus``, else in turn here); after each seed
    but the last, ``report`` writes the report of the seeds finished so far, so that a
    benchmark stopped early keeps them.

    Returns:
        ``(runs, configs, pending)``: the seeds that finished, their saved configs, and how
        many a SIGTERM left out (0 where every seed finished): those it stopped or never let
        start, and any seed whose own process a SIGTERM ended.
    """
    total = len(parse_seeds(config.seeds))

    def on_seed(runs: list, configs: list) -> None:
        if len(runs) < total:
            wall = time.time() - start
            report(runs, configs, overrides=overrides, wall_s=wall, pending=total - len(runs))

    if not gpus:
        return (*run_seeds(config, runs_dir, overrides, start, log, on_seed), 0)
    try:
        runs, configs = run_seeds_on_gpus(config, runs_dir, gpus, overrides, log, on_seed)
        return runs, configs, total - len(runs)
    except SeedsStopped as stopped:
        log(f"stopped by SIGTERM: {len(stopped.runs)} of {total} seeds finished")
        return stopped.runs, stopped.configs, total - len(stopped.runs)


def _start_seed(
    config: SeedsConfig,
    seed: int,
    runs_dir: Path,
    gpu: str,
    overrides: tuple[str, ...],
    servers: SeedServers | None = None,
) -> subprocess.Popen:
    """Start ``seed``'s training on ``gpu`` (a ``CUDA_VISIBLE_DEVICES`` entry: one GPU, or
    ``"0,1"`` for a seed on two) in a process of its own (with ``servers``, a ``train --server``
    command that the GPU's warm trainer runs), its output to ``runs_dir/seedN.log``."""
    env = {**gpu_env(gpu), **(servers.seed_env(gpu) if servers else {})}
    run_dir = seed_run_dir(config, seed, runs_dir)
    command = seed_command(config, seed, run_dir, overrides)
    with (runs_dir / f"seed{seed}.log").open("wb") as out:
        return subprocess.Popen(
            command + (["--server"] if servers else []),
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def _finished_seed(
    config: SeedsConfig, seed: int, runs_dir: Path, proc: subprocess.Popen, gpu: str, start: float
) -> tuple[SeedRun, dict[str, Any]]:
    """The result and saved config of a seed whose process has ended (a failed one: not
    solved, with the end of its log)."""
    from mjx_arm.train.rundir import RunDir

    end = time.time()
    if proc.returncode != 0:
        log = (runs_dir / f"seed{seed}.log").read_text(errors="replace")
        error = f"exit code {proc.returncode}: {log_error(log)}"
        return failed_seed(seed, gpu, end - start, error), {}
    run_dir = seed_run_dir(config, seed, runs_dir)
    run = read_seed_run(config, seed, run_dir, start, end)
    run.gpu = gpu
    return run, RunDir(run_dir).load_config()


def run_seeds_on_gpus(
    config: SeedsConfig,
    runs_dir: Path,
    gpus: list[str],
    overrides: tuple[str, ...] = (),
    log=print,
    on_seed: SeedsDone | None = None,
) -> tuple[list[SeedRun], list[dict[str, Any]]]:
    """Train every seed in a process of its own, one per GPU of ``gpus`` at a time.

    Each seed's times count from its own process's start (imports, cache loads and any compilation
    included); a seed is warm where another had ended before it started (the seeds started at once
    on a fresh host all found the caches empty). A seed whose process fails is reported as not
    solved, with the end of its log, and the others go on; one whose process a SIGTERM ended
    was stopped from outside and is left out (:data:`~mjx_arm.bench.seeds.STOPPED_EXIT_CODES`).
    ``on_seed`` is called with the seeds finished so far (in seed order) each time one
    or more finish. With ``config.server`` each GPU's
    warm trainer (:class:`~mjx_arm.bench.seed_servers.SeedServers`) runs its seeds' commands;
    a seed is then warm where that server had finished a seed before it and kept its programs.

    Raises:
        SeedsStopped: a SIGTERM came (the module's docstring), with the seeds that finished.
    """
    runs_dir.mkdir(parents=True, exist_ok=True)
    with _sigterm_requests_stop() as flag:
        servers = SeedServers(gpus, runs_dir, log).start() if config.server else None
        try:
            return _train_on_gpus(config, runs_dir, gpus, overrides, log, on_seed, servers, flag)
        finally:
            if servers:
                servers.stop()


def _train_on_gpus(
    config: SeedsConfig,
    runs_dir: Path,
    gpus: list[str],
    overrides: tuple[str, ...],
    log,
    on_seed: SeedsDone | None,
    servers: SeedServers | None,
    flag: dict[str, bool],
) -> tuple[list[SeedRun], list[dict[str, Any]]]:
    """:func:`run_seeds_on_gpus` once its warm trainers (if any) have started."""
    seeds = parse_seeds(config.seeds)
    queue, free = list(seeds), list(gpus)
    running: dict[int, tuple[subprocess.Popen, str, float, bool]] = {}
    done: dict[int, tuple[SeedRun, dict[str, Any]]] = {}
    while (queue or running) and not flag["stop"]:
        while queue and free:
            seed, gpu = queue.pop(0), free.pop(0)
            proc = _start_seed(config, seed, runs_dir, gpu, overrides, servers)
            warm = servers.served[gpu] > 0 if servers else bool(done)  # caches filled
            running[seed] = (proc, gpu, time.time(), warm)
            log(f"seed {seed}: training {config.task} / {config.preset} on GPU {gpu}")
        before = len(done)
        free += _collect(config, runs_dir, running, done, servers, log)
        if on_seed is not None and len(done) > before:  # not for a seed left out
            finished = [done[s] for s in seeds if s in done]
            on_seed([r for r, _ in finished], [c for _, c in finished])
        time.sleep(0.5)
    if flag["stop"]:
        _collect(config, runs_dir, running, done, servers, log)  # those that ended meanwhile
        # as Ctrl-C stops a run (a `train --server` command passes it on to its server)
        stop_processes([proc for proc, *_ in running.values()], signal.SIGINT, STOP_WAIT_S)
    ordered = [done[s] for s in seeds if s in done]
    runs, configs = [r for r, _ in ordered], [c for _, c in ordered]
    if flag["stop"]:
        raise SeedsStopped(runs, configs)
    return runs, configs


def _collect(config, runs_dir: Path, running: dict, done: dict, servers, log) -> list:
    """Move the seeds of ``running`` whose processes have ended into ``done`` (logging each;
    one a SIGTERM ended is dropped, :func:`~mjx_arm.bench.seeds.stopped_from_outside`); the
    GPUs they leave free."""
    ended = []
    for seed, (proc, gpu, start, warm) in list(running.items()):
        if proc.poll() is None:
            continue
        del running[seed]
        ended.append(gpu)
        run, saved = _finished_seed(config, seed, runs_dir, proc, gpu, start)
        if stopped_from_outside(run):
            log(f"seed {seed}: its process was stopped by a SIGTERM; left out ({run.error[:80]})")
            continue
        done[seed] = run, saved
        # on a server, a seed after a group's restart (a run stopped on it) starts cold again
        run.warm = warm and (not servers or bool((run.compile_report or {}).get("kept_warm")))
        if servers:
            servers.served[gpu] += 1
        if run.error:
            log(f"seed {seed}: its process failed ({run.error[:400]})")
        else:
            log_run(log, config, run)
    return ended
