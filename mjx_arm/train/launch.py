"""Start a host's share of a training: one process per GPU, joined by ``jax.distributed``.

With ``MJX_ARM_PROCESS_PER_GPU=1``, ``mjx-arm train --devices N`` on a host with several GPUs
runs N copies of the same command, each with one GPU (``CUDA_VISIBLE_DEVICES``) and its place in
the group
(:class:`~mjx_arm.train.distributed.ProcessGroup`, handed over in environment variables). The
launcher itself never starts JAX on a GPU: it counts the GPUs from the driver, so every GPU's
memory is left to the process that trains on it.

Process 0's output is this command's output; every other process writes
``RUN_DIR/logs/process_K.log``. When one process fails, the launcher stops the others (they
would wait for it at the next gradient all-reduce for ever) and exits with the failed
process's code, naming it and showing the end of its log.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mjx_arm.inputs import ConfigError
from mjx_arm.train.distributed import Hosts, ProcessGroup

NVIDIA_GPUS = Path("/proc/driver/nvidia/gpus")
STOP_GRACE_S = 10.0  # seconds a stopped process gets before it is killed
# "1": several GPUs of a host always train in a process each; "0": never (one process, XLA
# splits the batch over its devices). Unset: a process each for MuJoCo Warp asked for several
# GPUs (:func:`per_gpu_wanted`).
PROCESS_PER_GPU = "MJX_ARM_PROCESS_PER_GPU"
# jax versions on which XLA's compiler crashed (SIGSEGV in backend_compile_and_load) in every
# process of a per-GPU training of MJX on MuJoCo Warp: 0.11.2 on H100s, 8 of 8 runs. The
# pinned 0.10.2 trained on 1, 2 and 4 H100s (benchmarks/results/scaling/).
CRASHING_JAX = ("0.11.",)
CUDA_PLUGINS = (
    "jax_cuda13_plugin",
    "jax_cuda12_plugin",
    "jax_plugins.xla_cuda13",
    "jax_plugins.xla_cuda12",
)


def visible_gpus() -> list[str]:
    """The GPUs JAX would see here, as ``CUDA_VISIBLE_DEVICES`` entries, without starting CUDA.

    Empty where JAX has no CUDA plugin, runs on the CPU by request (``JAX_PLATFORMS``), or
    the driver lists no GPU.
    """
    platforms = os.environ.get("JAX_PLATFORMS", "")
    if platforms and "cuda" not in platforms and "gpu" not in platforms:
        return []
    if not any(_installed(name) for name in CUDA_PLUGINS):
        return []
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return [g for g in (s.strip() for s in visible.split(",")) if g and g != "-1"]
    count = len(list(NVIDIA_GPUS.iterdir())) if NVIDIA_GPUS.is_dir() else 0
    return [str(i) for i in range(count)]


def _installed(module: str) -> bool:
    """Whether ``module`` can be imported (a dotted name whose package is missing: no)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


@dataclass(frozen=True)
class Plan:
    """How this host takes part in a training.

    Attributes:
        gpus: the GPUs this host starts a process on (empty: the training runs in this
            process, on its local devices).
        groups: each started process's group, in the order of ``gpus``.
        group: this process's group where it trains itself (joined where hosts > 1).
    """

    gpus: tuple[str, ...] = ()
    groups: tuple[ProcessGroup, ...] = ()
    group: ProcessGroup = field(default_factory=ProcessGroup)

    @property
    def spawns(self) -> bool:
        """Whether this host starts processes rather than training in this one."""
        return bool(self.gpus)


def process_per_gpu() -> bool:
    """Whether ``MJX_ARM_PROCESS_PER_GPU=1`` asks for a process per GPU whatever the physics."""
    return os.environ.get(PROCESS_PER_GPU) == "1"


def per_gpu_wanted(devices: int | None, backend: str, impl: str) -> bool:
    """Whether ``--devices`` GPUs of this host train in a process each.

    MuJoCo Warp steps one GPU per process (two in one process crash at its first call), so
    ``--devices N`` (N > 1) on MJX with Warp (``impl`` auto or warp, warp-lang installed)
    starts N processes joined by jax.distributed. MJX's JAX physics keeps one process, whose
    XLA program splits the batch over the devices. ``MJX_ARM_PROCESS_PER_GPU`` overrides
    ("1": always, "0": never).
    """
    chosen = os.environ.get(PROCESS_PER_GPU)
    if chosen in ("0", "1"):
        return chosen == "1"
    on_warp = backend in ("auto", "mjx") and impl in ("auto", "warp") and _installed("warp")
    return bool(devices and devices > 1) and on_warp


def plan(
    hosts: Hosts,
    devices: int | None,
    gpus: list[str] | None = None,
    per_gpu: bool | None = None,
) -> Plan:
    """The processes of this host for ``--devices`` (None or 0: every GPU; else that many).

    Without ``per_gpu`` (default: :func:`process_per_gpu`), or with one GPU or none (a CPU),
    the training runs in this process on its local devices, joined to the other hosts where
    there are several. With it, several GPUs start one process each, numbered
    ``host rank * GPUs per host + GPU index`` (every host must use as many GPUs).

    Raises:
        ConfigError: more GPUs asked for than this host has.
    """
    per_gpu = process_per_gpu() if per_gpu is None else per_gpu
    gpus = visible_gpus() if gpus is None else gpus
    if devices and gpus and devices > len(gpus):
        raise ConfigError(
            f"asked for {devices} GPUs, this host has {len(gpus)}; choose --devices "
            f"{len(gpus)} or fewer"
        )
    chosen = gpus[: devices or len(gpus)]
    if len(chosen) <= 1 or not per_gpu:
        if hosts.count == 1:
            return Plan()
        group = ProcessGroup(hosts.coordinator, hosts.count, hosts.rank, hosts.join_timeout)
        return Plan(group=group)
    coordinator = hosts.coordinator if hosts.count > 1 else f"127.0.0.1:{free_port()}"
    total = hosts.count * len(chosen)
    groups = tuple(
        ProcessGroup(coordinator, total, hosts.rank * len(chosen) + i, hosts.join_timeout)
        for i in range(len(chosen))
    )
    return Plan(tuple(chosen), groups)


