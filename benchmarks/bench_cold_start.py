"""Cold and warm starts of training, stage by stage, each in a new process.

For every task on its shipped arm (Reach and Touch on the shipped arm, Lift on the gripper arm,
as the presets choose) and for an arm given with ``--arm`` (a URDF with mesh collisions, say),
each start is a new process that trains the preset (``mjx_arm.train.ppo.train``) and reports
where its seconds went (:mod:`mjx_arm.train.compile_report`: model conversion, MuJoCo Warp's
kernels, tracing, the XLA compiles of the reset, training epoch and evaluation, the first
runs) with JAX's persistent-cache counts:

* ``cold``: every compilation cache empty (JAX, Warp's kernels, the CUDA driver's), in new
  temporary folders;
* ``warm``: the same task again in a new process with the caches the cold start filled;
* ``second task``: ``--arm`` only: the arm's next task in a new process with the caches of its
  first task (what a user pays for trying a second task on a new arm);
* ``after warmup``: ``mjx-arm warmup`` in a process with empty caches, then a new process that
  trains (``--warmup-task``).

By default each process stops after its first trained epoch (``train(stop_after=1)``: the
programs are the full run's). ``--to-threshold`` trains each cold and warm start to the
preset's stop (and reads the time from the command's start to ``--threshold``).

On a CPU (MJX on its JAX implementation; ``tiny`` is the CPU preset cut down to a few envs)::

    python benchmarks/bench_cold_start.py --preset tiny --backend mjx \\
        --arm $ROBOTS/ur_description/urdf/ur5_robot.urdf

On a GPU (``benchmarks/gpu_suite.sh cold``)::

    python benchmarks/bench_cold_start.py --preset fast --tasks touch --to-threshold
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import (
    RESULTS_DIR,
    empty_cache_env,
    environment_metadata,
    markdown_table,
    save_results,
)

RESULTS = RESULTS_DIR / "cold_start"
# The CPU preset cut down so that a start is mostly compilation: 16 envs, short rollouts.
TINY = (
    "num_envs=16",
    "batch_size=16",
    "num_minibatches=2",
    "unroll_length=4",
    "num_updates_per_batch=1",
    "num_eval_envs=16",
    "num_evals=3",
    "num_timesteps=2000",
)


# --------------------------------------------------------------------------- child


def _child(args: argparse.Namespace) -> dict:
    """Train in this (fresh) process; the start's stages and times (s from ``--t0``)."""
    from mjx_arm.jax_cache import enable_compilation_cache

    enable_compilation_cache()
    from mjx_arm.bench.seeds import first_at, read_curve
    from mjx_arm.train.ppo import train

    config = _config(args.preset, args.task, args.backend, args.arm, args.set)
    imported = time.time() - args.t0
    run_dir = Path(args.run_dir or tempfile.mkdtemp(prefix="cold_start_run_")) / "run"
    stop_after = 0 if args.to_threshold else 1
    result = train(config, run_dir, quiet=True, stop_after=stop_after)
    curve = read_curve(run_dir, args.t0)  # (s from the command's start, step, success)
    trained = [t for t, step, _ in curve if step > 0]
    hit = first_at(curve, args.threshold)
    row = {
        "imports_s": imported,
        "compile_s": result.compile_seconds,
        "first_epoch_done_s": trained[0] if trained else None,
        "time_to_threshold_s": hit[0] if hit else None,
        "final_success": result.metrics.get("eval/episode_success"),
        "steps": result.steps,
        "total_s": time.time() - args.t0,
        **result.compile_report,
    }
    physics = json.loads((run_dir / "config.json").read_text()).get("physics_resolved", {})
    row["physics"] = physics
    if physics.get("impl") == "warp":
        from mjx_arm.envs import warp_compile

        row["warp_modules_loaded"] = sorted(warp_compile.loaded_modules())
    return row


def _config(preset: str, task: str, backend: str, arm: str, sets: list[str]):
    """The training config of a start (``tiny``: the CPU preset with :data:`TINY`)."""
    from mjx_arm.arm.config import load_arm
    from mjx_arm.train.presets import load_config

    items = [f"task={task}", f"backend={backend}"]
    if preset == "tiny":
        items += list(TINY)
    config = load_config("cpu" if preset == "tiny" else preset, None, [*items, *sets])
    return config.replace(arm=load_arm(arm)) if arm else config


