"""One line per seed run of a ``gpu_suite.sh campaign``: where each seed stands.

Reads every campaign folder under WORK (``NAME/*-seedN/metrics.csv``) and prints, per run, its
best and last evaluated success, the env steps of its first evaluation at the threshold, and,
for a Touch seed that has not reached it, the trap its last evaluation shows
(:func:`benchmarks.training_diagnosis.trap`). Runs still training show what they have logged
so far. Printed at the end of a campaign, so that the next call can be chosen at once.

    python -m benchmarks.campaign_brief runs/gpu_suite --threshold 0.95
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from benchmarks.training_diagnosis import SEED_DIR, _col, _rows, trap


def brief(run: Path, threshold: float) -> tuple[str, bool]:
    """``campaign/run: best B last L``, then the steps at the threshold or the trap, of one
    seed run; and whether it reached the threshold."""
    rows = _rows(run)
    if not rows:
        return f"{run.parent.name}/{run.name}: no evaluation yet", False
    success = _col(rows, "eval/episode_success")
    hit = next((r for r in rows if r.get("eval/episode_success", 0.0) >= threshold), None)
    best = float(success.max()) if success.size else math.nan
    text = f"{run.parent.name}/{run.name}: best {best:.3f} last {success[-1]:.3f}"
    if hit is not None:
        return f"{text} solved at {hit['step'] / 1e6:.1f}M steps", True
    return f"{text} unsolved at {rows[-1]['step'] / 1e6:.1f}M steps ({trap(rows[-1])})", False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("work", type=Path, help="the campaign's WORK folder")
    parser.add_argument("--threshold", type=float, default=0.95)
    args = parser.parse_args(argv)
    runs = sorted(args.work.glob("*/*"), key=lambda p: (p.parent.name, p.name))
    counts: dict[str, list[int]] = {}
    for run in runs:
        if SEED_DIR.search(run.name) and (run / "metrics.csv").is_file():
            line, solved = brief(run, args.threshold)
            print(line)
            count = counts.setdefault(run.parent.name, [0, 0])
            count[0] += solved
            count[1] += 1
    for name, (solved, total) in counts.items():
        print(f"{name}: {solved} of {total} at {args.threshold}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
