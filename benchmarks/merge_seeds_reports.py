"""One seeds report from several reports of the same benchmark run in different calls.

A GPU call is bounded in time, so a range of fresh seeds is often trained over two or more
calls (the first stopped at its deadline; the next trains the seeds it did not reach). This
writes the report of the whole range: every finished seed of the inputs, the summary computed
again over all of them (solve rate with its 95 % interval, times, steps, collapses). The
inputs must agree on task, preset, threshold, arm and ``--set`` items; a seed in two of them
is an error. A seed is warm as its record says; in a report written before records said so,
every seed but the report's first (each call starts with its own caches). A seed whose
process a deadline's SIGTERM ended (``mjx_arm.bench.seeds.stopped_from_outside``; reports
written before that rule list it as failed) is left out and counted in ``pending_seeds``.
The machine's record is the newest input's; ``meta.merged_from`` names each input with its
commit, date, seeds and the seeds it left out.

    python -m benchmarks.merge_seeds_reports A.json B.json --name seeds_reach_fast_fresh \\
        --out benchmarks/results/seeds/fresh
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from mjx_arm.bench.seeds import stopped_from_outside
from mjx_arm.bench.seeds_config import SeedRun, SeedsConfig
from mjx_arm.bench.seeds_report import write_report
from mjx_arm.bench.seeds_summary import warm_flags

# settings every input must share (the seeds differ)
SHARED = (
    "task", "preset", "backend", "threshold", "devices", "gpus_per_seed", "arm", "deterministic",
    "server",
)  # fmt: skip


def _setting(report: dict[str, Any], key: str) -> Any:
    """A shared setting of ``report``; one that reports written before it lack is the
    default (``gpus_per_seed``: 1, ``server``: False)."""
    return report["settings"].get(key, getattr(SeedsConfig(), key))


def merge(reports: list[dict[str, Any]], names: list[str]) -> tuple[SeedsConfig, list, list, dict]:
    """(config, seed runs in seed order, their configs, meta) of ``reports`` merged.

    Raises:
        ValueError: the reports differ in a shared setting or ``--set`` items, or share a seed.
    """
    first = reports[0]
    for report, name in zip(reports[1:], names[1:], strict=True):
        for key in SHARED:
            if _setting(report, key) != _setting(first, key):
                raise ValueError(
                    f"{name}: {key} {_setting(report, key)!r}, not "
                    f"{_setting(first, key)!r} as in {names[0]}"
                )
        if report["overrides"] != first["overrides"]:
            raise ValueError(f"{name}: --set {report['overrides']}, not {first['overrides']}")
    pairs: dict[int, tuple[SeedRun, dict]] = {}
    for report, name in zip(reports, names, strict=True):
        runs = [SeedRun(**record) for record in report["seeds"]]
        # each report's own rule (a report from before the flag: its first is cold)
        for run, warm, config in zip(runs, warm_flags(runs), report["configs"], strict=True):
            run.warm = warm
            if stopped_from_outside(run):
                continue
            if run.seed in pairs:
                raise ValueError(f"seed {run.seed} is in two reports (again in {name})")
            pairs[run.seed] = (run, config)
    order = sorted(pairs)
    runs = [pairs[s][0] for s in order]
    settings = {k: _setting(first, k) for k in SHARED}
    config = SeedsConfig(**settings, seeds=",".join(str(s) for s in order))
    newest = max(reports, key=lambda r: r["meta"]["date"])
    merged_from = [
        {
            "file": name,
            "git_commit": r["meta"].get("git_commit"),
            "date": r["meta"]["date"],
            "seeds": [s["seed"] for s in r["seeds"]],
            "left_out": [s["seed"] for s in r["seeds"] if s["seed"] not in pairs],
        }
        for r, name in zip(reports, names, strict=True)
    ]
    meta = {**newest["meta"], "merged_from": merged_from}
    return config, runs, [pairs[s][1] for s in order], meta


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reports", type=Path, nargs="+", help="seeds reports (NAME.json)")
    parser.add_argument("--name", required=True)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    reports = [json.loads(p.read_text()) for p in args.reports]
    try:
        config, runs, configs, meta = merge(reports, [p.name for p in args.reports])
    except ValueError as err:
        parser.error(str(err))
    overrides = tuple(reports[0]["overrides"])
    left_out = [s for source in meta["merged_from"] for s in source["left_out"]]
    if left_out:
        print(f"left out, stopped by a SIGTERM: seeds {left_out}")
    pending = len(left_out) + sum(r.get("pending_seeds", 0) for r in reports)
    out, name = args.out, args.name
    for path in write_report(config, runs, configs, meta, out, name, overrides, pending=pending):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