# --------------------------------------------------------------------------- parent


def _start(args: argparse.Namespace, task: str, arm: str, caches: dict, label: str) -> dict:
    """One start in a new process with the cache folders ``caches``; its row."""
    env = {**os.environ, **caches, "PYTHONUNBUFFERED": "1"}
    run_dir = Path(tempfile.mkdtemp(prefix="cold_start_run_"))
    t0 = time.time()
    cmd = [sys.executable, __file__, "--child", "--t0", repr(t0), "--task", task]
    cmd += ["--run-dir", str(run_dir)]
    cmd += ["--preset", args.preset, "--backend", args.backend, "--arm", arm or ""]
    cmd += ["--threshold", str(args.threshold), "--set", *args.set]
    if args.to_threshold and label in ("cold", "warm"):
        cmd.append("--to-threshold")
    row = {"task": task, "arm": Path(arm).stem if arm else "shipped", "start": label}
    try:
        proc = subprocess.run(
            cmd, capture_output=True, text=True, env=env, timeout=args.child_timeout
        )
    except subprocess.TimeoutExpired:
        row = {**row, "error": f"over {args.child_timeout} s", "wall_s": time.time() - t0}
        return {**row, **_curve_times(run_dir / "run", t0, args.threshold)}
    if proc.returncode != 0:
        print(proc.stderr[-3000:], file=sys.stderr)
        return {**row, "error": proc.stderr[-800:], "wall_s": time.time() - t0}
    return {**row, "wall_s": time.time() - t0, **json.loads(proc.stdout.strip().splitlines()[-1])}


def _curve_times(run_dir: Path, t0: float, threshold: float) -> dict:
    """What a stopped start's metrics.csv shows: its first trained evaluation and the time to
    ``threshold`` (s from ``t0``), where it got that far."""
    from mjx_arm.bench.seeds import first_at, read_curve

    if not (run_dir / "metrics.csv").is_file():
        return {}
    curve = read_curve(run_dir, t0)
    trained = [t for t, step, _ in curve if step > 0]
    hit = first_at(curve, threshold)
    best = max((v for _, _, v in curve), default=None)
    return {
        "first_epoch_done_s": trained[0] if trained else None,
        "time_to_threshold_s": hit[0] if hit else None,
        "best_success": best,
    }


def _warmup(args: argparse.Namespace, task: str, arm: str, caches: dict) -> dict:
    """``mjx-arm warmup`` for ``task`` in a new process filling ``caches``; its row."""
    env = {**os.environ, **caches, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "mjx_arm.cli", "warmup", "--task", task, "--quiet"]
    cmd += ["--backend", args.backend, "--preset", "cpu" if args.preset == "tiny" else args.preset]
    sets = [*(TINY if args.preset == "tiny" else ()), *args.set]
    cmd += ["--set", *sets] if sets else []
    cmd += ["--arm", arm] if arm else []
    t0 = time.time()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=args.child_timeout)
    row = {"task": task, "arm": Path(arm).stem if arm else "shipped", "start": "warmup command"}
    row["wall_s"] = time.time() - t0
    row["output"] = proc.stdout[-2000:]
    if proc.returncode != 0:
        row["error"] = proc.stderr[-800:]
    return row


def _plan(args: argparse.Namespace) -> list[tuple[str, str, str, str]]:
    """The starts in order: (label, task, arm, cache set), a new cache set per cold start."""
    plan = []
    for task in args.tasks:
        plan += [("cold", task, "", task), ("warm", task, "", task)]
    if args.arm:
        first, *rest = args.arm_tasks
        plan.append(("cold", first, args.arm, "arm"))
        plan += [("second task", task, args.arm, "arm") for task in rest]
        plan.append(("warm", first, args.arm, "arm"))
    if args.warmup_task:
        plan += [("warmup", args.warmup_task, "", "warmup")]
        plan += [("after warmup", args.warmup_task, "", "warmup")]
    return plan


