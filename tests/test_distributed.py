"""Training over several processes (:mod:`mjx_arm.train.distributed`, :mod:`mjx_arm.train.launch`).

Two ``mjx-arm train`` processes on this host, joined as two hosts of one CPU device each
(``--coordinator``, ``--hosts 2``, ``--host-rank``), train the same run as one process of two
CPU devices; a process whose partners never come fails with a named error; the launcher's plan
of processes for a host's GPUs, and what it does when one of them fails.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from tiny_run import EPOCH_STEPS, EPOCHS, SETTINGS

from mjx_arm.inputs import ConfigError
from mjx_arm.train import distributed, launch
from mjx_arm.train.distributed import Hosts, JoinError, ProcessGroup
from mjx_arm.train.launch import Plan, free_port, plan
from mjx_arm.train.resume import ENV_STATE_FILE, RESUME_FILE
from mjx_arm.train.rundir import RunDir

# Allowed difference of a stored array between the two runs, relative to its largest entry.
# Both runs split the 32 envs over a mesh of 2 devices the same way (envs 0-15 on the first),
# so each device runs the same program on the same data; the gradient is the mean of the two
# devices' terms, and a sum of 2 floats does not depend on its order (a + b == b + a), whether
# XLA's in-process all-reduce or gloo's across processes adds them. The runs agree to the bit
# (measured: 0.0); the tolerance, a few float32 ulps, allows a reduction that scales each term
# before adding (a/2 + b/2 rounds differently from (a + b)/2).
TOLERANCE = 1e-6
TIMEOUT_S = 600  # one training here takes about a minute; a hang ends at this
# What tells a process where it stands among several (none of it from the test's environment).
HOST_VARIABLES = (
    distributed.ENV_COORDINATOR,
    distributed.ENV_NUM_PROCESSES,
    distributed.ENV_PROCESS_ID,
    distributed.ENV_HOSTS,
    distributed.ENV_HOST_RANK,
    "MJX_ARM_JOIN_TIMEOUT",
    "SLURM_NNODES",
    "SLURM_NODEID",
)


def _env(**extra: str) -> dict[str, str]:
    """The environment of a training started here: CPU only, the tests' compilation cache.

    XLA aborts a CPU collective that one device joins a minute after the other
    (tests/test_multidevice.py): on 2 cores the two processes' rollouts share the cores, so
    the limit is raised to 10 minutes.
    """
    import jax

    flags = " ".join(
        [
            *extra.pop("XLA_FLAGS", "").split(),
            "--xla_cpu_collective_call_terminate_timeout_seconds=600",
        ]
    )
    env = {k: v for k, v in os.environ.items() if k not in HOST_VARIABLES}
    cache = jax.config.jax_compilation_cache_dir or os.environ.get("MJX_ARM_JAX_CACHE", "")
    return {**env, "JAX_PLATFORMS": "cpu", "MJX_ARM_JAX_CACHE": cache, "XLA_FLAGS": flags, **extra}


# Under an evaluation gate, so that the processes must agree on which epochs they evaluate
# (each reads the epoch's training success rate, reduced over both processes' envs).
GATE = 0.5


def _train_args(run_dir: Path, *flags: str) -> list[str]:
    sets = [f"{k}={v}" for k, v in SETTINGS.items()] + [f"eval_gate={GATE}"]
    return [sys.executable, "-m", "mjx_arm.cli", "train", "--quiet", "--preset", "cpu",
            "--run-dir", str(run_dir), *flags, "--set", *sets]  # fmt: skip


# one process of two devices, on the preset's totals rather than grown with the devices
SINGLE = ("--devices", "2", "--set", "scale_with_devices=false")


def _finish(procs: list[subprocess.Popen]) -> list[int]:
    """Wait for every process (killing all at the timeout); their exit codes."""
    deadline = time.monotonic() + TIMEOUT_S
    try:
        return [p.wait(timeout=max(deadline - time.monotonic(), 1)) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


@dataclass
class Runs:
    pair: Path  # two processes of one device each
    single: Path  # one process of two devices
    outputs: list[str]  # the two processes' stdout + stderr


def _start(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    with log.open("wb") as out:
        return subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    """The pair and the single process, started at once."""
    out = tmp_path_factory.mktemp("distributed")
    pair, single = out / "pair", out / "single"
    hosts = ["--coordinator", f"127.0.0.1:{free_port()}", "--hosts", "2"]
    logs = [out / name for name in ("process_0.log", "process_1.log", "single.log")]
    two_devices = _env(XLA_FLAGS="--xla_force_host_platform_device_count=2")
    procs = [
        _start(_train_args(pair, *hosts, "--host-rank", "0"), _env(), logs[0]),
        _start(_train_args(pair, *hosts, "--host-rank", "1"), _env(), logs[1]),
        # the preset's totals on two devices (not grown with them), as the pair trains
        _start(_train_args(single, *SINGLE), two_devices, logs[2]),
    ]
    codes = _finish(procs)
    outputs = [log.read_text(errors="replace") for log in logs]
    assert codes == [0, 0, 0], "\n\n".join(text[-3000:] for text in outputs)
    return Runs(pair, single, outputs[:2])


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def test_two_processes_train_what_one_process_of_two_devices_does(runs: Runs) -> None:
    """The final training state (params, normaliser, Adam's moments, keys) and envs' state."""
    final = RunDir(runs.pair).checkpoint_dir(EPOCHS * EPOCH_STEPS)
    reference = RunDir(runs.single).checkpoint_dir(EPOCHS * EPOCH_STEPS)
    for name in (RESUME_FILE, ENV_STATE_FILE):
        got, want = _arrays(final / name), _arrays(reference / name)
        assert sorted(got) == sorted(want), name
        for key, array in want.items():
            assert (got[key].shape, got[key].dtype) == (array.shape, array.dtype), key
            if not np.issubdtype(array.dtype, np.floating):  # keys, counters
                np.testing.assert_array_equal(got[key], array, err_msg=f"{name}: {key}")
                continue
            scale = max(float(np.abs(array).max(initial=0.0)), 1e-30)
            error = float(np.abs(got[key].astype(np.float64) - array).max(initial=0.0)) / scale
            assert error <= TOLERANCE, f"{name}: {key} differs by {error:.2e} of its largest entry"


def test_process_0_alone_writes_and_reports(runs: Runs) -> None:
    rows = RunDir(runs.pair).read_metrics()
    assert [int(r["step"]) for r in rows] == [i * EPOCH_STEPS for i in range(1, EPOCHS + 1)]
    # the pair evaluated where the gate let it (and at its last epoch), as the single process
    evaluated = [np.isfinite(r.get("eval/episode_success", np.nan)) for r in rows]
    rates = [r["training/episode_success"] for r in rows]
    assert evaluated == [rate >= GATE for rate in rates[:-1]] + [True] and not all(evaluated)
    single = RunDir(runs.single).read_metrics()
    assert [np.isfinite(r.get("eval/episode_success", np.nan)) for r in single] == evaluated
    assert [r["training/episode_success"] for r in single] == rates
    assert sorted(p.name for p in runs.pair.iterdir()) == sorted(
        p.name for p in runs.single.iterdir()
    )  # nothing of process 1's own: one config.json, one metrics.csv, no logs
    assert sorted(p.name for p in (runs.pair / "checkpoints").iterdir()) == sorted(
        p.name for p in (runs.single / "checkpoints").iterdir()
    )
    first, second = runs.outputs
    assert "done:" in first and "run directory:" in first
    assert "done:" not in second and "run directory:" not in second
    assert "Traceback" not in first + second
    saved = json.loads((runs.pair / "config.json").read_text())
    assert saved["processes"] == 2


def test_a_process_whose_partners_never_come_is_a_named_error(tmp_path: Path) -> None:
    """JAX's own join, alone, ends the process natively (SIGABRT, exit code 134, a C++ stack
    on stderr) after about twice the timeout; the processes meet on the coordinator's port
    before it, so this is one error line and exit code 2."""
    run_dir = tmp_path / "run"
    args = ["--task", "reach", "--preset", "cpu", "--run-dir", str(run_dir)]
    hosts = ["--coordinator", f"127.0.0.1:{free_port()}", "--hosts", "2", "--host-rank", "1"]
    command = [sys.executable, "-m", "mjx_arm.cli", "train", *args, *hosts, "--join-timeout", "5"]
    start = time.monotonic()
    done = subprocess.run(command, env=_env(), capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr[-3000:]
    lines = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-3000:]
    assert "process 1 of 2 could not join the training" in lines[0]
    assert "within 5 s" in lines[0] and "process 0 could not be reached" in lines[0]
    assert time.monotonic() - start < 60
    assert not run_dir.exists()


# ------------------------------------------------------------------- meeting on the port


def _meet_all(groups: list[ProcessGroup], timeout: float = 20) -> list[str]:
    """Each group's :meth:`ProcessGroup._meet` on its own thread: "" or its error."""

    def one(group: ProcessGroup) -> str:
        try:
            group._meet(time.monotonic() + group.join_timeout)
        except JoinError as err:
            return str(err)
        return ""

    with ThreadPoolExecutor(len(groups)) as pool:
        return list(pool.map(one, groups, timeout=timeout))


