"""A task's ``eval_from_step``, derived from seeds reports of its tuning seeds.

``eval_from_step`` (``mjx_arm.train.config.TrainConfig``) skips the evaluations of the initial
policy and of the epochs that end before it. Training is the same with or without them, so the
value trades time (each evaluation skipped) against lateness (a run that would have reached the
threshold at a skipped evaluation is only seen solved at the first kept one). The rule, applied
to reports whose runs were evaluated at every epoch:

- find the earliest step at which any tuning run reached the threshold, at epoch ``k``;
- keep the epoch before it evaluated (``k - 1``), as a margin for seeds that learn sooner;
- choose the roundest step (one significant digit, else two) after epoch ``k - 2`` and at or
  before epoch ``k - 1``.

It prints the choice, the best success any run had logged before the first kept evaluation
(how far from the threshold the skipped evaluations were), and the evaluations each run would
have skipped. Only tuning seeds (1000-1099) may be given: a value chosen on the seeds it is
reported on proves nothing.

    python -m benchmarks.choose_eval_from_step \\
        benchmarks/results/seeds/tuning/seeds_touch_fast_tuning_nopay.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

TUNING = range(1000, 1100)


def _curves(reports: list[dict[str, Any]]) -> tuple[dict[int, list[tuple[int, float]]], float]:
    """Each tuning seed's evaluations ``[(step, success), ...]`` in step order, and the
    threshold the reports share."""
    thresholds = {report["summary"]["threshold"] for report in reports}
    if len(thresholds) != 1:
        raise SystemExit(f"the reports count a seed solved at different levels: {thresholds}")
    curves = {}
    for report in reports:
        for run in report["seeds"]:
            if run["seed"] not in TUNING:
                raise SystemExit(f"seed {run['seed']} is not a tuning seed (1000-1099)")
            curves[run["seed"]] = sorted((int(step), success) for _, step, success in run["curve"])
    return curves, thresholds.pop()


def round_step(low: int, high: int) -> int:
    """The roundest step in ``(low, high]``: ``high`` rounded down to one significant digit,
    else two, else ``high``."""
    for digits in (1, 2):
        scale = 10 ** max(int(math.log10(high)) - digits + 1, 0)
        value = high // scale * scale
        if value > low:
            return value
    return high


def choose(curves: dict[int, list[tuple[int, float]]], threshold: float) -> dict[str, Any]:
    """The rule of the module docstring over ``curves`` (seed -> evaluations in step order,
    each run evaluated at every epoch from step 0)."""
    solves = {
        seed: next((step for step, s in curve if s >= threshold), None)
        for seed, curve in curves.items()
    }
    earliest = min((step for step in solves.values() if step is not None), default=None)
    if earliest is None:
        raise SystemExit(f"no run reached {threshold}: nothing to choose from")
    epochs = sorted({step for curve in curves.values() for step, _ in curve})
    k = epochs.index(earliest)
    if k < 2:
        return {"eval_from_step": 0, "earliest_solve": earliest, "why": "solved too early"}
    kept = epochs[k - 1]
    value = round_step(epochs[k - 2], kept)
    before = [s for curve in curves.values() for step, s in curve if step < kept]
    return {
        "eval_from_step": value,
        "threshold": threshold,
        "earliest_solve": earliest,
        "first_kept_evaluation": kept,
        "best_success_before_it": max(before),
        "evaluations_skipped_per_run": sum(1 for step in epochs if step < value),
        "runs": len(curves),
        "solved": sum(step is not None for step in solves.values()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reports", nargs="+", type=Path, help="seeds reports of tuning seeds")
    args = parser.parse_args(argv)
    reports = [json.loads(path.read_text()) for path in args.reports]
    result = choose(*_curves(reports))
    for key, value in result.items():
        print(f"{key}: {value:,}" if isinstance(value, int) else f"{key}: {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
