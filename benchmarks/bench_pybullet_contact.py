"""Which PyBullet scene contact acts most like MuJoCo's: trained policies run in CPU MuJoCo and
in PyBullet with rigid contacts and with compliant ones.

A compliant setting gives the table and the box one spring and damper and the cube of a gripper
task another (:class:`pybullet_ref.contact.SceneContact`, text form ``FIXED/CUBE`` with each
part ``STIFFNESS:DAMPING`` in N/m and N s/m, or ``rigid``). Each row: one policy, one engine and
contact, the same episode seeds; the success rate and the median and 90th percentile of the
episodes' peak wrist force (N). Then, per contact, the mean |success rate difference| from
MuJoCo and the median |log ratio| of the median peaks, over the policies; the setting with the
smallest sum is printed last. :data:`pybullet_ref.contact.SOFT` was chosen this way.

Policies (committed under ``benchmarks/results/``): the shipped arm's Touch (fast preset, seeds
0-2, and the gentle C-backend policy), the UR10's Touch (seeds 0-2; needs ``ROS_PACKAGE_PATH``
to hold example-robot-data's ``robots`` folder, else skipped) and Lift (seeds 0-4).

Run from the repository root:
``python benchmarks/bench_pybullet_contact.py [--episodes 200] [--cases ...] [--contacts rigid
soft 4e4:200/3e3:100 ...] [--name NAME]``. Results: ``benchmarks/results/contact/NAME.{json,md}``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

UR10 = str(Path(__file__).resolve().parent / "arms" / "ur10.toml")
# name: (policy file under the results, arm file or None for the one the policy records). Only
# the reference policies in ``policies/`` are tracked; export the others first from the runs
# their seeds JSON records (``mjx-arm bench seeds``, then ``mjx-arm export``).
CASES = {
    "touch_seed0": ("policies/touch_fast_seed0.npz", None),
    **{f"touch_seed{s}": (f"seeds/policies/touch_fast_seed{s}.npz", None) for s in (1, 2)},
    "touch_gentle_c": ("transfer/policies/touch_gentle_c_backend_cpu.npz", None),
    **{
        f"ur10_touch_seed{s}": (f"arms/policies_ur10/ur10-touch-fast-seed{s}.npz", UR10)
        for s in range(3)
    },
    "lift_seed0": ("policies/lift-fast-seed0.npz", None),
    **{f"lift_seed{s}": (f"lift/policies/lift-fast-seed{s}.npz", None) for s in range(1, 5)},
}


def run_case(case: str, engine: str, contact: str | None, episodes: int, seed: int) -> dict:
    """Episodes of one policy in one engine (``contact``: PyBullet's scene contact in the text
    form of :meth:`pybullet_ref.contact.SceneContact.parse`; ignored by MuJoCo)."""
    from mjx_arm.evaluate.core import eval_arm, eval_task, make_eval_env
    from mjx_arm.evaluate.runners import run_episodes
    from mjx_arm.policy import load

    path, arm_file = CASES[case]
    policy = load(RESULTS_DIR / path)
    task, _ = eval_task(policy)
    arm = eval_arm(policy, arm_file)
    start = time.perf_counter()
    env = make_eval_env(task, engine, arm=arm, contact=contact)
    try:
        run = run_episodes(policy, env, episodes, seed)
    finally:
        env.close()
    peaks = np.array([e.peak_contact_force for e in run.episodes])
    return {
        "case": case,
        "engine": engine,
        "contact": contact if engine == "pybullet" else None,
        "episodes": episodes,
        "success_rate": float(np.mean([e.success for e in run.episodes])),
        "peak_median_n": float(np.median(peaks)),
        "peak_p90_n": float(np.percentile(peaks, 90)),
        "seconds": time.perf_counter() - start,
    }


def available(case: str) -> bool:
    """Whether the case's arm resolves on this machine (the UR10 needs its package)."""
    from mjx_arm.arm.config import load_arm

    arm_file = CASES[case][1]
    if arm_file is None:
        return True
    try:
        from mjx_arm.arm.info import arm_info

        arm_info(load_arm(arm_file))
    except Exception as exc:  # reported, the case is skipped
        print(f"skip {case}: {exc}", flush=True)
        return False
    return True


