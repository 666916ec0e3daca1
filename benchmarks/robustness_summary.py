"""One table over saved ``mjx-arm bench robustness`` results: per policy, the pooled nominal
success, the joint draw, and per perturbation the worst success inside its stated range.

Usage: python -m benchmarks.robustness_summary [RESULT.json ...]
(default: every benchmarks/results/robustness/robustness_*.json); writes summary.md and
summary.json beside them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, markdown_table, save_results

FOLDER = RESULTS_DIR / "robustness"


def policy_label(path: Path) -> str:
    """A policy file's name, with the folder of its run where it sits in a ``policies/``
    folder (``seeds_cradle/shipped_lift_lift-fast-seed0.npz``): runs of several code versions
    export files of the same name."""
    if path.parent.name == "policies":
        return f"{path.parent.parent.name}/{path.name}"
    return path.name


def policy_row(result: dict) -> dict:
    """One policy's figures from its saved result."""
    summary = result["summary"]
    pool = summary["nominal_pooled"]
    joint = next(r for r in result["rows"] if r["perturbation"] == "joint draw")
    return {
        "policy": policy_label(Path(result["policy"])),
        "task": result["task"],
        "episodes_per_point": result["config"]["episodes"],
        "nominal_pooled": pool["success_rate"],
        "nominal_ci95": pool["success_ci95"],
        "joint": joint["success_rate"],
        "joint_ci95": joint["success_ci95"],
        "joint_mean_peak_force": joint["mean_peak_force"],
        "worst_inside": {k: v["worst_inside"] for k, v in summary["per_perturbation"].items()},
        "below_goal_at": {k: v["below_goal_at"] for k, v in summary["per_perturbation"].items()},
    }


def main(paths: list[Path]) -> None:
    rows = [policy_row(json.loads(p.read_text())) for p in paths]
    names = sorted({k for r in rows for k in r["worst_inside"]}, key=str)
    headers = ["policy", "eps/point", "nominal (pooled)", "joint draw", *names]
    table = []
    for r in rows:
        lo, hi = r["nominal_ci95"]
        jlo, jhi = r["joint_ci95"]
        cells = [f"{r['worst_inside'][n]:.2f}" if n in r["worst_inside"] else "" for n in names]
        table.append([
            r["policy"], r["episodes_per_point"], f"{r['nominal_pooled']:.3f} [{lo:.2f}, {hi:.2f}]",
            f"{r['joint']:.3f} [{jlo:.2f}, {jhi:.2f}]", *cells,
        ])  # fmt: skip
    text = (
        "Worst success inside each perturbation's stated range (goal >= 0.9; joint draw goal "
        ">= 0.85), C MuJoCo batch on a 2-core CPU.\n\n" + markdown_table(headers, table)
    )
    print(text)
    for path in save_results("summary", {"policies": rows}, text, FOLDER):
        print(f"wrote {path}")


if __name__ == "__main__":
    given = [Path(a) for a in sys.argv[1:]]
    main(given or sorted(FOLDER.glob("robustness_*.json")))
