"""One training on two devices, per command: new processes against a warm group of two.

The same ``train --devices 2`` command, seed after seed, each timed from its command's start to
its exit:

* ``processes``: new processes for every command. On a host of two GPUs or more, ``mjx-arm
  train --devices 2`` (a process per GPU, :mod:`mjx_arm.train.launch`); on a CPU, two ``train``
  processes of one CPU device each joined by ``--coordinator``/``--hosts`` (gloo).
* ``group``: the command with ``--server``, run by a warm trainer of two devices (``mjx-arm
  serve --devices 2``, :mod:`mjx_arm.train.server_group`; on a CPU the same front over two CPU
  processes). Its first command builds everything; the next ones are warm.

The two kinds take turns seed by seed (CPU figures here are noisy: medians, side by side), and
each seed's two runs are compared bit for bit (:func:`mjx_arm.train.repeat.compare_runs`).

On a CPU (the default: a tiny Reach run, about 3 minutes on 2 cores)::

    python -m benchmarks.bench_server_group

On a host of two GPUs (Touch ``fast`` to its stop)::

    python -m benchmarks.bench_server_group --preset fast --task touch --set - --name touch_fast
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

RESULTS = RESULTS_DIR / "scaling"
# The CPU preset cut down to three epochs of 32 envs (the resume tests' run), on C MuJoCo, at
# twice its batch on two devices (as measured in scaling/server_group_reach_tiny.json).
TINY = [
    "scale_with_devices=true",
    "backend=mujoco",
    "num_timesteps=1920",
    "num_evals=4",
    "num_envs=32",
    "batch_size=32",
    "num_minibatches=4",
    "unroll_length=5",
    "num_updates_per_batch=2",
    "num_eval_envs=16",
    "policy_hidden=32,32",
    "value_hidden=32,32",
]
# The front of a group on two CPU processes (``serve --devices 2`` asks the driver for GPUs).
CPU_FRONT = (
    "import sys; from pathlib import Path; from mjx_arm.cli import build_parser; "
    "from mjx_arm.train.server_group import ServerGroup; "
    "sys.exit(ServerGroup(Path(sys.argv[1]), build_parser().parse_args, ['0', '1'], 600.0, "
    "log=lambda line: print(line, flush=True)).serve_forever())"
)
TIMEOUT_S = 1800  # one command at most


def _cpu_env() -> dict[str, str]:
    """CPU processes whose collectives wait 10 minutes for a partner (2 cores, shared)."""
    flags = "--xla_cpu_collective_call_terminate_timeout_seconds=600"
    return {**os.environ, "JAX_PLATFORMS": "cpu", "XLA_FLAGS": flags}


def _train_argv(args: argparse.Namespace, seed: int, run: Path) -> list[str]:
    sets = TINY if args.set is None else [s for s in args.set if s != "-"]
    argv = ["train", "--quiet", "--devices", "2", "--task", args.task, "--preset", args.preset]
    argv += ["--set", *sets] if sets else []
    return [sys.executable, "-m", "mjx_arm.cli", *argv, "--seed", str(seed), "--run-dir", str(run)]


def _processes(args: argparse.Namespace, seed: int, run: Path, on_gpus: bool) -> tuple:
    """Train ``seed`` in new processes; (``time.time()`` at the start, seconds to the last
    exit).

    Raises:
        RuntimeError: a process that failed.
    """
    from mjx_arm.train.launch import free_port

    start = time.time()
    if on_gpus:
        procs = [subprocess.Popen(_train_argv(args, seed, run), stdout=subprocess.DEVNULL)]
    else:
        hosts = ["--coordinator", f"127.0.0.1:{free_port()}", "--hosts", "2"]
        procs = [
            subprocess.Popen(
                [*_train_argv(args, seed, run), *hosts, "--host-rank", str(rank)],
                env=_cpu_env(),
                stdout=subprocess.DEVNULL,
            )
            for rank in (0, 1)
        ]
    codes = [p.wait(timeout=TIMEOUT_S) for p in procs]
    if any(codes):
        raise RuntimeError(f"seed {seed} in new processes: exit codes {codes}")
    return start, time.time() - start


class _Group:
    """A warm trainer of two devices at a socket of its own, for the benchmark's length."""

    def __init__(self, folder: Path, on_gpus: bool) -> None:
        self.path = folder / "g.sock"
        self.env = os.environ.copy() if on_gpus else _cpu_env()
        if on_gpus:
            command = ["-m", "mjx_arm.cli", "serve", "--devices", "2", "--socket", str(self.path)]
        else:
            command = ["-c", CPU_FRONT, str(self.path)]
        self.log = folder / "front.log"
        with self.log.open("wb") as out:
            self.proc = subprocess.Popen(
                [sys.executable, *command], env=self.env, stdout=out, stderr=out
            )
        self._wait_ready()

    def _wait_ready(self) -> None:
        from mjx_arm.train.client import ping

        deadline = time.time() + 600
        while ping(self.path) is None:
            if self.proc.poll() is not None or time.time() > deadline:
                raise RuntimeError(f"the group did not start: {self.log.read_text()[-2000:]}")
            time.sleep(0.5)

    def train(self, args: argparse.Namespace, seed: int, run: Path) -> tuple:
        """Train ``seed`` with ``--server``; (``time.time()`` at the command's start, seconds
        to its exit)."""
        env = {**self.env, "MJX_ARM_SERVER": str(self.path)}
        start = time.time()
        done = subprocess.run(
            [*_train_argv(args, seed, run), "--server"],
            env=env,
            capture_output=True,
            text=True,
            timeout=TIMEOUT_S,
        )
        if done.returncode or "no warm trainer" in done.stderr or "cannot take" in done.stderr:
            raise RuntimeError(f"seed {seed} in the group: {done.stderr[-2000:]}")
        return start, time.time() - start

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)  # the group stops with its front
        self.proc.wait(timeout=120)