def label(row: dict) -> str:
    """Engine and contact of a row, e.g. ``pybullet 4e4:200/3e3:100``."""
    if row["engine"] != "pybullet":
        return row["engine"]
    return f"pybullet {row['contact']}"


def closest(rows: list[dict]) -> tuple[str, dict[str, dict[str, float]]]:
    """The PyBullet contact that acts most like MuJoCo on the same episodes: the smallest sum of
    the mean |success rate difference| and the median |log(peak_pybullet / peak_mujoco)| of the
    median peaks, both over the policies."""
    ref = {r["case"]: r for r in rows if r["engine"] == "mujoco"}
    parts: dict[str, dict[str, list[float]]] = {}
    for r in rows:
        m = ref.get(r["case"])
        if r["engine"] != "pybullet" or m is None:
            continue
        gaps = parts.setdefault(label(r), {"success": [], "peak": []})
        gaps["success"].append(abs(r["success_rate"] - m["success_rate"]))
        if m["peak_median_n"] > 0.0 < r["peak_median_n"]:
            gaps["peak"].append(abs(math.log(r["peak_median_n"] / m["peak_median_n"])))
    score = {}
    for k, v in parts.items():
        success, peak = float(np.mean(v["success"])), float(np.median(v["peak"]))
        score[k] = {"success_gap": success, "peak_log_gap": peak, "total": success + peak}
    return min(score, key=lambda k: score[k]["total"]), score


def table(rows: list[dict]) -> str:
    """One line per case and engine/contact."""
    body = []
    for r in rows:
        peaks = [f"{r['peak_median_n']:.1f}", f"{r['peak_p90_n']:.1f}"]
        body.append([r["case"], label(r), f"{r['success_rate']:.3f}", *peaks])
    head = ["policy", "engine / contact", "success", "peak median (N)", "peak p90 (N)"]
    return markdown_table(head, body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0, help="first episode's seed")
    parser.add_argument(
        "--contacts",
        nargs="+",
        default=["rigid", "soft"],
        help='PyBullet scene contacts: "rigid", "soft" or FIXED/CUBE, each part "rigid" or '
        "STIFFNESS:DAMPING (N/m:N s/m)",
    )
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--name", default="pybullet_contact")
    args = parser.parse_args()
    cases = [c for c in args.cases if available(c)]
    jobs = [(c, "mujoco", None) for c in cases]
    jobs += [(c, "pybullet", k) for c in cases for k in args.contacts]
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run_case, *job, args.episodes, args.seed) for job in jobs]
        for future in futures:
            row = future.result()
            rows.append(row)
            print(
                f"{row['case']:>18} {label(row):>16}: success {row['success_rate']:.3f}, peak "
                f"median {row['peak_median_n']:.1f} N ({row['seconds']:.0f} s)",
                flush=True,
            )
    best, score = closest(rows)
    gaps = [[k, f"{v['success_gap']:.3f}", f"{v['peak_log_gap']:.3f}", f"{v['total']:.3f}"]
            for k, v in score.items()]  # fmt: skip
    head = ["contact", "mean abs. success gap", "median abs. log peak ratio", "sum"]
    text = table(rows) + "\n\nGap to MuJoCo over the policies:\n\n" + markdown_table(head, gaps)
    text += f"\n\nClosest to MuJoCo: {best}.\n"
    print(text)
    out = {"meta": environment_metadata(), "config": vars(args), "rows": rows, "score": score,
           "closest": best}  # fmt: skip
    save_results(args.name, out, text, RESULTS_DIR / "contact")


if __name__ == "__main__":
    main()