def test_processes_meet_before_joining() -> None:
    address = f"127.0.0.1:{free_port()}"
    assert _meet_all([ProcessGroup(address, 3, i, 10) for i in (2, 1, 0)]) == ["", "", ""]
    # the port is free again for JAX's service
    assert _meet_all([ProcessGroup(address, 2, i, 10) for i in (0, 1)]) == ["", ""]


def test_two_processes_of_one_id_are_a_named_error() -> None:
    address = f"127.0.0.1:{free_port()}"
    errors = _meet_all([ProcessGroup(address, 3, i, 10) for i in (0, 1, 1)])
    assert all("two processes have id 1" in e for e in errors), errors


def test_processes_told_of_other_host_counts_are_a_named_error() -> None:
    address = f"127.0.0.1:{free_port()}"
    errors = _meet_all([ProcessGroup(address, 2, 0, 10), ProcessGroup(address, 3, 1, 10)])
    assert all("give every host the same --hosts" in e for e in errors), errors


def test_process_0_without_the_others_is_a_named_error() -> None:
    address = f"127.0.0.1:{free_port()}"
    (error,) = _meet_all([ProcessGroup(address, 3, 0, 1)])
    assert "process 0 of 3 could not join" in error and "process(es) 1, 2 did not come" in error


# --------------------------------------------------------------------------- the launcher


