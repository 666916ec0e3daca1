"""A task's ``eval_gate``, derived from the runs of its tuning seeds.

``eval_gate`` (``mjx_arm.train.config.TrainConfig``) skips the evaluation of an epoch whose
training episodes succeeded at a rate under it (``training/episode_success``), and the initial
policy's. Training is the same with or without the gate, so a run evaluated at every epoch shows
what any gate would have skipped. The rule, over tuning runs that log that rate:

- for each run that reached the threshold, take the training rate of the epoch whose evaluation
  first reached it;
- the gate is half the lowest of them, rounded down to a hundredth: every tuning run would still
  have been evaluated where it solved, with a margin of 2x for seeds whose training rate lags
  their evaluation further.

It prints the gate, the evaluations it would have skipped before each run's solve and the
seconds they took (``eval/epoch_eval_time``); with ``--from-step``, only those at or after the
task's ``eval_from_step`` count (the earlier ones are skipped without the gate). With ``--out``
it also saves the choice and every run's course (step, evaluation, training rate) as JSON.
Only tuning seeds (1000-1099) may be given: a value chosen on the seeds it is reported on
proves nothing.

    python -m benchmarks.choose_eval_gate runs/seeds-lift-fast-20261201/ --from-step 3000000 \
        --out benchmarks/results/diagnosis --name lift_fast_eval_gate_tuning
"""

from __future__ import annotations

import argparse
import math
import statistics
from dataclasses import asdict, dataclass
from pathlib import Path

from benchmarks.common import environment_metadata, markdown_table, save_results
from mjx_arm.train.rundir import RunDir, is_run_dir

TUNING = range(1000, 1100)
RATE, SUCCESS, EVAL_TIME = (
    "training/episode_success",
    "eval/episode_success",
    "eval/epoch_eval_time",
)


@dataclass(frozen=True)
class Evaluation:
    """One evaluated epoch of a run: its step, evaluation success, the training episodes'
    success rate (NaN for the initial policy) and the evaluation's seconds."""

    step: int
    success: float
    rate: float
    seconds: float


def run_dirs(paths: list[Path]) -> list[Path]:
    """The run directories among ``paths`` and directly under them."""
    found = []
    for path in paths:
        found += [path] if is_run_dir(path) else sorted(p for p in path.iterdir() if is_run_dir(p))
    if not found:
        raise SystemExit(f"no run directory in {[str(p) for p in paths]}")
    return found


def read_run(path: Path) -> tuple[int, float, list[Evaluation]]:
    """A run's seed, the success its run stopped at, and its evaluated epochs in step order."""
    run = RunDir(path)
    train = run.load_config()["train"]
    rows = [row for row in run.read_metrics() if math.isfinite(row.get(SUCCESS, math.nan))]
    if rows and not any(RATE in row for row in rows):
        raise SystemExit(f"{path} logs no {RATE}: trained before that metric")
    evaluations = [
        Evaluation(int(r["step"]), r[SUCCESS], r.get(RATE, math.nan), r.get(EVAL_TIME, 0.0))
        for r in rows
    ]
    return int(train["seed"]), float(train["stop_at_success"]), evaluations


def choose(
    runs: dict[int, list[Evaluation]], threshold: float, from_step: int = 0
) -> dict[str, object]:
    """The rule of the module docstring over ``runs`` (seed -> evaluated epochs in order); the
    savings count the evaluations at or after ``from_step`` alone."""
    solves = {
        seed: next((e for e in evals if e.success >= threshold), None)
        for seed, evals in runs.items()
    }
    rates = [e.rate for e in solves.values() if e is not None and math.isfinite(e.rate)]
    if not rates:
        raise SystemExit(f"no run reached {threshold} after its first epoch: nothing to choose")
    gate = math.floor(min(rates) / 2 * 100) / 100
    skipped = {
        seed: [e for e in evals if from_step <= e.step < solves[seed].step and not e.rate >= gate]
        for seed, evals in runs.items()
        if solves[seed] is not None
    }
    seconds = [sum(e.seconds for e in evals) for evals in skipped.values()]
    return {
        "eval_gate": gate,
        "threshold": threshold,
        "from_step": from_step,
        "lowest_rate_at_a_solve": min(rates),
        "evaluations_skipped_per_solved_run": statistics.median(map(len, skipped.values())),
        "seconds_saved_per_solved_run": round(statistics.median(seconds), 2),
        "runs": len(runs),
        "solved": len(skipped),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", type=Path, help="run directories, or their folders")
    parser.add_argument(
        "--threshold", type=float, help="success that counts as solved (default: the runs' stop)"
    )
    parser.add_argument(
        "--from-step", type=int, default=0, help="the task's eval_from_step (default: 0)"
    )
    parser.add_argument("--out", type=Path, help="also save NAME.json and NAME.md here")
    parser.add_argument("--name", default="eval_gate_tuning", help="file stem for --out")
    args = parser.parse_args(argv)
    runs, thresholds = {}, set()
    for path in run_dirs(args.paths):
        seed, threshold, evaluations = read_run(path)
        if seed not in TUNING:
            raise SystemExit(f"seed {seed} ({path}) is not a tuning seed (1000-1099)")
        runs[seed] = evaluations
        thresholds.add(args.threshold or threshold)
    if len(thresholds) != 1 or not min(thresholds):
        raise SystemExit(f"the runs stopped at {sorted(thresholds)}: give --threshold")
    choice = choose(runs, thresholds.pop(), args.from_step)
    for key, value in choice.items():
        print(f"{key}: {value}")
    if args.out:
        save_choice(args.out, args.name, choice, runs)
    return 0


def save_choice(
    out: Path, name: str, choice: dict[str, object], runs: dict[int, list[Evaluation]]
) -> None:
    """``choice`` and each run's evaluated epochs as ``out/name.json``, with a table per
    seed (the training rate and the evaluation of each epoch) as ``out/name.md``."""
    courses = {str(seed): [asdict(e) for e in evals] for seed, evals in sorted(runs.items())}
    rows = [
        [seed, " ".join(f"{e.rate:.2f}/{e.success:.2f}" for e in evals[1:])]
        for seed, evals in sorted(runs.items())
    ]
    table = markdown_table(["seed", "each epoch: training rate / evaluation"], rows)
    payload = {"meta": environment_metadata(), "choice": choice, "runs": courses}
    for path in save_results(name, payload, table, out):
        print(f"saved {path}")


if __name__ == "__main__":
    raise SystemExit(main())
