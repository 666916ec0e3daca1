"""What the seeds benchmark reports (:mod:`mjx_arm.bench.seeds`): the fraction of seeds solved,
the quartiles of the time to the threshold, the table of every seed and its progress lines.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mjx_arm.bench.results import fmt, markdown_table
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig


def seed_line(config: SeedsConfig, run: SeedRun) -> str:
    """A seed's result, one line of the progress log."""
    reached = fmt(run.time_to_threshold) + " s" if run.solved else "not reached"
    return (
        f"seed {run.seed}: final {run.final_success:.3f}, best {run.best_success:.3f}, "
        f"{config.threshold:.2f} at {reached}, wall {run.wall_s:.1f} s, "
        f"compile {fmt(run.compile_s)} s"
    )


def start_up_line(report: dict[str, Any]) -> str:
    """A seed's start-up stages and JAX cache hits, one line (from its compile report)."""
    stages = ", ".join(f"{k} {v:.1f}" for k, v in report.get("stages", {}).items())
    counts = report.get("jax_counts", {})
    hits = f"{counts.get('cache_hits', 0)} of {counts.get('cache_requests', 0)}"
    return f"start-up (s): {stages}; JAX cache hits {hits}"


def quartiles(times: list[float | None]) -> dict[str, float | None]:
    """Median and interquartile range of times, a missing time counting as infinite.

    Returns:
        ``median``, ``q25``, ``q75`` (None where the quantile falls on an unsolved seed) and
        ``n``.
    """
    if not times:
        return {"median": None, "q25": None, "q75": None, "n": 0}
    values = np.sort([math.inf if t is None else t for t in times])
    # the median averages the middle pair (inf if either is unsolved); the quartiles take a
    # sample ("lower"/"higher"), so an infinity never enters an interpolation as inf * 0
    q = {
        "median": float(np.median(values)),
        "q25": float(np.quantile(values, 0.25, method="lower")),
        "q75": float(np.quantile(values, 0.75, method="higher")),
    }
    out: dict[str, float | None] = {k: (v if math.isfinite(v) else None) for k, v in q.items()}
    out["n"] = len(times)
    return out


def wilson_interval(successes: int, trials: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion (95% for ``z`` 1.96): what the solve
    rate of the population of seeds lies in, given ``successes`` of ``trials`` seeds."""
    if trials == 0:
        return (math.nan, math.nan)
    p, n = successes / trials, trials
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def percentile_time(times: list[float | None], q: float) -> float | None:
    """The ``q`` quantile (0-1) of times, a missing time counting as infinite (None there)."""
    if not times:
        return None
    values = np.sort([math.inf if t is None else t for t in times])
    value = float(np.quantile(values, q, method="higher"))
    return value if math.isfinite(value) else None


def warm_flags(runs: list[SeedRun]) -> list[bool]:
    """Whether each run counts as warm: its own record's ``warm`` (it started after another
    seed of its benchmark had ended), or, in a record without it, every run but the first."""
    return [r.warm if r.warm is not None else i > 0 for i, r in enumerate(runs)]


def summarize(runs: list[SeedRun], threshold: float) -> dict[str, Any]:
    """Fraction of seeds solved with its 95% interval, time quartiles and 90th percentile over
    all seeds and over the warm ones, steps to the threshold, and the runs that collapsed
    (reached the threshold, then ended under it)."""
    times = [r.time_to_threshold for r in runs]
    warm = [t for t, r in zip(times, warm_flags(runs), strict=True) if r]
    steps = [r.steps_to_threshold for r in runs if r.steps_to_threshold is not None]
    solved = sum(r.solved for r in runs)
    return {
        "threshold": threshold,
        "seeds": len(runs),
        "solved": solved,
        "fraction_solved": solved / len(runs) if runs else math.nan,
        "fraction_solved_ci95": wilson_interval(solved, len(runs)),
        "collapsed": [r.seed for r in runs if r.collapsed(threshold)],
        "time_to_threshold_p90_all": percentile_time(times, 0.9),
        "time_to_threshold_p90_warm": percentile_time(warm, 0.9),
        "time_to_threshold_all": quartiles(times),
        "time_to_threshold_warm": quartiles(warm),
        "median_steps_to_threshold": float(np.median(steps)) if steps else None,
        "median_training_steps_per_s": float(np.median([r.training_steps_per_s for r in runs])),
    }


def seeds_table(runs: list[SeedRun], summary: dict[str, Any]) -> str:
    """The markdown table of every seed, then the summary lines."""
    pct = f"{summary['threshold']:.2f}"
    headers = [
        "seed",
        "final policy success",
        "best success",
        f"steps to {pct}",
        f"time to {pct} (s)",
        "wall (s)",
        "compile (s)",
        "training steps/s",
    ]
    rows = [
        [
            r.seed,
            f"{r.final_success:.3f}",
            f"{r.best_success:.3f}",
            f"{r.steps_to_threshold:,}" if r.solved else "not reached",
            fmt(r.time_to_threshold) if r.solved else "not reached",
            f"{r.wall_s:.1f}",
            fmt(r.compile_s),
            f"{r.training_steps_per_s:,.0f}",
        ]
        for r in runs
    ]
    return markdown_table(headers, rows) + "\n" + summary_lines(summary)


def _quartile_text(q: dict[str, float | None]) -> str:
    def show(v: float | None) -> str:
        return "not reached" if v is None else f"{v:.1f} s"

    return f"median {show(q['median'])} (IQR {show(q['q25'])} to {show(q['q75'])}, n={q['n']})"


def summary_lines(summary: dict[str, Any]) -> str:
    """The summary as markdown list lines."""
    low, high = summary.get("fraction_solved_ci95", (math.nan, math.nan))
    p90 = summary.get("time_to_threshold_p90_warm")
    collapsed = summary.get("collapsed", [])
    return (
        f"- solved (evaluation success >= {summary['threshold']:.2f}): "
        f"{summary['solved']} of {summary['seeds']} seeds (95% interval {low:.2f}-{high:.2f}); "
        f"collapsed (reached it, last evaluation under it): {len(collapsed)}"
        f"{' (seeds ' + ', '.join(map(str, collapsed)) + ')' if collapsed else ''}\n"
        f"- 90th percentile of the time to {summary['threshold']:.2f}, warm seeds: "
        f"{'not reached' if p90 is None else f'{p90:.1f} s'}\n"
        f"- time to {summary['threshold']:.2f}, all seeds: "
        f"{_quartile_text(summary['time_to_threshold_all'])}\n"
        f"- time to {summary['threshold']:.2f}, warm seeds (started after a seed had ended): "
        f"{_quartile_text(summary['time_to_threshold_warm'])}\n"
        f"{_steps_line(summary)}"
    )


def _steps_line(summary: dict[str, Any]) -> str:
    """The median env steps to the threshold and training env steps/s, as a list line ("" in
    a summary that has neither)."""
    steps = summary.get("median_steps_to_threshold")
    speed = summary.get("median_training_steps_per_s")
    if steps is None and speed is None:
        return ""
    steps_text = "not reached" if steps is None else f"{steps:,.0f}"
    speed_text = "unknown" if speed is None else f"{speed:,.0f}"
    return f"- median env steps to it: {steps_text}; median training env steps/s: {speed_text}\n"
