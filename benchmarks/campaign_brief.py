"""One line per seed run of a ``gpu_suite.sh campaign``: where each seed stands.

Reads every campaign folder under WORK (``NAME/*-seedN/metrics.csv``) and prints, per run, its
best and last evaluated success, the env steps of its first evaluation at the threshold, and,
for a Touch seed that has not reached it, the trap its last evaluation shows
(:func:`benchmarks.training_diagnosis.trap`). A run that ended before its budget without
reaching the threshold (the call's deadline stopped it) says so and is left out of its
campaign's count. Printed at the end of a campaign, so that the next call can be chosen at once.

    python -m benchmarks.campaign_brief runs/gpu_suite [--threshold 0.95]

Without ``--threshold`` each run counts as solved where its task does (``Task.solved_at``: 0.95,
Lift 0.9), read from its ``config.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.training_diagnosis import (
    SEED_DIR,
    _col,
    _rows,
    evaluated_rows,
    short_of_budget,
    trap,
)
from mjx_arm.task.registry import get_task
from mjx_arm.task.spec import Task

STATES = ("solved", "unsolved", "stopped")


def brief(run: Path, threshold: float) -> tuple[str, str]:
    """``campaign/run: best B last L``, then the steps at the threshold or the trap, of one
    seed run; and where it stands: "solved", "unsolved" (its budget spent) or "stopped"."""
    rows = _rows(run)
    steps = f"{rows[-1]['step'] / 1e6:.1f}M steps" if rows else "0 steps"
    evaluated = evaluated_rows(rows)
    if not evaluated:
        return f"{run.parent.name}/{run.name}: no evaluation yet (stopped at {steps})", "stopped"
    success = _col(evaluated, "eval/episode_success")
    hit = next((r for r in evaluated if r["eval/episode_success"] >= threshold), None)
    text = f"{run.parent.name}/{run.name}: best {success.max():.3f} last {success[-1]:.3f}"
    if hit is not None:
        return f"{text} solved at {hit['step'] / 1e6:.1f}M steps", "solved"
    config = run / "config.json"
    train = json.loads(config.read_text()).get("train", {}) if config.is_file() else {}
    last = trap(evaluated[-1])
    if short_of_budget(train, rows[-1]["step"]):
        return f"{text} stopped at {steps}, before its budget (so far {last})", "stopped"
    return f"{text} unsolved at {steps} ({last})", "unsolved"


def run_threshold(run: Path, given: float | None) -> float:
    """``given``, or where the run's task counts as solved (its ``config.json``; a task's
    default ``solved_at`` when the file or its task cannot be read)."""
    if given is not None:
        return given
    config = run / "config.json"
    try:
        return get_task(json.loads(config.read_text())["train"]["task"]).solved_at
    except (OSError, ValueError, KeyError, TypeError):
        return Task.solved_at


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("work", type=Path, help="the campaign's WORK folder")
    parser.add_argument("--threshold", type=float, default=None, help="default: the task's")
    args = parser.parse_args(argv)
    runs = sorted(args.work.glob("*/*"), key=lambda p: (p.parent.name, p.name))
    counts: dict[str, dict[str, float]] = {}
    for run in runs:
        if SEED_DIR.search(run.name) and (run / "metrics.csv").is_file():
            threshold = run_threshold(run, args.threshold)
            line, state = brief(run, threshold)
            print(line)
            count = counts.setdefault(run.parent.name, {**dict.fromkeys(STATES, 0), "at": 0})
            count[state] += 1
            count["at"] = threshold
    for name, count in counts.items():
        finished = count["solved"] + count["unsolved"]
        stopped = f" ({count['stopped']} stopped, left out)" if count["stopped"] else ""
        print(f"{name}: {count['solved']} of {finished} at {count['at']:g}{stopped}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