def free_port() -> int:
    """A TCP port free on this host now (for the coordinator of a one-host training)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(plan: Plan, argv: list[str], logs: Path, log=print) -> int:
    """Start the processes of ``plan``, each ``python -m mjx_arm.cli ARGV``; wait for all.

    Args:
        plan: the GPUs and each process's group.
        argv: the command's arguments (the run directory named, so every process writes the
            same one).
        logs: where processes other than the first write their output.
        log: where the launcher's own lines go.

    Returns:
        0 when every process succeeded, else the exit code of the first that failed.
    """
    from mjx_arm.train.rundir import open_no_follow  # no log is written through a link

    logs.mkdir(parents=True, exist_ok=True)
    children: list[tuple[ProcessGroup, str, subprocess.Popen, Path | None]] = []
    pairs = zip(plan.gpus, plan.groups, strict=True)
    ids = ", ".join(f"GPU {g}: process {p.process_id}" for g, p in pairs)
    log(f"{len(plan.gpus)} processes of {plan.groups[0].num_processes}, one per GPU ({ids})")
    try:
        for gpu, group in zip(plan.gpus, plan.groups, strict=True):
            env = {**os.environ, **group.env(), "CUDA_VISIBLE_DEVICES": gpu}
            command = [sys.executable, "-m", "mjx_arm.cli", *argv]
            if group.leader:
                children.append((group, gpu, subprocess.Popen(command, env=env), None))
                continue
            path = logs / f"process_{group.process_id}.log"
            flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
            with os.fdopen(open_no_follow(path, flags, "process log"), "wb") as out:
                proc = subprocess.Popen(command, env=env, stdout=out, stderr=subprocess.STDOUT)
            children.append((group, gpu, proc, path))
        return _wait(children, log)
    finally:
        stop_processes([c[2] for c in children])  # SIGTERM, then SIGKILL after a grace


def _wait(children: list, log) -> int:
    """Wait until every child ended (0) or one failed (its exit code, the rest stopped)."""
    pending = list(children)
    while pending:
        for item in list(pending):
            group, gpu, proc, path = item
            code = proc.poll()
            if code is None:
                continue
            pending.remove(item)
            if code != 0:
                log(_failure(group, gpu, code, path))
                return code if code > 0 else 1
        time.sleep(0.2)
    return 0


def _failure(group: ProcessGroup, gpu: str, code: int, path: Path | None) -> str:
    """The launcher's line (and the log's end) for a process that failed."""
    cause = f"signal {-code}" if code < 0 else f"exit code {code}"
    text = (
        f"error: process {group.process_id} (GPU {gpu}) ended with {cause}; the other "
        "processes were stopped"
    )
    if path is not None and path.is_file():
        tail = path.read_text(errors="replace").strip().splitlines()[-15:]
        text += f"; the end of {path}:\n" + "\n".join(f"  {line}" for line in tail)
    return text


def stop_processes(
    procs: list[subprocess.Popen], sig: int = signal.SIGTERM, grace_s: float = STOP_GRACE_S
) -> None:
    """Send ``sig`` to every process of ``procs`` still running and wait for them; one still
    running ``grace_s`` seconds later is killed."""
    running = [p for p in procs if p.poll() is None]
    for p in running:
        p.send_signal(sig)
    deadline = time.monotonic() + grace_s
    for p in running:
        try:
            p.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def devices_for_physics(config: Any) -> Any:
    """``config`` with the device count its physics can train on in this process.

    MuJoCo Warp steps one GPU per process: two devices in one process crash at its first
    call (its foreign call assumes the first device), so several GPUs train in processes
    joined by jax.distributed (:func:`per_gpu_wanted`), each on its own GPU. In one process
    on Warp the default (``devices=0``) is one GPU and more is a named error that says what
    works; MJX's JAX physics or the C MuJoCo batch keep every device asked for.

    Raises:
        ConfigError: several GPUs in one process on MuJoCo Warp, or joined processes on a jax
            version whose compiler crashed on them (:data:`CRASHING_JAX`).
    """
    import jax

    from mjx_arm.envs.backend import resolve_backend
    from mjx_arm.envs.physics_config import resolve_impl

    if resolve_backend(config.backend) != "mjx" or resolve_impl(config.physics.impl) != "warp":
        return config
    if jax.process_count() > 1 and jax.__version__.startswith(CRASHING_JAX):
        if process_per_gpu():
            return config
        raise ConfigError(
            f"MuJoCo Warp in processes joined by jax.distributed crashes XLA's compiler on jax "
            f"{jax.__version__}: install the tested set (pip install -e '.[gpu]' brings jax "
            "0.10.2), or use --set physics.impl=jax, or MJX_ARM_PROCESS_PER_GPU=1 to try anyway"
        )
    if jax.process_count() > 1:
        return config
    if config.devices > 1 and jax.local_device_count() > 1:
        raise ConfigError(
            f"MuJoCo Warp trains on one GPU per process (asked for {config.devices} in one): "
            f"unset {PROCESS_PER_GPU} so that --devices starts a process per GPU, or use "
            "--set physics.impl=jax (XLA splits the batch over the devices of one process)"
        )
    return config.replace(devices=1) if jax.local_device_count() > 1 else config
