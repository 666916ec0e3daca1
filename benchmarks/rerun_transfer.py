"""Measure some engines of saved transfer results again, after a change to those engines.

For each ``transfer/*.json`` given (written by ``mjx-arm bench transfer``), the policy it names
is evaluated again in the chosen engines (default: PyBullet) with the file's own settings
(episodes, first seed, arm, contact model). Those rows are replaced; the rows they replace go to
the file's ``history`` with their date, commit and the reason given, and the other engines' rows
stay as they were (their code did not change). The markdown beside it is written anew.

    python -m benchmarks.rerun_transfer --reason "PyBullet servo implicit" FILE.json [...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from benchmarks.common import environment_metadata
from benchmarks.summarize_seeds import own_policy
from mjx_arm.bench.transfer import TransferConfig, transfer_matrix, write_report


def rerun(path: Path, engines: tuple[str, ...], reason: str) -> dict[str, Any]:
    """Re-measure ``engines`` of one transfer result in place; returns the new payload."""
    from mjx_arm.evaluate import eval_task, resolve_policy

    data = json.loads(path.read_text())
    config = TransferConfig(**{**data["config"], "engines": tuple(engines)})
    recorded = Path(data["policy"])
    policy, _ = resolve_policy(str(own_policy(path.parent.parent, recorded) or recorded))
    task, _ = eval_task(policy, data["task"])
    fresh = transfer_matrix(policy, task, config, jax_backend="cpu")
    new_rows = {row["key"]: row for row in fresh["rows"]}
    old_rows = [row for row in data["rows"] if row["key"] in new_rows]
    rows = [new_rows.pop(row["key"], row) for row in data["rows"]] + list(new_rows.values())
    history = [
        *data.get("history", []),
        {
            "date": data["meta"].get("date"),
            "git_commit": data["meta"].get("git_commit"),
            "replaced_because": reason,
            "rows": old_rows,
        },
    ]
    matrix = {
        "config": data["config"],
        "task": data["task"],
        "rows": rows,
        "notes": data.get("notes", []),
        "history": history,
    }
    write_report(
        matrix,
        environment_metadata(),
        path.parent,
        path.stem,
        data["policy"],
        data.get("trained_on", ""),
    )
    return matrix


def main() -> None:
    """Command line: re-measure each file, print one line per engine."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--engines", nargs="+", default=["pybullet"])
    parser.add_argument("--reason", required=True, help="why the rows are measured again")
    args = parser.parse_args()
    for path in args.files:
        matrix = rerun(path, tuple(args.engines), args.reason)
        old = {r["key"]: r for r in matrix["history"][-1]["rows"]}
        for row in matrix["rows"]:
            if row["key"] in args.engines:
                before = old.get(row["key"], {}).get("success_rate")
                print(
                    f"{path}: {row['label']} {before} -> {row['success_rate']:.3f} "
                    f"(peak {row['mean_peak_contact_force']})",
                    flush=True,
                )


if __name__ == "__main__":
    main()
