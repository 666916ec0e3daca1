"""Why Touch seeds fail: the PPO figures of solving and failing seeds, side by side.

Reads the seed run directories of one or more campaigns (each a folder of ``bench seeds`` runs,
``*-seedN/metrics.csv``, as ``gpu_suite.sh campaign`` leaves them) and writes ``NAME.json`` and
``NAME.md``: per campaign and seed, whether the seed reached the threshold, its best and last
evaluation, and what its training logged: the largest and the median per-epoch KL between the
rollout's policy and the updated one, the epochs whose KL passed 1 (an update that replaced the
policy rather than nudged it), the median clip fraction, the learning rate, the policy's std
and the value function's explained variance at the end, the evaluation's touch and overforce
figures at the end, and how far the policy's Gaussian (before the tanh) had drifted by
:data:`EARLY_STEPS`: its smallest and largest std and its largest mean over the batch and the
action entries (a mean of 3 already gives tanh 0.995: beyond, the action no longer changes),
the course of its success: every evaluation's value, the first at :data:`FIRST` or more,
and its falls; and the evaluation of the highest return beside the most successful one. An
unsolved run a deadline stopped short of its budget is listed and left out.

    python -m benchmarks.training_diagnosis --campaign "as shipped=runs/tune_base" \\
        --campaign "std floor + clip=runs/tune_clip" --out benchmarks/results/diagnosis
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import environment_metadata, save_results

SEED_DIR = re.compile(r"seed(?P<seed>\d+)$")
SPIKE_KL = 1.0  # a per-epoch mean KL above this: the update replaced the policy
STRIKES = 0.2  # episodes ending on a strike, as a fraction: the striking trap
TOUCHING = 5.0  # steps per episode with a reading in the band or over it: the tool presses
HELD = 0.5  # steps per episode whose press had held 2+ steps: below it, in-band steps are taps
TRAPS = ("striking", "tapping", "resting", "stalled", "other")
EARLY_STEPS = 6e6  # env steps: the policy's drift is read over the first ones (a fifth of Touch's)
FIRST = 0.05  # evaluation success at which a seed counts as having started to touch
FALL = 0.3  # a drop in evaluation success between two evaluations that counts as a fall


def trap(last: dict[str, float]) -> str:
    """The local optimum a failing Touch seed's evaluation ``last`` (a ``metrics.csv`` row:
    per-episode sums) shows, one of :data:`TRAPS`:

    - ``striking``: at least :data:`STRIKES` of the episodes end on a strike over the limit;
    - ``tapping``: the tool meets the box on :data:`TOUCHING` steps or more, but its in-band
      steps do not come two in a row (under :data:`HELD` streak steps per episode);
    - ``resting``: it presses for several steps running, yet succeeds rarely (a reading over
      the band earlier in the episode, or off the face centre);
    - ``stalled``: it touches the box on less than one step per episode;
    - ``other``: none of these.
    """
    if last.get("eval/episode_strike", 0.0) >= STRIKES:
        return "striking"
    touching = last.get("eval/episode_touching", 0.0)
    if touching < 1.0:
        return "stalled"
    if touching >= TOUCHING:
        return "tapping" if last.get("eval/episode_streak", 0.0) < HELD else "resting"
    return "other"


def _rows(run: Path) -> list[dict[str, float]]:
    with (run / "metrics.csv").open(newline="") as f:
        return [
            {k: float(v) if v not in ("", None) else math.nan for k, v in r.items()}
            for r in csv.DictReader(f)
        ]


def evaluated_rows(rows: list[dict[str, float]]) -> list[dict[str, float]]:
    """The rows that hold an evaluation (an epoch before ``eval_from_step`` logs its training
    figures alone)."""
    return [r for r in rows if math.isfinite(r.get("eval/episode_success", math.nan))]


def _col(rows: list[dict[str, float]], name: str) -> np.ndarray:
    values = np.array([r.get(name, math.nan) for r in rows], dtype=float)
    return values[np.isfinite(values)]


def seed_record(run: Path, threshold: float) -> dict[str, Any]:
    """What one seed's run logged, condensed (see the module docstring)."""
    rows = _rows(run)
    trained = [r for r in rows if math.isfinite(r.get("training/kl_mean", math.nan))]
    evaluated = evaluated_rows(rows)
    success = _col(evaluated, "eval/episode_success")
    kl = _col(trained, "training/kl_mean")
    hit = next((int(r["step"]) for r in evaluated if r["eval/episode_success"] >= threshold), None)
    last = rows[-1]
    last_eval = evaluated[-1] if evaluated else {}  # the last row may hold no evaluation
    train = json.loads((run / "config.json").read_text())["train"]
    return {
        "seed": int(SEED_DIR.search(run.name)["seed"]),
        "solved": hit is not None,
        "steps_to_threshold": hit,
        "best_success": float(success.max()) if success.size else math.nan,
        "last_success": float(success[-1]) if success.size else math.nan,
        "last_step": int(last["step"]),
        "stopped": hit is None and short_of_budget(train, last["step"]),
        "kl_max": float(kl.max()) if kl.size else math.nan,
        "kl_median": float(np.median(kl)) if kl.size else math.nan,
        "kl_spikes": [int(r["step"]) for r in trained if r["training/kl_mean"] > SPIKE_KL],
        "clip_fraction_median": float(np.median(_col(trained, "training/clip_fraction"))),
        "learning_rate_last": last.get("training/learning_rate", math.nan),
        "policy_std_last": last.get("training/policy_dist_mean_std", math.nan),
        "explained_variance_last": last.get("training/explained_variance", math.nan),
        "touching_last": last_eval.get("eval/episode_touching", math.nan),
        "overforce_last": last_eval.get("eval/episode_overforce", math.nan),
        "mean_distance_last": last_eval.get("eval/episode_distance", math.nan)
        / last_eval.get("eval/avg_episode_length", math.nan),
        "trap": None if hit is not None else trap(last_eval),
        **early_drift(trained),
        **normaliser_share(trained),
        **success_course(rows),
        **richest_evaluation(rows),
        "settings": train["schedule"] | train["normalizer"],
    }