def test_no_gpu_or_one_trains_in_this_process() -> None:
    for gpus in ([], ["0"]):
        chosen = plan(Hosts(), None, gpus)
        assert not chosen.spawns and not chosen.group.joined
    joined = plan(Hosts("10.0.0.1:1234", 2, 1), None, ["0"]).group  # one GPU on each host
    assert (joined.coordinator, joined.num_processes, joined.process_id) == ("10.0.0.1:1234", 2, 1)


def test_several_gpus_train_in_this_process_unless_one_process_per_gpu_is_asked_for() -> None:
    assert not plan(Hosts(), None, ["0", "1"], per_gpu=False).spawns
    joined = plan(Hosts("10.0.0.1:1234", 2, 1), None, ["0", "1"], per_gpu=False).group
    assert (joined.num_processes, joined.process_id) == (2, 1)


def test_several_gpus_start_one_process_each() -> None:
    chosen = plan(Hosts(), None, ["0", "1", "2", "3"], per_gpu=True)
    assert chosen.spawns and chosen.gpus == ("0", "1", "2", "3")
    assert [g.process_id for g in chosen.groups] == [0, 1, 2, 3]
    assert {g.num_processes for g in chosen.groups} == {4}
    (coordinator,) = {g.coordinator for g in chosen.groups}
    assert coordinator.startswith("127.0.0.1:")
    assert plan(Hosts(), 2, ["0", "1", "2", "3"], per_gpu=True).gpus == ("0", "1")


def test_the_second_of_two_hosts_numbers_its_processes_after_the_first() -> None:
    chosen = plan(Hosts("10.0.0.1:1234", 2, 1), None, ["0", "1"], per_gpu=True)
    assert [g.process_id for g in chosen.groups] == [2, 3]
    assert {(g.num_processes, g.coordinator) for g in chosen.groups} == {(4, "10.0.0.1:1234")}


def test_more_gpus_than_there_are_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="asked for 3 GPUs, this host has 2"):
        plan(Hosts(), 3, ["0", "1"])


def test_a_group_reaches_the_process_it_starts(monkeypatch) -> None:
    group = ProcessGroup("127.0.0.1:4321", 4, 3, 60)
    for name, value in group.env().items():
        monkeypatch.setenv(name, value)
    assert ProcessGroup.from_env() == group


@pytest.fixture
def host_env(monkeypatch):
    for name in HOST_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_hosts_come_from_flags_then_our_variables_then_slurms(host_env) -> None:
    assert Hosts.from_args(None, None, None, None) == Hosts()
    host_env.setenv("SLURM_NNODES", "3")
    host_env.setenv("SLURM_NODEID", "2")
    host_env.setenv("MJX_ARM_COORDINATOR", "node0:5000")
    assert Hosts.from_args(None, None, None, None) == Hosts("node0:5000", 3, 2)
    host_env.setenv("MJX_ARM_HOSTS", "4")
    host_env.setenv("MJX_ARM_HOST_RANK", "3")
    assert Hosts.from_args(None, None, None, 7) == Hosts("node0:5000", 4, 3, 7)
    assert Hosts.from_args("node1:6000", 2, 0, None) == Hosts("node1:6000", 2, 0)