def run_all(args: argparse.Namespace, save=None) -> list[dict]:
    """Every start of :func:`_plan`, printed as it ends; ``save(rows)`` after each."""
    caches: dict[str, dict] = {}
    rows = []
    for label, task, arm, cache_set in _plan(args):
        if cache_set not in caches:
            caches[cache_set] = empty_cache_env()
        if label == "warmup":
            row = _warmup(args, task, arm, caches[cache_set])
        else:
            row = _start(args, task, arm, caches[cache_set], label)
        rows.append(row)
        brief = {k: v for k, v in row.items() if k not in ("output", "slowest_programs")}
        print(json.dumps(brief, default=str), flush=True)
        if save is not None:
            save(rows)
    return rows


def _s(value) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.1f}"


def table(rows: list[dict]) -> str:
    """One line per start: its stages (s) and the JAX cache's hits."""
    head = ["task", "arm", "start", "imports", "build env", "learner init", "trace + lower"]
    head += ["XLA compile", "Warp kernels", "first reset", "first eval", "first epoch"]
    head += ["first epoch done", "compile (s)", "to threshold", "cache hits", "wall (s)"]
    body = []
    for r in rows:
        stages = r.get("stages", {})
        counts = r.get("jax_counts", {})
        cells = [r["task"], r["arm"], r["start"]]
        if "error" in r:  # a start that failed or ran over its time: what its metrics show
            times = [_s(r.get("first_epoch_done_s")), "-", _s(r.get("time_to_threshold_s"))]
            body.append([*cells, *["error"] * 9, *times, "-", _s(r.get("wall_s"))])
            continue
        if r["start"] == "warmup command":
            body.append([*cells, *["-"] * (len(head) - 4), _s(r.get("wall_s"))])
            continue
        cells += [_s(r.get("imports_s"))]
        for name in ("build env", "learner init", "trace + lower", "XLA compile (in parallel)"):
            cells.append(_s(stages.get(name)))
        cells.append(_s(stages.get("Warp kernels")))
        for name in ("first reset run", "first evaluation run", "first epoch run"):
            cells.append(_s(stages.get(name)))
        cells += [_s(r.get("first_epoch_done_s")), _s(r.get("compile_s"))]
        cells.append(_s(r.get("time_to_threshold_s")))
        cells.append(f"{counts.get('cache_hits', 0)}/{counts.get('cache_requests', 0)}")
        cells.append(_s(r.get("wall_s")))
        body.append(cells)
    return markdown_table(head, body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="tiny", choices=["tiny", "cpu", "fast", "seed"])
    parser.add_argument("--backend", default="mjx", choices=["auto", "mjx", "mujoco"])
    parser.add_argument("--tasks", nargs="*", default=["reach", "touch", "lift"])
    parser.add_argument("--arm", default="", help="a URDF or arm file (e.g. with mesh collisions)")
    parser.add_argument("--arm-tasks", nargs="+", default=["reach", "touch"])
    parser.add_argument("--warmup-task", default="", help="warmup, then train this task")
    parser.add_argument("--set", nargs="*", default=[], help="KEY=VALUE changes to the preset")
    parser.add_argument("--to-threshold", action="store_true", help="train cold/warm to the end")
    parser.add_argument("--threshold", type=float, default=0.95)
    parser.add_argument("--child-timeout", type=float, default=1800.0)
    parser.add_argument("--results-dir", type=Path, default=RESULTS)
    parser.add_argument("--name", default=None, help="result file stem")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--t0", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--task", default="touch", help=argparse.SUPPRESS)
    parser.add_argument("--run-dir", default="", help=argparse.SUPPRESS)  # RUN_DIR/run: the run
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_child(args), default=float))
        return
    start = time.time()
    meta = environment_metadata(accelerator=True)
    name = (
        args.name or f"cold_start_{args.preset}_{meta['device']['kind'].replace(' ', '_').lower()}"
    )
    title = f"# Cold and warm starts, preset {args.preset}, backend {args.backend}, "
    title += f"{meta['device']['kind']}\n\n"

    def save(rows: list[dict]) -> str:
        text = table(rows)
        payload = {"meta": meta, "settings": {k: v for k, v in vars(args).items() if k != "t0"}}
        payload.update(tiny_preset=list(TINY), rows=rows, wall_s=time.time() - start)
        save_results(name, payload, title + text, args.results_dir)
        return text

    print(save(run_all(args, save)))


if __name__ == "__main__":
    main()