def early_drift(trained: list[dict[str, float]]) -> dict[str, float]:
    """The policy Gaussian's smallest and largest std and largest mean (before the tanh) over
    the training epochs up to :data:`EARLY_STEPS` (rows of ``metrics.csv``)."""
    early = [r for r in trained if r["step"] <= EARLY_STEPS]

    def pick(name: str, reduce) -> float:
        values = _col(early, name)
        return float(reduce(values)) if values.size else math.nan

    return {
        "early_std_min": pick("training/policy_dist_min_std", np.min),
        "early_std_max": pick("training/policy_dist_max_std", np.max),
        "early_mean_max": pick("training/policy_dist_max_loc", np.max),
    }


def success_course(rows: list[dict[str, float]]) -> dict[str, Any]:
    """The evaluations' success over the run: every value (``success_curve``, with its
    ``curve_steps``), the step of the first at :data:`FIRST` or more (None: never), and the
    falls, evaluations at least :data:`FALL` under the one before."""
    evaluated = evaluated_rows(rows)
    curve = [float(r["eval/episode_success"]) for r in evaluated]
    first = next((int(r["step"]) for r in evaluated if r["eval/episode_success"] >= FIRST), None)
    return {
        "success_curve": curve,
        "curve_steps": [int(r["step"]) for r in evaluated],
        "first_success_step": first,
        "falls": sum(before - after >= FALL for before, after in itertools.pairwise(curve)),
    }


def richest_evaluation(rows: list[dict[str, float]]) -> dict[str, Any]:
    """The evaluation of the highest episode return and the one of the best success, each as
    step, success, return, overforce readings, steps touching and held-press steps per
    episode: where a policy earns more without succeeding, the reward ranks something above
    success (``richest`` and ``most_successful``)."""
    evaluated = [r for r in rows if math.isfinite(r.get("eval/episode_reward", math.nan))]
    if not evaluated:
        return {"richest": None, "most_successful": None}
    keys = {"success": "eval/episode_success", "episode_return": "eval/episode_reward",
            "overforce": "eval/episode_overforce", "touching": "eval/episode_touching",
            "streak": "eval/episode_streak"}  # fmt: skip

    def view(r: dict[str, float]) -> dict[str, float]:
        return {"step": int(r["step"]), **{k: r.get(v, math.nan) for k, v in keys.items()}}

    richest = max(evaluated, key=lambda r: r["eval/episode_reward"])
    best = max(evaluated, key=lambda r: r.get("eval/episode_success", -1.0))
    return {"richest": view(richest), "most_successful": view(best)}


