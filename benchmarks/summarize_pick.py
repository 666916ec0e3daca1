"""Lift on the Panda beside MuJoCo Playground's PandaPickCube, from runs on one machine.

Reads a folder holding this project's Lift seeds runs on the Panda (``seeds_lift_*.json``,
written by ``mjx-arm bench seeds --task lift --arm panda.urdf``) and Playground's runs
(``playground/*.json``, written by :mod:`benchmarks.bench_playground_pick`), and writes
``comparison.json`` and ``comparison.md`` beside them: per seed, whether it reached the
threshold, the steps and wall seconds to it (compiles included; the first run of each side
started with empty caches), and each side's training rate.

    python -m benchmarks.summarize_pick benchmarks/results/arms/any_arm/pick
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from benchmarks.common import markdown_table, save_results


def ours(folder: Path) -> list[dict[str, Any]]:
    """This project's seeds, in file order (the first file ran with empty caches)."""
    rows = []
    for path in sorted(folder.glob("seeds_lift_*.json")):
        data = json.loads(path.read_text())
        threshold = data["summary"]["threshold"]
        for run in data["seeds"]:
            rows.append({
                "side": "mjx_arm Lift, Panda (example-robot-data URDF, no arm file)",
                "seed": run["seed"],
                "threshold": threshold,
                "success": run["best_success"],
                "reached": run["steps_to_threshold"] is not None,
                "steps_to_threshold": run["steps_to_threshold"],
                "time_to_threshold_s": run["time_to_threshold"],
                "compile_s": run["compile_s"],
                "steps_per_s": run["training_steps_per_s"],
                "source": path.name,
            })  # fmt: skip
    return rows


def playground(folder: Path) -> list[dict[str, Any]]:
    """Playground's seeds: the lift criterion's time to its threshold."""
    rows = []
    for path in sorted((folder / "playground").glob("*.json")):
        data = json.loads(path.read_text())
        rows.append({
            "side": "Playground PandaPickCube (menagerie MJX Panda), its PPO config",
            "seed": data["seed"],
            "threshold": data["threshold"],
            "success": max(p["lift"] for p in data["curve"]),
            "final_success": data["final"]["lift"],
            "reached": data["steps_to_threshold"]["lift"] is not None,
            "steps_to_threshold": data["steps_to_threshold"]["lift"],
            "time_to_threshold_s": data["time_to_threshold_s"]["lift"],
            "compile_s": data["curve"][0]["wall_s"],
            "steps_per_s": data["steps_per_s"],
            "total_steps": data["total_steps"],
            "train_s": data["train_s"],
            "source": f"playground/{path.name}",
        })  # fmt: skip
    return rows


def main() -> None:
    """Command line: write comparison.json and comparison.md into the folder."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path)
    args = parser.parse_args()
    rows = ours(args.folder) + playground(args.folder)
    meta = json.loads(next(args.folder.glob("seeds_lift_*.json")).read_text())["meta"]

    def num(x: Any, spec: str) -> str:
        return "not reached" if x is None else format(x, spec)

    table = markdown_table(
        ["side", "seed", "threshold", "best success", "steps to it", "wall s to it",
         "compile or first eval (s)", "training steps/s"],
        [[r["side"], r["seed"], r["threshold"], f"{r['success']:.3f}",
          num(r["steps_to_threshold"], ",d"), num(r["time_to_threshold_s"], ".1f"),
          f"{r['compile_s']:.1f}", f"{r['steps_per_s']:,.0f}"] for r in rows],
    )  # fmt: skip
    note = (
        "Wall seconds from each run's start, compiles included; the first run of each side "
        "started with empty compile caches, the others on warm ones. Success: the cube (box) "
        "held 10 cm or more above its start for 10 control steps (Playground's box: its centre; "
        "its control step is 20 ms, ours 33 ms)."
    )
    print(table + "\n\n" + note)
    save_results("comparison", {"meta": meta, "rows": rows}, table + "\n\n" + note, args.folder)


if __name__ == "__main__":
    main()
