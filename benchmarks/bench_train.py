"""Time to solve: wall-clock from the command start to evaluation success >= 95%.

Trains each task with a preset and reads the run's ``metrics.csv``: the first evaluation whose
``eval/episode_success`` reaches the threshold gives the time to solve, measured from the start of
this script (imports included). Compile time (first training epoch minus its steady share) and
steady training throughput are reported apart. ``--devices N`` trains on N local devices,
for the 1-vs-2 GPU scaling measurement::

    python benchmarks/bench_train.py --tasks reach touch --preset fast --cold
    python benchmarks/bench_train.py --tasks reach --preset fast --set physics.impl=jax

``--cold`` points JAX's persistent compilation cache, Warp's kernel cache and the CUDA driver's
JIT cache at new, empty folders, so the time includes every compilation, as on a fresh machine
(for the later tasks of one run, the caches hold what the earlier ones compiled).
"""

from __future__ import annotations

import time

START = time.time()

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import (  # noqa: E402
    RESULTS_DIR,
    empty_cache_env,
    environment_metadata,
    markdown_table,
    save_results,
)

THRESHOLD = 0.95
# Goals on one H200 from a cold cache: seconds to 95% success and Brax training steps/s.
GOALS_H200 = {"reach_s": 45, "touch_s": 90, "reach_training_sps": 1.0e6, "touch_training_sps": 8e5}


def solve_time(run_dir: Path, start: float) -> tuple[float | None, int | None, float]:
    """(seconds to the first eval >= THRESHOLD, its step, best success) from metrics.csv."""
    from mjx_arm.train.rundir import RunDir

    best, hit = 0.0, None
    for row in RunDir(run_dir).read_metrics():
        success = row.get("eval/episode_success", 0.0)
        best = max(best, success)
        if hit is None and success >= THRESHOLD:
            hit = (row["time"] - start, int(row["step"]))
    return (hit[0], hit[1], best) if hit else (None, None, best)


def brax_training_sps(run_dir: Path) -> float | None:
    """Median of Brax's ``training/sps`` (rollout + update, evaluation excluded), first epoch
    (which carries the compilation) left out."""
    import statistics

    from mjx_arm.train.rundir import RunDir

    values = [
        r["training/sps"]
        for r in RunDir(run_dir).read_metrics()[2:]
        if r.get("training/sps", 0) > 0
    ]
    return statistics.median(values) if values else None


def run_task(task: str, args: argparse.Namespace, start: float) -> dict:
    """Train one task and return its timings."""
    from mjx_arm.train.ppo import train
    from mjx_arm.train.presets import load_config
    from mjx_arm.train.rundir import RunDir

    overrides = [f"task={task}", f"backend={args.backend}", *args.set]
    if args.devices:
        overrides.append(f"devices={args.devices}")
    config = load_config(args.preset, None, overrides)
    run_dir = args.out / f"{task}-{args.preset}-{int(time.time())}"
    result = train(config, run_dir, quiet=True)
    seconds, step, best = solve_time(run_dir, start)
    resolved = RunDir(run_dir).load_config().get("physics_resolved", {})
    return {
        "task": task,
        "preset": args.preset,
        "impl": resolved.get("impl"),
        "physics": resolved,
        "cold_cache": args.cold,
        "config": config.to_dict(),
        "time_to_solve_s": seconds,
        "solve_step": step,
        "best_success": best,
        "final_success": result.metrics.get("eval/episode_success"),
        "compile_s": result.compile_seconds,
        "train_s": result.train_seconds,
        "steady_steps_per_s": result.steps_per_second,
        "training_steps_per_s": brax_training_sps(run_dir),
        "total_steps": result.steps,
        "run_dir": str(run_dir),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["reach", "touch"])
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--backend", default="auto")
    parser.add_argument("--devices", type=int, default=0, help="train on N devices (0: all)")
    parser.add_argument("--set", nargs="*", default=[], help="config overrides key=value")
    parser.add_argument("--out", type=Path, default=Path("runs/bench"))
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "train")
    parser.add_argument("--name", default=None)
    parser.add_argument("--cold", action="store_true", help="empty compilation caches")
    args = parser.parse_args()
    if args.cold:
        import os

        os.environ.update(empty_cache_env())

    import jax

    from mjx_arm.jax_cache import enable_compilation_cache

    enable_compilation_cache()
    rows = []
    for task in args.tasks:
        start = START if not rows else time.time()  # each task timed from its own start
        row = run_task(task, args, start)
        rows.append(row)
        print({k: v for k, v in row.items() if k != "config"}, flush=True)
    meta = environment_metadata(accelerator=True)
    meta["devices_used"] = args.devices or jax.local_device_count()
    headers = [
        "task",
        "impl",
        "time to 95% (s)",
        "solve step",
        "best success",
        "compile (s)",
        "steps/s with evals",
        "training steps/s",
        "train (s)",
    ]
    table = markdown_table(
        headers,
        [
            [
                r["task"],
                r["impl"],
                f"{r['time_to_solve_s']:.1f}"
                if r["time_to_solve_s"] is not None
                else "not reached",
                r["solve_step"],
                f"{r['best_success']:.3f}",
                f"{r['compile_s']:.1f}",
                f"{r['steady_steps_per_s']:,.0f}",
                f"{r['training_steps_per_s'] or float('nan'):,.0f}",
                f"{r['train_s']:.1f}",
            ]
            for r in rows
        ],
    )
    print(table)
    name = args.name or f"train_{args.preset}_{meta['device']['kind'].replace(' ', '_')}"
    save_results(
        name,
        {"meta": meta, "rows": rows, "threshold": THRESHOLD, "goals_h200": GOALS_H200},
        table,
        args.results_dir,
    )


if __name__ == "__main__":
    main()
