"""Where the sim-to-real chain costs success: one policy under velocity control and through the
chain with each stage changed alone, on the same episodes.

Variants (``--variants``, comma separated):

- ``velocity``: the normal, velocity-controlled env (what the policy was trained on);
- ``held40``: the chain as it was: each command held for a control period, ``K = 40 /s``, no
  feed-forward;
- ``held40_tau0``, ``held40_noacc``, ``held40_grip``: ``held40`` without the adapter's
  filter, with the limiter's acceleration limit out of reach (1e6 rad/s^2), with the gripper's
  stand-in loop at 1000 /s (ablations, not settings to run a robot with);
- ``held10``: held commands at ``K = 10 /s``;
- ``ff40``, ``ff10``: feed-forward stream at ``K = 40`` or ``10 /s``, the correction uncapped
  (10 rad/s);
- ``ff_K_C``: feed-forward stream at ``K`` (1/s), the correction capped at ``C`` (rad/s);
- ``chain``: the chain's defaults (feed-forward stream, ``K = 10 /s``, correction cap
  0.1 rad/s).

Run from the repository root::

    python benchmarks/bench_deploy_chain.py --engine mujoco --episodes 100 \\
        --policies benchmarks/results/policies/lift-fast-seed0.npz

Results: ``benchmarks/results/sim2real/deploy_chain_<name>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

VARIANTS = (
    "velocity",
    "held40",
    "held40_tau0",
    "held40_noacc",
    "held40_grip",
    "held10",
    "ff40",
    "ff10",
    "chain",
)


def chain_config(variant: str):
    """The :class:`ChainConfig` of a chain variant (see the module docstring)."""
    from mjx_arm.sim2real.gripper import GripperConfig
    from mjx_arm.sim2real.limiter import LimiterConfig
    from mjx_arm.sim2real.settings import ChainConfig, ServoConfig

    if variant.startswith("ff_"):
        gain, cap = (float(x) for x in variant.split("_")[1:])
        return ChainConfig(servo=ServoConfig(gain, feedforward=True, correction_limit=cap))
    held = ServoConfig(position_gain=40.0, feedforward=False)
    configs = {
        "held40": ChainConfig(servo=held),
        "held40_tau0": ChainConfig(servo=held, tau=0.0),
        "held40_noacc": ChainConfig(servo=held, limiter=LimiterConfig(acceleration=1e6)),
        "held40_grip": ChainConfig(servo=held, gripper=GripperConfig(position_gain=1000.0)),
        "held10": ChainConfig(servo=ServoConfig(position_gain=10.0, feedforward=False)),
        "ff40": ChainConfig(servo=ServoConfig(40.0, feedforward=True, correction_limit=10.0)),
        "ff10": ChainConfig(servo=ServoConfig(10.0, feedforward=True, correction_limit=10.0)),
        "chain": ChainConfig(),
    }
    return configs[variant]


def run_variant(policy_path: Path, engine: str, variant: str, episodes: int) -> dict:
    """Success, wrist peak and limiter clips of one policy under one variant."""
    from mjx_arm.evaluate import eval_arm, eval_task, make_eval_env, run_episodes, summarize
    from mjx_arm.policy import load
    from mjx_arm.sim2real.position_env import make_position_env

    policy = load(policy_path)
    task, arm = eval_task(policy)[0], eval_arm(policy, None)
    start = time.perf_counter()
    if variant == "velocity":
        env = make_eval_env(task, engine, arm=arm)
    else:
        env = make_position_env(task, engine, chain_config(variant), arm=arm)
    try:
        run = run_episodes(policy, env, episodes, 0)
        clips = 0 if variant == "velocity" else env.unwrapped.limiter.total_clips
    finally:
        env.close()
    summary = summarize(run.episodes)
    peaks = [e.peak_contact_force for e in run.episodes]
    return {
        "policy": policy_path.name,
        "task": task.task,
        "engine": engine,
        "variant": variant,
        "episodes": episodes,
        "success_rate": summary["success_rate"],
        "success_ci95": summary.get("success_ci95"),
        "mean_peak_force_n": sum(peaks) / len(peaks),
        "limiter_clips": clips,
        "seconds": time.perf_counter() - start,
    }


def table(rows: list[dict], variants: list[str]) -> str:
    """Success (mean wrist peak, N) per policy and variant."""
    by = {(r["policy"], r["variant"]): r for r in rows}
    policies = list(dict.fromkeys(r["policy"] for r in rows))
    cells = [
        [p]
        + [
            f"{by[p, v]['success_rate']:.2f} ({by[p, v]['mean_peak_force_n']:.0f})"
            if (p, v) in by
            else ""
            for v in variants
        ]
        for p in policies
    ]
    return markdown_table(["policy", *variants], cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policies", nargs="+", type=Path, required=True)
    parser.add_argument("--engine", default="mujoco", choices=("mujoco", "pybullet"))
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--variants", default="velocity,held40,chain")
    parser.add_argument("--name", default=None, help="results name (default: task and engine)")
    args = parser.parse_args()
    variants = args.variants.split(",")
    unknown = {v for v in variants if not v.startswith("ff_")} - set(VARIANTS)
    if unknown:
        parser.error(f"unknown variants {sorted(unknown)}; choose from {VARIANTS}")
    rows = []
    for path in args.policies:
        for variant in variants:
            row = run_variant(path, args.engine, variant, args.episodes)
            rows.append(row)
            print(
                f"{path.name} {args.engine} {variant}: success {row['success_rate']:.2f}, "
                f"peak {row['mean_peak_force_n']:.1f} N, clips {row['limiter_clips']}, "
                f"{row['seconds']:.0f} s",
                flush=True,
            )
    name = args.name or f"deploy_chain_{rows[0]['task']}_{args.engine}"
    md = (
        f"# deploy-sim chain: {rows[0]['task']} on {args.engine}, {args.episodes} episodes "
        "per cell (seeds 0..N-1)\n\nSuccess rate (mean wrist peak force, N).\n\n"
        + table(rows, variants)
    )
    payload = {"meta": environment_metadata(), "engine": args.engine, "rows": rows}
    save_results(name, payload, md, RESULTS_DIR / "sim2real")
    print(md)


if __name__ == "__main__":
    main()