@pytest.mark.parametrize(
    ("variables", "message"),
    [
        (
            {"MJX_ARM_HOSTS": "2", "MJX_ARM_HOST_RANK": "2", "MJX_ARM_COORDINATOR": "h:1"},
            "rank 2 of 2",
        ),
        ({"SLURM_NNODES": "2", "SLURM_NODEID": "1"}, "needs --coordinator HOST:PORT"),
        ({"MJX_ARM_HOSTS": "2", "MJX_ARM_COORDINATOR": "node0"}, "needs --coordinator HOST:PORT"),
        ({"MJX_ARM_HOST_RANK": "first"}, "MJX_ARM_HOST_RANK='first' is not a whole number"),
    ],
)
def test_bad_host_settings_are_config_errors(host_env, variables: dict, message: str) -> None:
    for name, value in variables.items():
        host_env.setenv(name, value)
    with pytest.raises(ConfigError, match=message):
        Hosts.from_args(None, None, None, None)


def test_children_that_fail_end_the_launch_with_their_code(tmp_path: Path, capfd) -> None:
    """A bad argument: every child exits 2 at once; the launcher returns 2 and names one."""
    lines: list[str] = []
    chosen = plan(Hosts(), None, ["0", "1"], per_gpu=True)
    code = launch.run(chosen, ["train", "--preset", "none"], tmp_path / "logs", log=lines.append)
    assert code == 2
    assert lines[0].startswith("2 processes of 2, one per GPU (GPU 0: process 0, GPU 1: process 1)")
    assert len(lines) == 2 and lines[1].startswith("error: process ")
    assert "ended with exit code 2; the other processes were stopped" in lines[1]
    assert "invalid choice: 'none'" in (tmp_path / "logs" / "process_1.log").read_text()


def test_one_failed_child_stops_the_others(tmp_path: Path, monkeypatch) -> None:
    """Process 1 fails; process 0, which would wait for it for ever, is stopped (SIGTERM)."""
    ready, stopped = tmp_path / "ready", tmp_path / "stopped"
    child = tmp_path / "child.sh"  # in place of python: process 0 waits, process 1 fails
    child.write_text(
        "#!/bin/sh\n"
        'if [ "$MJX_ARM_PROCESS_ID" = 1 ]; then\n'
        f"  while [ ! -f {ready} ]; do sleep 0.05; done\n"
        '  echo "process 1 gives up"; exit 3\n'
        "fi\n"
        "sleep 60 &\n"
        f"trap 'kill $!; echo $MJX_ARM_PROCESS_ID > {stopped}; exit 143' TERM\n"
        f"touch {ready}\n"
        "wait\n"
    )
    child.chmod(0o755)
    monkeypatch.setattr(launch.sys, "executable", str(child))
    lines: list[str] = []
    start = time.monotonic()
    groups = tuple(ProcessGroup("127.0.0.1:1", 2, i, 60) for i in (0, 1))
    code = launch.run(Plan(("0", "1"), groups), ["train"], tmp_path / "logs", log=lines.append)
    assert code == 3
    assert time.monotonic() - start < launch.STOP_GRACE_S
    assert lines[-1].startswith("error: process 1 (GPU 1) ended with exit code 3")
    assert "process 1 gives up" in lines[-1]  # the end of its log
    assert stopped.read_text().strip() == "0"


def test_mujoco_warp_trains_on_one_gpu_of_several(monkeypatch) -> None:
    """Warp on several GPUs of one process crashes: the default takes one, more is an error;
    MJX's JAX physics keeps every device asked for."""
    import jax

    from mjx_arm.train.config import TrainConfig

    monkeypatch.setattr(jax, "local_device_count", lambda: 2)
    monkeypatch.setattr("mjx_arm.envs.physics_config.resolve_impl", lambda impl: impl)
    warp = TrainConfig(backend="mjx").replace(physics=TrainConfig().physics.__class__(impl="warp"))
    assert launch.devices_for_physics(warp).devices == 1
    with pytest.raises(ConfigError, match="MuJoCo Warp trains on one GPU per process"):
        launch.devices_for_physics(warp.replace(devices=2))
    jax_physics = warp.replace(physics=warp.physics.__class__(impl="jax"), devices=2)
    assert launch.devices_for_physics(jax_physics).devices == 2


