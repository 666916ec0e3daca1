"""Scaling over GPUs: env steps/s at fixed envs per GPU, and time to a solved task.

Each measurement is one ``mjx-arm train`` command, exactly as a user types it: on D GPUs the
launcher starts one process per GPU, joined by jax.distributed (docs/training.md). Times count
from the command's start (process start-up, cache loads and compilation included) to the first
evaluation at the threshold.

    python benchmarks/bench_scaling.py throughput --devices 1 2 4 --envs-per-gpu 8192 \\
        --out benchmarks/results/scaling --name scaling_throughput_touch
    python benchmarks/bench_scaling.py solve --devices 1 2 4 --seeds 0-2 \\
        --out benchmarks/results/scaling --name scaling_solve_touch [--set KEY=VALUE ...]

``throughput`` grows the batch with the GPUs (``num_envs`` and ``batch_size`` times D, the same
minibatch count) and reports the steady env steps/s of the epochs after the first, with each
epoch's seconds in the rollout and in the PPO update. ``solve`` trains the preset as shipped
(``--devices D`` splits the same global batch over D GPUs) unless ``--set`` or
``--per-gpu-minibatches`` says otherwise, and reports the time to the threshold per seed and its
median per device count, beside the ratio to one GPU.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results
from mjx_arm.bench.seeds import parse_seeds
from mjx_arm.train.rundir import RunDir

SUCCESS = "eval/episode_success"


def train(devices: int, sets: list[str], run_dir: Path, task: str, preset: str, limit: float):
    """Run one ``mjx-arm train`` on ``devices`` GPUs; (wall seconds, exit code, start time)."""
    command = [sys.executable, "-m", "mjx_arm.cli", "train", "--task", task, "--preset", preset]
    command += ["--devices", str(devices), "--run-dir", str(run_dir), "--quiet"]
    command += ["--set", *sets] if sets else []
    print(" ".join(command[2:]), flush=True)
    start = time.time()
    try:
        code = subprocess.run(command, timeout=limit).returncode
    except subprocess.TimeoutExpired:
        code = -1
    return time.time() - start, code, start


def run_record(run_dir: Path, start: float, wall: float, code: int) -> dict[str, Any]:
    """What a finished run's folder says: its curve, steady speed, seconds per program."""
    rows = RunDir(run_dir).read_metrics() if (run_dir / "metrics.csv").is_file() else []
    trained = [r for r in rows if "training/sps" in r and math.isfinite(r["training/sps"])]
    steady = trained[1:] or trained
    compile_path = run_dir / "compile.json"
    starts = json.loads(compile_path.read_text()) if compile_path.is_file() else []

    def median(key: str) -> float:
        values = [r[key] for r in steady if math.isfinite(r.get(key, math.nan))]
        return statistics.median(values) if values else math.nan

    return {
        "exit_code": code,
        "wall_s": wall,
        "curve": [(r["time"] - start, int(r["step"]), r.get(SUCCESS, math.nan)) for r in rows],
        "steps_per_s": median("training/sps"),
        "rollout_s_per_epoch": median("training/rollout_s"),
        "update_s_per_epoch": median("training/update_s"),
        "compile_s": starts[-1].get("compile_s", math.nan) if starts else math.nan,
        "stages": starts[-1].get("stages", {}) if starts else {},
    }


def cmd_throughput(args: argparse.Namespace) -> int:
    """Steady env steps/s at ``--envs-per-gpu`` envs on each GPU, per device count."""
    rows, records = [], {}
    per_step = args.envs_per_gpu * 10  # unroll_length of the fast preset
    for d in args.devices:
        steps = args.epochs * args.steps_per_epoch * per_step * d
        sets = [
            f"num_envs={args.envs_per_gpu * d}",
            f"batch_size={256 * d}",
            f"num_timesteps={steps}",
            f"num_evals={args.epochs + 1}",
            "stop_at_success=0",
            *args.set,
        ]
        run_dir = args.runs / f"throughput_{d}gpu"
        wall, code, start = train(d, sets, run_dir, args.task, "fast", args.limit)
        records[d] = {"sets": sets, **run_record(run_dir, start, wall, code)}
    base = records[1]["steps_per_s"] if 1 in records else math.nan  # no 1-GPU run: no ratio
    for d, r in records.items():
        rows.append(
            [
                d,
                args.envs_per_gpu * d,
                f"{r['steps_per_s']:,.0f}",
                f"{r['steps_per_s'] / base:.2f}x" if math.isfinite(base) else "-",
                f"{r['rollout_s_per_epoch']:.2f}",
                f"{r['update_s_per_epoch']:.2f}",
                f"{r['compile_s']:.1f}",
                r["exit_code"],
            ]
        )
    headers = [
        "GPUs",
        "envs",
        "env steps/s",
        "vs 1 GPU",
        "rollout s/epoch",
        "update s/epoch",
        "compile (s)",
        "exit",
    ]
    table = markdown_table(headers, rows)
    payload = {"meta": environment_metadata(accelerator=True), "settings": vars_of(args)}
    payload["runs"] = {str(d): r for d, r in records.items()}
    save_results(args.name, payload, f"# Throughput over GPUs: {args.task}\n\n{table}", args.out)
    print(table)
    return 0