def normaliser_share(trained: list[dict[str, float]]) -> dict[str, float]:
    """The KL and clip fraction of each update's first minibatch, before its first gradient
    step (the observation normaliser's move alone), over the epochs: largest and median KL,
    median clip fraction (NaN for runs that did not log them)."""
    kl = _col(trained, "training/kl_before_update")
    clip = _col(trained, "training/clip_fraction_before_update")
    return {
        "kl_before_update_max": float(kl.max()) if kl.size else math.nan,
        "kl_before_update_median": float(np.median(kl)) if kl.size else math.nan,
        "clip_fraction_before_update_median": float(np.median(clip)) if clip.size else math.nan,
    }


def short_of_budget(train: dict[str, Any], last_step: float) -> bool:
    """Whether a run's last logged step falls short of its budget (``num_timesteps`` of its
    config's ``train``): unsolved, such a run was stopped by a call's deadline or a kill, so it
    neither solved nor failed."""
    budget = train.get("num_timesteps")
    return budget is not None and last_step < budget


def campaign(label: str, folder: Path, threshold: float) -> dict[str, Any]:
    """Every seed run under ``folder``, with the campaign's counts; unsolved runs stopped short
    of their budget (:func:`short_of_budget`) are listed as ``stopped`` and left out of them."""
    runs = sorted(p for p in folder.iterdir() if p.is_dir() and SEED_DIR.search(p.name))
    records = [seed_record(r, threshold) for r in runs if (r / "metrics.csv").is_file()]
    stopped = [s["seed"] for s in records if s["stopped"]]
    seeds = [s for s in records if not s["stopped"]]
    solved = [s for s in seeds if s["solved"]]
    failed = [s for s in seeds if not s["solved"]]
    return {
        "label": label,
        "seeds": seeds,
        "stopped": stopped,
        "solved": len(solved),
        "count": len(seeds),
        "spiking_seeds_solved": sum(bool(s["kl_spikes"]) for s in solved),
        "spiking_seeds_failed": sum(bool(s["kl_spikes"]) for s in failed),
        "traps": {t: sum(s["trap"] == t for s in failed) for t in TRAPS},
        "seeds_with_falls_solved": sum(s["falls"] > 0 for s in solved),
        "seeds_with_falls_failed": sum(s["falls"] > 0 for s in failed),
        "failed_never_started": sum(s["first_success_step"] is None for s in failed),
    }


