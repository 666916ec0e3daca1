"""Why Lift runs fall back: what the evaluation read before and after each fall.

A Lift run often climbs towards 0.9 and drops back before it gets there (1020 read 0.86, then
0.04). This reads the seed runs of one or more campaigns (folders of ``bench seeds`` runs,
``*-seedN/metrics.csv``, as ``gpu_suite.sh campaign`` leaves them) and lists every fall: two
evaluations in a row, the first at :data:`STARTED` or more, the second at least
:data:`~benchmarks.training_diagnosis.FALL` under it. For each it gives, before and after, the
evaluation's success, the share of its episodes that ended on a strike (a wrist reading over
the strike limit, which ends a Lift episode), the cube's mean height per step (m above its
rest), the share of steps both pads held it (``grasp``) and the mean episode length, with the
fall epoch's training-episode success and approximate KL where logged. Each fall gets one
:func:`kind`; the counts of each kind close the report.

    python -m benchmarks.lift_falls --campaign "fresh 8700=runs/lift_a,runs/lift_b" \\
        --out benchmarks/results/diagnosis --name lift_fast_falls
"""

from __future__ import annotations

import argparse
import collections
import itertools
import math
from pathlib import Path
from typing import Any

from benchmarks.choose_eval_gate import run_dirs
from benchmarks.common import environment_metadata, markdown_table, save_results
from benchmarks.training_diagnosis import FALL, SEED_DIR, evaluated_rows
from mjx_arm.train.rundir import RunDir

STARTED = 0.3  # evaluation success from which a drop can count as a fall
STRIKE_RISE = 0.2  # the share of episodes ending on a strike rose at least this much
KINDS = ("strike", "lift without grasp", "other")


def kind(before: dict[str, float], after: dict[str, float]) -> str:
    """What changed over a fall (``before`` and ``after``: :func:`reading` of the two
    evaluations), one of :data:`KINDS`:

    - ``strike``: the share of episodes that ended on a strike rose by :data:`STRIKE_RISE`
      or more (the policy runs the tool or the cube into the table);
    - ``lift without grasp``: otherwise, the cube rode higher per step while both pads held
      it on under half the steps they did before (Lift pays the cube's height, grasped or
      not);
    - ``other``: neither.
    """
    if after["strike"] - before["strike"] >= STRIKE_RISE:
        return "strike"
    if after["height"] > before["height"] and after["grasp"] < 0.5 * before["grasp"]:
        return "lift without grasp"
    return "other"


def reading(row: dict[str, float]) -> dict[str, float]:
    """One evaluation's figures (``metrics.csv`` holds per-episode sums): success, share of
    episodes ending on a strike, mean cube height per step (m), share of steps grasped, mean
    episode length (steps)."""
    length = row["eval/avg_episode_length"]
    return {
        "success": row["eval/episode_success"],
        "strike": row.get("eval/episode_strike", math.nan),
        "height": row.get("eval/episode_lift_height", math.nan) / length,
        "grasp": row.get("eval/episode_grasp", math.nan) / length,
        "length": length,
    }


def falls(rows: list[dict[str, float]]) -> list[dict[str, Any]]:
    """The falls among a run's ``rows`` (every ``metrics.csv`` row), in step order."""
    found = []
    for a, b in itertools.pairwise(evaluated_rows(rows)):
        if a["eval/episode_success"] < STARTED:
            continue
        if a["eval/episode_success"] - b["eval/episode_success"] < FALL:
            continue
        before, after = reading(a), reading(b)
        found.append(
            {
                "step": int(b["step"]),
                "kind": kind(before, after),
                "before": before,
                "after": after,
                "training_success": b.get("training/episode_success", math.nan),
                "approx_kl": b.get("training/approx_kl", math.nan),
            }
        )
    return found


def campaign(label: str, folders: list[Path]) -> dict[str, Any]:
    """The falls of every run under ``folders``, by seed, with how many runs they hold."""
    runs = run_dirs(folders)
    seeds = {int(SEED_DIR.search(r.name)["seed"]): falls(RunDir(r).read_metrics()) for r in runs}
    return {"label": label, "runs": len(runs), "falls": seeds}


def summary(campaigns: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts over ``campaigns``: runs, runs with a fall, falls of each kind."""
    every = [f for c in campaigns for seed_falls in c["falls"].values() for f in seed_falls]
    kinds = collections.Counter(f["kind"] for f in every)
    return {
        "runs": sum(c["runs"] for c in campaigns),
        "runs_with_a_fall": sum(bool(v) for c in campaigns for v in c["falls"].values()),
        "falls": len(every),
        "kinds": {k: kinds.get(k, 0) for k in KINDS},
    }


def table(campaigns: list[dict[str, Any]]) -> str:
    """One markdown row per fall: before -> after of each figure."""

    def pair(f: dict[str, Any], key: str, digits: int) -> str:
        return f"{f['before'][key]:.{digits}f} -> {f['after'][key]:.{digits}f}"

    rows = [
        [c["label"], seed, f"{f['step'] / 1e6:.1f}", f["kind"], pair(f, "success", 2),
         pair(f, "strike", 2), pair(f, "height", 3), pair(f, "grasp", 3), pair(f, "length", 0),
         f"{f['training_success']:.2f}", f"{f['approx_kl']:.3g}"]
        for c in campaigns
        for seed, seed_falls in sorted(c["falls"].items())
        for f in seed_falls
    ]  # fmt: skip
    head = ["campaign", "seed", "at (M steps)", "kind", "success", "strike share",
            "height/step (m)", "grasp share", "length", "training success",
            "approx KL"]  # fmt: skip
    return markdown_table(head, rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--campaign", action="append", required=True, help="LABEL=FOLDER[,FOLDER...] of seed runs"
    )
    parser.add_argument("--out", type=Path, help="save NAME.json and NAME.md here")
    parser.add_argument("--name", default="lift_falls")
    args = parser.parse_args(argv)
    campaigns = []
    for item in args.campaign:
        label, _, folders = item.partition("=")
        campaigns.append(campaign(label, [Path(f) for f in folders.split(",")]))
    counts = summary(campaigns)
    text = table(campaigns)
    print(text)
    print(counts)
    if args.out:
        payload = {"meta": environment_metadata(), "summary": counts, "campaigns": campaigns}
        for path in save_results(args.name, payload, f"{text}\n\n{counts}\n", args.out):
            print(f"saved {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
