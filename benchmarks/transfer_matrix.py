"""Transfer matrix: one trained policy evaluated in every engine of the contract.

Engines: MJX (the batched JAX env), the C MuJoCo batched backend, the CPU MuJoCo Gymnasium env
and the PyBullet reference env. Each row gives the success rate with its 95% Wilson interval,
the mean return, mean steps to success and mean peak contact force, beside the goal.

    python benchmarks/transfer_matrix.py RUN_DIR_OR_POLICY --episodes 200 --name transfer_touch
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import environment_metadata, markdown_table, save_results

# (label, engine, batched backend, goal success rate)
ENGINES = (
    ("MJX", "mjx", "mjx", 0.95),
    ("C MuJoCo batch", "mjx", "mujoco", 0.90),
    ("CPU MuJoCo (Gymnasium)", "mujoco", None, 0.90),
    ("PyBullet (Gymnasium)", "pybullet", None, 0.80),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("policy", help="policy file or run directory (newest checkpoint)")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--skip", nargs="*", default=[], help="labels to skip, e.g. MJX")
    parser.add_argument("--trained-on", default="", help="where the policy was trained (text)")
    parser.add_argument("--name", default="transfer")
    parser.add_argument("--results-dir", type=Path, default=None)
    args = parser.parse_args()

    from mjx_arm.evaluate import eval_task, evaluate, resolve_policy

    policy, source = resolve_policy(args.policy)
    task, _ = eval_task(policy)
    rows = []
    for label, engine, backend, goal in ENGINES:
        if label in args.skip:
            continue
        result, _ = evaluate(policy, engine, task, args.episodes, args.seed, backend=backend)
        result.pop("per_episode", None)
        result.update(label=label, goal=goal)
        rows.append(result)
        print(
            label,
            {k: result[k] for k in ("success_rate", "success_ci95", "mean_return")},
            flush=True,
        )
    headers = [
        "engine",
        "episodes",
        "success",
        "95% CI",
        "mean return",
        "steps to success",
        "peak force (N)",
        "goal",
        "",
    ]
    table = markdown_table(
        headers,
        [
            [
                r["label"],
                r["episodes"],
                f"{r['success_rate']:.3f}",
                f"{r['success_ci95'][0]:.3f}-{r['success_ci95'][1]:.3f}",
                f"{r['mean_return']:.1f}",
                _fmt(r.get("mean_steps_to_success")),
                _fmt(r.get("mean_peak_contact_force")),
                f">= {r['goal']:.2f}",
                "pass" if r["success_rate"] >= r["goal"] else "MISS",
            ]
            for r in rows
        ],
    )
    title = f"Task {task.task}; policy {source}; trained on {args.trained_on or 'see run'}.\n\n"
    print(title + table)
    save_results(
        args.name,
        {
            "meta": environment_metadata(accelerator=True),
            "policy": source,
            "trained_on": args.trained_on,
            "task": task.task,
            "rows": rows,
        },
        title + table,
        args.results_dir,
    )


def _fmt(value) -> str:
    return "n/a" if value is None else f"{value:.1f}"


if __name__ == "__main__":
    main()
