"""Summarise the published-arm runs of one code version: seeds solved and transfer per arm and task.

Reads the seeds results (``seeds_*.json``, one or more per (arm, task), written by
``gpu_suite.sh arms``) and the transfer results (``transfer/*.json``, written by
``mjx-arm bench transfer``) under a folder such as
``benchmarks/results/arms/any_arm/final_2e708e5`` and writes ``summary.json`` and
``summary.md`` beside them: per (arm, task), each seed's best MJX success, whether it reached the
task's threshold, and its exported policy's success and mean peak force in CPU MuJoCo and
PyBullet.

    python -m benchmarks.summarize_any_arm benchmarks/results/arms/any_arm/final_2e708e5
"""

from __future__ import annotations

import argparse
import json
import re
from collections import defaultdict
from pathlib import Path
from typing import Any

# Success a seed must reach in MJX: the issue-level goals (Lift 0.9, Reach and Touch 0.95).
THRESHOLDS = {"reach": 0.95, "touch": 0.95, "lift": 0.9}
SEEDS_NAME = re.compile(r"seeds_(?P<task>[a-z]+)_fast_(?P<arm>.+?)(_x\d+)?_seed[\d-]+$")
POLICY_NAME = re.compile(r"(?P<arm>.+)-(?P<task>[a-z]+)-fast-seed(?P<seed>\d+)$")


def seed_rows(folder: Path) -> dict[tuple[str, str], dict[int, dict[str, Any]]]:
    """Each (arm, task)'s seeds: ``{seed: {"best": success, "wall_s": s, "compile_s": s}}``."""
    rows: dict[tuple[str, str], dict[int, dict[str, Any]]] = defaultdict(dict)
    for path in sorted(folder.glob("seeds_*.json")):
        match = SEEDS_NAME.match(path.stem)
        if match is None:
            continue
        for run in json.loads(path.read_text())["seeds"]:
            rows[(match["arm"], match["task"])][run["seed"]] = {
                "best": run["best_success"],
                "wall_s": run["wall_s"],
                "compile_s": run["compile_s"],
            }
    return rows


def transfer_rows(folder: Path) -> dict[tuple[str, str, int], dict[str, Any]]:
    """Each exported policy's transfer: ``{(arm, task, seed): {engine: (success, peak N)}}``."""
    found: dict[tuple[str, str, int], dict[str, Any]] = {}
    for path in sorted((folder / "transfer").glob("*.json")):
        match = POLICY_NAME.match(path.stem)
        if match is None:
            continue
        # exported as NAME_RUN where RUN starts with NAME again: "ur5_robot_ur5_robot"
        arm = match["arm"][(len(match["arm"]) + 1) // 2 :]
        engines = {
            row["engine"]: (row["success_rate"], row["mean_peak_contact_force"])
            for row in json.loads(path.read_text())["rows"]
        }
        found[(arm, match["task"], int(match["seed"]))] = engines
    return found


def summarize(folder: Path) -> dict[str, Any]:
    """The summary of ``folder``: a list of (arm, task) entries with their seeds."""
    transfers = transfer_rows(folder)
    entries = []
    for (arm, task), seeds in sorted(seed_rows(folder).items()):
        threshold = THRESHOLDS[task]
        per_seed = []
        for seed, run in sorted(seeds.items()):
            per_seed.append(
                {
                    "seed": seed,
                    "best_success": run["best"],
                    "solved": run["best"] >= threshold,
                    "transfer": transfers.get((arm, task, seed), {}),
                }
            )
        entries.append(
            {
                "arm": arm,
                "task": task,
                "threshold": threshold,
                "solved": sum(s["solved"] for s in per_seed),
                "seeds": per_seed,
            }
        )
    first = next(iter(sorted(folder.glob("seeds_*.json"))), None)
    meta = json.loads(first.read_text()).get("meta", {}) if first else {}
    return {"meta": meta, "folder": folder.name, "entries": entries}


def markdown(summary: dict[str, Any]) -> str:
    """The summary as a markdown table, a row per (arm, task)."""

    def transfer_text(seed: dict[str, Any]) -> str:
        t = seed["transfer"]
        if not t:
            return "not run"
        engines = [e for e in ("mujoco", "pybullet") if e in t]
        return " / ".join(f"{t[e][0]:.3f} ({t[e][1]:.0f} N)" for e in engines)

    lines = [
        f"# Published arms, no arm file (`{summary['folder']}`)",
        "",
        "| arm | task | seeds at threshold | best MJX success per seed | exported policy per seed: "
        "CPU MuJoCo / PyBullet (mean peak force) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for e in summary["entries"]:
        best = ", ".join(f"{s['best_success']:.3f}" for s in e["seeds"])
        transfer = "; ".join(f"seed {s['seed']}: {transfer_text(s)}" for s in e["seeds"])
        lines.append(
            f"| {e['arm']} | {e['task']} (>= {e['threshold']}) | {e['solved']} of "
            f"{len(e['seeds'])} | {best} | {transfer} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    folder = parser.parse_args().folder
    summary = summarize(folder)
    (folder / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    (folder / "summary.md").write_text(markdown(summary))
    print(markdown(summary))


if __name__ == "__main__":
    main()