def _row(kind: str, seed: int, timed: tuple[float, float], run: Path) -> dict:
    """A run's figures: its wall time (``timed``: its start and seconds) and what its compile
    report says of its start (``before_training_s``: from the command's start to the
    trainer's)."""
    report = json.loads((run / "compile.json").read_text())[-1]
    start, wall = timed
    return {
        "kind": kind,
        "seed": seed,
        "wall_s": wall,
        "compile_s": report.get("compile_s"),
        "before_training_s": report["opened_at"] - start,
        "kept_warm": report.get("kept_warm", []),
    }


def run(args: argparse.Namespace) -> dict:
    """Every seed in new processes and in the group, taking turns; the rows and a summary."""
    from mjx_arm.train.launch import visible_gpus
    from mjx_arm.train.repeat import compare_runs

    on_gpus = len(visible_gpus()) >= 2
    folder = Path(args.work or tempfile.mkdtemp(prefix="bench_group_"))
    folder.mkdir(parents=True, exist_ok=True)
    group = _Group(folder, on_gpus)
    rows, same = [], []
    try:
        first, seed = folder / "group_first", args.seeds[0]
        rows.append(_row("group, first command", seed, group.train(args, seed, first), first))
        for seed in args.seeds:
            alone, warm = folder / f"processes_{seed}", folder / f"group_{seed}"
            rows.append(_row("processes", seed, _processes(args, seed, alone, on_gpus), alone))
            rows.append(_row("group, warm", seed, group.train(args, seed, warm), warm))
            same.append(compare_runs(alone, warm).identical)
            print(
                f"seed {seed}: {rows[-2]['wall_s']:.1f} s in new processes, "
                f"{rows[-1]['wall_s']:.1f} s in the warm group",
                flush=True,
            )
    finally:
        group.stop()
    return {"on_gpus": on_gpus, "rows": rows, "identical": same, "summary": _summary(rows)}


def _summary(rows: list[dict]) -> dict:
    """Medians of each kind's wall time and start, and the warm group's share of new processes'."""
    out = {}
    for kind in ("processes", "group, warm", "group, first command"):
        mine = [r for r in rows if r["kind"] == kind]
        out[kind] = {
            "runs": len(mine),
            "median_wall_s": statistics.median(r["wall_s"] for r in mine),
            "median_before_training_s": statistics.median(r["before_training_s"] for r in mine),
            "median_compile_s": statistics.median(r["compile_s"] for r in mine),
        }
    out["warm_over_processes"] = (
        out["group, warm"]["median_wall_s"] / out["processes"]["median_wall_s"]
    )
    return out


def _table(result: dict) -> str:
    rows = [
        [
            kind,
            str(v["runs"]),
            f"{v['median_wall_s']:.1f}",
            f"{v['median_before_training_s']:.2f}",
            f"{v['median_compile_s']:.2f}",
        ]
        for kind, v in result["summary"].items()
        if isinstance(v, dict)
    ]
    head = ["how", "runs", "median s, start to exit", "of it before the trainer", "compile s"]
    ratio = result["summary"]["warm_over_processes"]
    same = sum(result["identical"])
    return (
        markdown_table(head, rows)
        + f"\nwarm group / new processes: {ratio:.2f}x; the two runs of a seed identical, bit "
        f"for bit: {same} of {len(result['identical'])}\n"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="reach")
    parser.add_argument("--preset", default="cpu")
    parser.add_argument(
        "--set", nargs="*", help="the run's settings (default: a tiny CPU run; - for none)"
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[1000, 1001, 1002])
    parser.add_argument("--work", help="where the runs go (default: a new temporary folder)")
    parser.add_argument("--name", default="server_group_reach_tiny")
    parser.add_argument("--results-dir", type=Path, default=RESULTS)
    args = parser.parse_args()
    result = run(args)
    accelerator = bool(result["on_gpus"])
    settings = {"task": args.task, "preset": args.preset, "set": args.set or TINY, "devices": 2}
    payload = {"meta": environment_metadata(accelerator=accelerator), "settings": settings}
    table = _table(result)
    print(table)
    paths = save_results(args.name, {**payload, **result}, table, args.results_dir)
    print(f"saved {paths[0]}")


if __name__ == "__main__":
    main()