def test_no_cuda_plugin_means_no_gpu(monkeypatch) -> None:
    """Without JAX_PLATFORMS and without a CUDA plugin for JAX (a CPU install), no GPU is
    counted, and the plugin names that live in a missing package raise nothing."""
    monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    monkeypatch.setattr(launch, "CUDA_PLUGINS", ("no_such_plugin", "no_such_package.plugin"))
    assert launch.visible_gpus() == []


def test_several_gpus_on_warp_start_a_process_each_and_jax_physics_keeps_one(monkeypatch) -> None:
    monkeypatch.delenv(launch.PROCESS_PER_GPU, raising=False)
    monkeypatch.setattr(launch, "_installed", lambda name: name == "warp")
    assert launch.per_gpu_wanted(2, "auto", "auto")
    assert launch.per_gpu_wanted(4, "mjx", "warp")
    assert not launch.per_gpu_wanted(2, "auto", "jax")  # XLA splits the batch in one process
    assert not launch.per_gpu_wanted(2, "mujoco", "auto")  # the C MuJoCo batch: CPUs
    assert not launch.per_gpu_wanted(None, "auto", "auto")  # Warp's default: one GPU
    assert not launch.per_gpu_wanted(1, "auto", "auto")
    monkeypatch.setattr(launch, "_installed", lambda name: False)
    assert not launch.per_gpu_wanted(2, "auto", "auto")  # no warp-lang: MJX on JAX
    monkeypatch.setenv(launch.PROCESS_PER_GPU, "0")
    monkeypatch.setattr(launch, "_installed", lambda name: name == "warp")
    assert not launch.per_gpu_wanted(2, "auto", "auto")
    monkeypatch.setenv(launch.PROCESS_PER_GPU, "1")
    assert launch.per_gpu_wanted(2, "auto", "jax")


def test_joined_warp_processes_are_refused_on_the_jax_whose_compiler_crashed(monkeypatch) -> None:
    import jax

    from mjx_arm.train.config import TrainConfig

    monkeypatch.delenv(launch.PROCESS_PER_GPU, raising=False)
    monkeypatch.setattr(jax, "process_count", lambda: 2)
    monkeypatch.setattr("mjx_arm.envs.physics_config.resolve_impl", lambda impl: impl)
    warp = TrainConfig(backend="mjx").replace(physics=TrainConfig().physics.__class__(impl="warp"))
    monkeypatch.setattr(jax, "__version__", "0.11.2")
    with pytest.raises(ConfigError, match=r"crashes XLA's compiler on jax 0\.11\.2.*0\.10\.2"):
        launch.devices_for_physics(warp)
    monkeypatch.setenv(launch.PROCESS_PER_GPU, "1")  # tried anyway, as asked
    assert launch.devices_for_physics(warp) == warp
    monkeypatch.delenv(launch.PROCESS_PER_GPU)
    monkeypatch.setattr(jax, "__version__", "0.10.2")  # the tested set
    assert launch.devices_for_physics(warp) == warp


LAUNCHER_PROBE = """
import sys
from mjx_arm.train import launch
import mjx_arm.cli as cli
launch.visible_gpus = lambda: ["0", "1"]
def probe(plan, argv, logs, log=print):
    heavy = [m for m in ("mjx_arm.train.ppo", "brax", "jax", "mujoco") if m in sys.modules]
    print("started", len(plan.gpus), "imported", heavy)
    return 0
launch.run = probe
sys.exit(cli.main(["train", "--devices", "2", "--run-dir", sys.argv[1], "--task", "reach",
                   "--preset", "cpu", "--backend", "mujoco"]))
"""


def test_the_launcher_starts_its_processes_before_importing_the_trainer(tmp_path: Path) -> None:
    """``train --devices N`` with a process per GPU starts them without importing JAX, MuJoCo
    or Brax itself: each process imports them anyway, and on a GPU host the launcher's own
    import cost about 4 s before any process started (measured: 5.7 s from the command to the
    processes' start on two H200s)."""
    env = {**os.environ, launch.PROCESS_PER_GPU: "1"}
    done = subprocess.run([sys.executable, "-c", LAUNCHER_PROBE, str(tmp_path / "run")],
                          env=env, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert "started 2 imported []" in done.stdout, done.stdout
