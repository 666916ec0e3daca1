"""The report of a ``bench seeds`` that was stopped before it wrote one, from its runs and log.

``gpu_suite.sh campaign`` stops every line at its deadline; a ``bench seeds`` stopped there
before it wrote its report after each seed (``pending_seeds``) left its seeds' run directories
and its log, but no ``NAME.json``. This rebuilds that report
(the same summary: solve rate with its 95 % interval, times, steps, collapses) from them:

- each seed's curve comes from its ``metrics.csv``;
- its start is where its logged time to the threshold puts it (the log's ``seed S: ...
  0.95 at T s`` line); a seed that did not reach the threshold starts its group's median
  first-evaluation delay before its first evaluation (``start_estimated`` in the record);
- a seed that was still training when the deadline came is left out of the report (it has
  neither reached the threshold nor spent its budget); the record names it, with its best
  success and steps so far, under ``meta.stopped_at_deadline``;
- a finished seed's final success is its best evaluation where the run kept its best
  (``keep_best``: what the final checkpoint holds; the checkpoints are not read), else its
  last;
- the machine's record (device, packages) is taken from a report of the same call.

Several folders (each with its log, in the same order) make one report: the lines of a
campaign that ran the same settings on different GPUs at once.

    python -m benchmarks.seeds_from_runs runs/fresh_0 runs/fresh_1 \\
        --logs runs/fresh_0.log runs/fresh_1.log --meta-from a_report_of_the_call.json \\
        --name seeds_touch_fast_fresh --out DIR
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
from pathlib import Path

from benchmarks.training_diagnosis import SEED_DIR
from mjx_arm.bench.seeds import read_curve, read_seed_run
from mjx_arm.bench.seeds_config import SeedsConfig
from mjx_arm.bench.seeds_report import write_report

LOGGED = re.compile(r"^seed (?P<seed>\d+): final .*?at (?:(?P<t>[\d.]+) s|not reached)", re.M)


def logged_times(log: str) -> dict[int, float | None]:
    """Seed -> its logged time to the threshold (s; None: not reached), for finished seeds."""
    return {int(m["seed"]): float(m["t"]) if m["t"] else None for m in LOGGED.finditer(log)}


def rebuild(folder: Path, log: str, config: SeedsConfig) -> tuple[list, list, dict, dict]:
    """The finished seed runs, their saved configs, per-seed notes, and the seeds stopped at
    the deadline (seed -> best success and steps so far), seeds in order."""
    times = logged_times(log)
    runs = sorted(
        (int(SEED_DIR.search(p.name)["seed"]), p, read_curve(p, 0.0))
        for p in folder.iterdir()
        if p.is_dir() and SEED_DIR.search(p.name) and (p / "metrics.csv").is_file()
    )
    starts, delays = {}, []
    for seed, _, curve in runs:
        hit = next((t for t, _, s in curve if s >= config.threshold), None)
        if times.get(seed) is not None and hit is not None:
            starts[seed] = hit - times[seed]
            delays.append(curve[0][0] - starts[seed])
    delay = statistics.median(delays) if delays else 0.0
    seeds, configs, notes, stopped = [], [], {}, {}
    for seed, run, curve in runs:
        if seed not in times:
            stopped[seed] = {"best_success": max(s for _, _, s in curve), "steps": curve[-1][1]}
            continue
        start = starts.get(seed, curve[0][0] - delay)
        record = read_seed_run(config, seed, run, start, curve[-1][0])
        saved = json.loads((run / "config.json").read_text())
        if saved["train"].get("keep_best", False):
            record.final_success = record.best_success
        seeds.append(record)
        configs.append(saved)
        notes[seed] = {"start_estimated": seed not in starts}
    return seeds, configs, notes, stopped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+", help="the benches' --runs folders")
    parser.add_argument("--logs", type=Path, nargs="+", required=True, help="their outputs")
    parser.add_argument("--meta-from", type=Path, required=True, help="a report of the call")
    parser.add_argument("--task", default="touch")
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--arm", default="")
    parser.add_argument("--threshold", type=float, default=0.95)
    parser.add_argument("--set", nargs="*", default=[], help="the bench's --set items")
    parser.add_argument("--name", required=True)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    if len(args.logs) != len(args.folders):
        parser.error("give one --logs file per folder")
    base = SeedsConfig(task=args.task, preset=args.preset, arm=args.arm, threshold=args.threshold)
    seeds, configs, notes, stopped = [], [], {}, {}
    for folder, log in zip(args.folders, args.logs, strict=True):
        more = rebuild(folder, log.read_text(), base)
        seeds += more[0]
        configs += more[1]
        notes |= more[2]
        stopped |= more[3]
    config = SeedsConfig(
        task=args.task,
        preset=args.preset,
        arm=args.arm,
        threshold=args.threshold,
        seeds=",".join(str(r.seed) for r in seeds),
    )
    meta = json.loads(args.meta_from.read_text())["meta"]
    meta = {
        **meta,
        "rebuilt_from_runs": {str(k): v for k, v in notes.items()},
        "stopped_at_deadline": {str(k): v for k, v in stopped.items()},
    }
    for path in write_report(config, seeds, configs, meta, args.out, args.name, tuple(args.set)):
        print(path)
    for seed, what in stopped.items():
        print(f"seed {seed} stopped at the deadline, left out: {what}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
