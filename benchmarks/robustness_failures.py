"""How a policy's episodes fail at chosen points of one robustness perturbation.

``mjx-arm bench robustness`` reports success and the mean and median wrist peak per point. This
script runs one perturbation at the values given, in the C MuJoCo batch, and splits each point's
failures into strikes (the wrist peak at or above the task's strike limit, which ends an
episode) and the rest (a drop, a slip or the time running out), with the peaks of both.

    python -m benchmarks.robustness_failures POLICY.npz --perturbation payload --values 0 5 \\
        --episodes 64 --name failures_lift_robust_seed0_payload

Results: ``benchmarks/results/robustness/NAME.{json,md}``.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results
from mjx_arm.bench import robustness as rb

OUT = RESULTS_DIR / "robustness"


def point_failures(success: np.ndarray, peak: np.ndarray, strike: float) -> dict[str, Any]:
    """One point's split: ``success (n,)`` bool and ``peak (n,)`` wrist peaks (N) of its
    episodes, ``strike`` the limit (N) at or above which an episode ended on a strike."""
    failed = ~success
    struck = failed & (peak >= strike)
    return {
        "episodes": int(success.size),
        "success_rate": float(success.mean()),
        "failures": int(failed.sum()),
        "strikes": int(struck.sum()),
        "median_peak_success": float(np.median(peak[success])) if success.any() else None,
        "peaks_of_other_failures": sorted(np.round(peak[failed & ~struck], 1).tolist()),
    }


def run(policy_path: str, perturbation: str, values: list[float], episodes: int, seed: int):
    """Each value's :func:`point_failures`, in the C MuJoCo batch, as a list of rows."""
    from mjx_arm.evaluate import eval_task, resolve_policy
    from mjx_arm.evaluate.core import eval_arm

    policy, _ = resolve_policy(policy_path)
    task, _ = eval_task(policy)
    known = {p.name: p for p in rb.perturbations_for(bool(task.spec.gripper))}
    if perturbation not in known:
        raise SystemExit(f"unknown perturbation {perturbation!r}; choose from {sorted(known)}")
    pert = known[perturbation]
    points = [rb.Point(perturbation, v, pert.config(v), pert.inside(v)) for v in values]
    env = rb.make_env(task, "mujoco-batch", "auto", eval_arm(policy, None), episodes * len(values))
    episode = rb.point_draws(env, points, [episodes] * len(values), seed)
    out = rb.rollout(env, policy, episode, seed)
    rows = []
    for i, value in enumerate(values):
        part = slice(i * episodes, (i + 1) * episodes)
        split = point_failures(out["success"][part], out["peak_force"][part], task.strike_force)
        rows.append({"perturbation": perturbation, "value": value, **split})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("policy")
    parser.add_argument("--perturbation", required=True)
    parser.add_argument("--values", nargs="+", type=float, required=True)
    parser.add_argument("--episodes", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--name", required=True)
    args = parser.parse_args()
    rows = run(args.policy, args.perturbation, args.values, args.episodes, args.seed)
    table = markdown_table(
        ["value", "success", "failures", "of them strikes", "median peak of successes (N)",
         "peaks of the other failures (N)"],
        [[f"{r['value']:g}", f"{r['success_rate']:.3f}", r["failures"], r["strikes"],
          "-" if r["median_peak_success"] is None else f"{r['median_peak_success']:.1f}",
          ", ".join(f"{p:.0f}" for p in r["peaks_of_other_failures"]) or "none"]
         for r in rows],
    )  # fmt: skip
    text = f"# {args.perturbation} failures of {args.policy}, C MuJoCo batch\n\n{table}"
    payload = {"meta": environment_metadata(), "policy": args.policy, "rows": rows}
    for path in save_results(args.name, payload, text, OUT):
        print(f"wrote {path}")
    print(text)


if __name__ == "__main__":
    main()