def _time_or_inf(record: dict[str, Any]) -> float:
    t = record["time_to_threshold"]
    return math.inf if t is None else t


def first_at(curve: list, threshold: float) -> float | None:
    return next((t for t, _, v in curve if v >= threshold), None)


def cmd_solve(args: argparse.Namespace) -> int:
    """Time to the threshold per seed and device count (``--append``: beside the device counts
    of an earlier run of the same name, e.g. one measured in an earlier command)."""
    records: dict[int, list[dict[str, Any]]] = {}
    earlier = args.out / f"{args.name}.json"
    if args.append and earlier.is_file():
        runs = json.loads(earlier.read_text())["runs"]
        records = {int(d): r for d, r in runs.items() if int(d) not in args.devices}
    for d in args.devices:
        for seed in parse_seeds(args.seeds):
            sets = [f"seed={seed}", *args.set]
            if args.per_gpu_minibatches:
                sets += [f"num_envs={8192 * d}", f"num_minibatches={32 * d}"]
            run_dir = args.runs / f"solve_{d}gpu_seed{seed}"
            wall, code, start = train(d, sets, run_dir, args.task, args.preset, args.limit)
            record = {"seed": seed, "sets": sets, **run_record(run_dir, start, wall, code)}
            record["time_to_threshold"] = first_at(record["curve"], args.threshold)
            records.setdefault(d, []).append(record)
            print(f"{d} GPU(s), seed {seed}: {record['time_to_threshold']} s", flush=True)
    summary = {}
    for d, runs in records.items():
        times = [_time_or_inf(r) for r in runs]
        summary[d] = {
            "solved": sum(math.isfinite(t) for t in times),
            "seeds": len(times),
            "median_s": statistics.median(times),
            "warm_median_s": statistics.median(times[1:]) if len(times) > 1 else math.nan,
            "median_steps_per_s": statistics.median(r["steps_per_s"] for r in runs),
        }
    summary = dict(sorted(summary.items()))
    base = summary[min(summary)]
    rows = [
        [
            d,
            f"{s['solved']} of {s['seeds']}",
            f"{s['median_s']:.1f}",
            f"{base['median_s'] / s['median_s']:.2f}x",
            f"{s['warm_median_s']:.1f}",
            f"{s['median_steps_per_s']:,.0f}",
            ", ".join(
                "-" if r["time_to_threshold"] is None else f"{r['time_to_threshold']:.1f}"
                for r in records[d]
            ),
        ]
        for d, s in summary.items()
    ]
    headers = [
        "GPUs",
        f"seeds at {args.threshold}",
        "median time (s)",
        "speed-up",
        "warm median (s)",
        "env steps/s",
        "per seed (s)",
    ]
    table = markdown_table(headers, rows)
    payload = {"meta": environment_metadata(accelerator=True), "settings": vars_of(args)}
    payload.update(summary={str(d): s for d, s in summary.items()}, runs=records)
    title = f"# Time to {args.threshold} over GPUs: {args.task}, preset {args.preset}"
    save_results(args.name, payload, f"{title}\n\n{table}", args.out)
    print(table)
    return 0


def vars_of(args: argparse.Namespace) -> dict[str, Any]:
    return {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items() if k != "func"}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(required=True)
    for name, func in (("throughput", cmd_throughput), ("solve", cmd_solve)):
        p = sub.add_parser(name)
        p.set_defaults(func=func)
        p.add_argument("--devices", type=int, nargs="+", default=[1, 2, 4])
        p.add_argument("--task", default="touch")
        p.add_argument("--set", nargs="*", default=[])
        p.add_argument("--out", type=Path, default=RESULTS_DIR / "scaling")
        p.add_argument("--runs", type=Path, default=Path("runs/scaling"))
        p.add_argument("--name", required=True)
        p.add_argument("--limit", type=float, default=400.0, help="seconds per run at most")
    sub.choices["throughput"].add_argument("--envs-per-gpu", type=int, default=8192)
    sub.choices["throughput"].add_argument("--epochs", type=int, default=4)
    sub.choices["throughput"].add_argument("--steps-per-epoch", type=int, default=10)
    solve = sub.choices["solve"]
    solve.add_argument("--seeds", default="0-2")
    solve.add_argument("--preset", default="fast")
    solve.add_argument("--threshold", type=float, default=0.95)
    solve.add_argument("--append", action="store_true", help="keep other device counts' runs")
    solve.add_argument(
        "--per-gpu-minibatches",
        action="store_true",
        help="8192 envs per GPU and 32 minibatches per GPU (minibatches of the preset's size)",
    )
    args = parser.parse_args()
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
