"""Where a Lift policy loses episodes on a CPU engine: how each failed episode ended, and what a
more converged contact solver in C MuJoCo changes.

Each episode is sorted by how it ended: ``success``; ``strike`` (the wrist reading passed the
strike limit and ended the episode); ``dropped`` (both pads pressed the cube at some step but
it was not held up: a grasp that slipped, or one taken too low on the cube); ``no_grasp``
(the pads never pressed it together). Per policy it also gives the mean wrist peak (N), the
peak at the first table or cube contact of the tool (``touchdown``, N) and the largest height
the cube reached (m).

Solver variants (MuJoCo only; ``--solvers``): ``as_trained`` (the task model's options, the
same as MJX trains on: Newton, 2 iterations, 4 line-search iterations, pyramidal cone);
``iter4`` (4 and 8); ``iter10`` (10 and 10); ``elliptic`` (elliptic cone, impratio 10, 10
and 10); ``noslip`` (as trained plus 5 noslip iterations).

Run from the repository root::

    python benchmarks/bench_lift_transfer.py --engine mujoco --episodes 100 \\
        --policies benchmarks/results/policies/lift-fast-seed0.npz

Results: ``benchmarks/results/sim2real/lift_transfer_<engine>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

SOLVERS = {
    "as_trained": {},
    "iter4": {"iterations": 4, "ls_iterations": 8},
    "iter10": {"iterations": 10, "ls_iterations": 10},
    "elliptic": {"cone": 1, "impratio": 10.0, "iterations": 10, "ls_iterations": 10},
    "noslip": {"noslip_iterations": 5},
}
OUTCOMES = ("success", "strike", "dropped", "no_grasp")
PAD_PRESS = 0.5  # N on each pad: Lift's GRASP_FORCE


def run_episode(policy, env, seed: int) -> dict:
    """One episode: how it ended, its wrist peak, touchdown peak and the cube's top height."""
    obs, _ = env.reset(seed=seed)
    done, success, pressed, peak, touchdown, top = False, False, False, 0.0, None, 0.0
    terminated, window = False, []
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        force = float(info["contact_force_norm"])
        peak, top = max(peak, force), max(top, float(info["height"]))
        if touchdown is None and force > 1.0:
            window = [force]
            touchdown = force
        elif window and len(window) < 5:  # the touchdown's peak: its first five steps
            window.append(force)
            touchdown = max(window)
        pressed = pressed or bool((np.asarray(obs["pad_force"]) >= PAD_PRESS).all())
        success = success or bool(info["is_success"])
        done = bool(terminated or truncated)
    if success:
        outcome = "success"
    elif terminated and info.get("overforce"):
        outcome = "strike"
    else:
        outcome = "dropped" if pressed else "no_grasp"
    return {"outcome": outcome, "peak": peak, "touchdown": touchdown or 0.0, "top": top}


def run_policy(path: Path, engine: str, solver: str, episodes: int) -> dict:
    """All episodes of one policy on one engine and solver variant, summarised."""
    from mjx_arm.evaluate import eval_arm, eval_task, make_eval_env
    from mjx_arm.policy import load

    policy = load(path)
    task, arm = eval_task(policy)[0], eval_arm(policy, None)
    env = make_eval_env(task, engine, arm=arm)
    for key, value in SOLVERS[solver].items():
        setattr(env.unwrapped.model.opt, key, value)
    start = time.perf_counter()
    try:
        eps = [run_episode(policy, env, seed) for seed in range(episodes)]
    finally:
        env.close()
    counts = Counter(e["outcome"] for e in eps)
    return {
        "policy": path.name,
        "engine": engine,
        "solver": solver,
        "episodes": episodes,
        "outcomes": {k: counts.get(k, 0) for k in OUTCOMES},
        "success_rate": counts.get("success", 0) / episodes,
        "mean_peak_n": float(np.mean([e["peak"] for e in eps])),
        "mean_touchdown_peak_n": float(np.mean([e["touchdown"] for e in eps])),
        "mean_top_height_m": float(np.mean([e["top"] for e in eps])),
        "seconds": time.perf_counter() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policies", nargs="+", type=Path, required=True)
    parser.add_argument("--engine", default="mujoco", choices=("mujoco", "pybullet"))
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--solvers", default="as_trained")
    parser.add_argument("--name", default=None)
    args = parser.parse_args()
    solvers = args.solvers.split(",")
    if args.engine != "mujoco" and solvers != ["as_trained"]:
        parser.error("solver variants are C MuJoCo's")
    rows = []
    for path in args.policies:
        for solver in solvers:
            row = run_policy(path, args.engine, solver, args.episodes)
            rows.append(row)
            print(
                f"{path.name} {args.engine} {solver}: success {row['success_rate']:.2f} "
                f"{row['outcomes']}, peak {row['mean_peak_n']:.1f} N, touchdown "
                f"{row['mean_touchdown_peak_n']:.1f} N, {row['seconds']:.0f} s",
                flush=True,
            )
    cells = [
        [r["policy"], r["solver"], f"{r['success_rate']:.2f}"]
        + [r["outcomes"][k] for k in OUTCOMES[1:]]
        + [f"{r['mean_peak_n']:.1f}", f"{r['mean_touchdown_peak_n']:.1f}"]
        for r in rows
    ]
    headers = ["policy", "solver", "success", "strike", "dropped", "no grasp", "peak N"]
    md = (
        f"# Lift policies on {args.engine}: how episodes end ({args.episodes} episodes, "
        "seeds 0..N-1)\n\n" + markdown_table([*headers, "touchdown peak N"], cells)
    )
    name = args.name or f"lift_transfer_{args.engine}"
    payload = {"meta": environment_metadata(), "engine": args.engine, "rows": rows}
    save_results(name, payload, md, RESULTS_DIR / "sim2real")
    print(md)


if __name__ == "__main__":
    main()
