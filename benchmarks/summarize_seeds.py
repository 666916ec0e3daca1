"""Summarise the seeds runs of one folder: seeds solved and transfer per arm, task and preset.

Reads the seeds results (``seeds_*.json``, one or more per (arm, task, preset), written by
``mjx-arm bench seeds``, e.g. through ``gpu_suite.sh arms``) and the transfer results of their
exported policies (``transfer/*.json``, written by ``mjx-arm bench transfer``; a policy file's
name ends in ``TASK-PRESET-seedN``) under a folder such as
``benchmarks/results/arms/any_arm/final`` and writes ``summary.json`` and
``summary.md`` beside them: per (arm, task, preset), each seed's best MJX success, whether it
reached the task's threshold, and its exported policy's success and mean peak force in CPU
MuJoCo and PyBullet. The arm is named by its URDF's file name, as each run recorded it.

    python -m benchmarks.summarize_seeds benchmarks/results/arms/any_arm/final
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
POLICY_NAME = re.compile(r"(?:^|[-_])(?P<task>[a-z]+)-(?P<preset>[a-z]+)-seed(?P<seed>\d+)$")
Key = tuple[str, str, str]  # (arm, task, preset)


def arm_name(record: dict[str, Any]) -> str:
    """The arm a run or policy records, by its URDF's file name (``ur10_robot``)."""
    return Path(record["config"]["urdf"]).stem


def seed_rows(folder: Path) -> dict[Key, dict[int, dict[str, Any]]]:
    """Each (arm, task, preset)'s seeds: ``{seed: {"best": success, "wall_s": s, ...}}``."""
    rows: dict[Key, dict[int, dict[str, Any]]] = defaultdict(dict)
    for path in sorted(folder.glob("seeds_*.json")):
        data = json.loads(path.read_text())
        settings = data["settings"]
        key = (arm_name(data["configs"][0]["arm"]), settings["task"], settings["preset"])
        for run in data["seeds"]:
            rows[key][run["seed"]] = {
                "best": run["best_success"],
                "wall_s": run["wall_s"],
                "compile_s": run["compile_s"],
            }
    return rows


def own_policy(folder: Path, recorded: Path) -> Path | None:
    """A transfer result's policy file: the folder's own copy first (the recorded path is where
    the policy was when its transfer ran; a folder renamed since leaves it dangling), else the
    recorded path; None where neither exists."""
    return next((p for p in (folder / "policies" / recorded.name, recorded) if p.is_file()), None)


def transfer_rows(folder: Path) -> dict[tuple[str, str, str, int], dict[str, Any]]:
    """Each exported policy's transfer: ``{(arm, task, preset, seed): {engine: (success, peak
    N)}}``; the arm is the policy's own record."""
    from mjx_arm.policy import load

    found: dict[tuple[str, str, str, int], dict[str, Any]] = {}
    for path in sorted((folder / "transfer").glob("*.json")):
        data = json.loads(path.read_text())
        policy = Path(data["policy"])
        match = POLICY_NAME.search(policy.stem)
        policy = own_policy(folder, policy)
        if match is None or policy is None:
            continue
        arm = arm_name(load(policy).metadata["arm"])
        engines = {
            row["engine"]: (row["success_rate"], row["mean_peak_contact_force"])
            for row in data["rows"]
        }
        found[(arm, match["task"], match["preset"], int(match["seed"]))] = engines
    return found


def summarize(folder: Path) -> dict[str, Any]:
    """The summary of ``folder``: a list of (arm, task) entries with their seeds."""
    transfers = transfer_rows(folder)
    entries = []
    for (arm, task, preset), seeds in sorted(seed_rows(folder).items()):
        threshold = THRESHOLDS[task]
        per_seed = []
        for seed, run in sorted(seeds.items()):
            per_seed.append(
                {
                    "seed": seed,
                    "best_success": run["best"],
                    "solved": run["best"] >= threshold,
                    "transfer": transfers.get((arm, task, preset, seed), {}),
                }
            )
        entries.append(
            {
                "arm": arm,
                "task": task,
                "preset": preset,
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
        f"# Seeds and transfer (`{summary['folder']}`)",
        "",
        "| arm | task, preset | seeds at threshold | best MJX success per seed | exported "
        "policy per seed: CPU MuJoCo / PyBullet (mean peak force) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for e in summary["entries"]:
        best = ", ".join(f"{s['best_success']:.3f}" for s in e["seeds"])
        transfer = "; ".join(f"seed {s['seed']}: {transfer_text(s)}" for s in e["seeds"])
        lines.append(
            f"| {e['arm']} | {e['task']}, {e['preset']} (>= {e['threshold']}) | {e['solved']} of "
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