def markdown(campaigns: list[dict[str, Any]], threshold: float) -> str:
    """One table per campaign."""
    lines = []
    for c in campaigns:
        left_out = ", ".join(str(seed) for seed in c.get("stopped", []))
        left_out = f" ({left_out} stopped before their budget, left out)" if left_out else ""
        lines += [
            f"## {c['label']}: {c['solved']} of {c['count']} seeds at {threshold}{left_out}",
            "",
        ]
        lines += [
            "| seed | solved | best | last | KL max | KL median | epochs with KL > 1 | clip "
            "fraction (median) | lr (last) | std (last) | explained variance (last) | std "
            f"range, first {EARLY_STEPS / 1e6:.0f}M | largest mean, first "
            f"{EARLY_STEPS / 1e6:.0f}M | trap |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for s in c["seeds"]:
            lines.append(
                f"| {s['seed']} | {'yes' if s['solved'] else 'no'} | {s['best_success']:.3f} | "
                f"{s['last_success']:.3f} | {s['kl_max']:.3g} | {s['kl_median']:.3g} | "
                f"{len(s['kl_spikes'])} | {s['clip_fraction_median']:.3f} | "
                f"{s['learning_rate_last']:.2g} | {s['policy_std_last']:.3f} | "
                f"{s['explained_variance_last']:.3f} | {s['early_std_min']:.3g}-"
                f"{s['early_std_max']:.3g} | {s['early_mean_max']:.3g} | {s.get('trap') or '-'} |"
            )
        lines.append("")
        lines += _normaliser_table(c["seeds"])
        lines += _course_table(c["seeds"])
        lines += _richest_table(c["seeds"])
    return "\n".join(lines)


def _normaliser_table(seeds: list[dict[str, Any]]) -> list[str]:
    """The normaliser's share of each seed's KL (runs that logged it), as markdown lines."""
    logged = [s for s in seeds if math.isfinite(s.get("kl_before_update_max", math.nan))]
    if not logged:
        return []
    lines = [
        "Before each update's first gradient step (the normaliser's move alone):",
        "",
        "| seed | KL max | KL median | clip fraction (median) | whole update: KL max, median |",
        "|---|---|---|---|---|",
    ]
    for s in logged:
        lines.append(
            f"| {s['seed']} | {s['kl_before_update_max']:.3g} | "
            f"{s['kl_before_update_median']:.3g} | "
            f"{s['clip_fraction_before_update_median']:.3f} | "
            f"{s['kl_max']:.3g}, {s['kl_median']:.3g} |"
        )
    return [*lines, ""]


def _course_table(seeds: list[dict[str, Any]]) -> list[str]:
    """Each seed's success over its evaluations: when it started and how often it fell."""
    lines = [
        f"Success over the run (started: the first evaluation at {FIRST} or more; falls: "
        f"evaluations {FALL} or more under the one before):",
        "",
        "| seed | solved | started at (M steps) | falls | success at each evaluation |",
        "|---|---|---|---|---|",
    ]
    for s in seeds:
        start = s["first_success_step"]
        start = f"{start / 1e6:.1f}" if start is not None else "never"
        curve = " ".join(f"{v:.2f}" for v in s["success_curve"])
        lines.append(
            f"| {s['seed']} | {'yes' if s['solved'] else 'no'} | {start} | {s['falls']} | {curve} |"
        )
    return [*lines, ""]


def _richest_table(seeds: list[dict[str, Any]]) -> list[str]:
    """Each seed's evaluation of the highest return beside its most successful one."""
    lines = [
        "The evaluation of the highest return beside the most successful one (per episode: "
        "return, readings over the band, steps touching, held-press steps):",
        "",
        "| seed | highest return: step (M), success, return, over, touching, held | best "
        "success: step (M), success, return, over, touching, held |",
        "|---|---|---|",
    ]

    def cell(e: dict[str, float] | None) -> str:
        if e is None:
            return "-"
        return (f"{e['step'] / 1e6:.1f}, {e['success']:.2f}, {e['episode_return']:.0f}, "
                f"{e['overforce']:.2f}, {e['touching']:.1f}, {e['streak']:.1f}")  # fmt: skip

    for s in seeds:
        lines.append(f"| {s['seed']} | {cell(s['richest'])} | {cell(s['most_successful'])} |")
    return [*lines, ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", action="append", required=True, help="LABEL=FOLDER")
    parser.add_argument("--threshold", type=float, default=0.95)
    parser.add_argument("--device", default="", help="the device the runs trained on (text)")
    parser.add_argument("--name", default="touch_fast_seeds")
    parser.add_argument("--out", type=Path, default=Path("runs/diagnosis"))
    args = parser.parse_args()
    campaigns = []
    for item in args.campaign:
        label, _, folder = item.partition("=")
        campaigns.append(campaign(label, Path(folder), args.threshold))
    text = markdown(campaigns, args.threshold)
    payload = {
        "meta": environment_metadata(),
        "runs_device": args.device,
        "threshold": args.threshold,
        "spike_kl": SPIKE_KL,
        "campaigns": campaigns,
    }
    for path in save_results(args.name, payload, f"# Touch seeds side by side\n\n{text}", args.out):
        print(f"wrote {path}")
    print(text)


if __name__ == "__main__":
    main()
