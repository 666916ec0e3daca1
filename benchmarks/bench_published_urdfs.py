"""Every URDF of the installed example-robot-data package through the MuJoCo conversion.

Each URDF is converted twice, as a new user would: as published, then with the converter's
repair options (``repair_inertia`` and default effort / velocity limits). A URDF counts as
converted, as a named error (a ``UrdfError`` or ``ConversionError`` that says what to fix) or as
a crash (any other exception: a traceback). The goal: no crash.

Run from the repository root: ``python benchmarks/bench_published_urdfs.py``.
Results: ``benchmarks/results/arms/published_urdfs.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import sysconfig
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
REPAIRS = {"repair_inertia": True, "default_effort": 10.0, "default_velocity": 1.0}


def convert_one(path: Path, **options) -> tuple[str, str]:
    """(outcome, first line of the message) of converting ``path`` to MJCF."""
    from mjx_arm.urdf import to_mjcf
    from mjx_arm.urdf.errors import UrdfError

    try:
        to_mjcf(path, **options)
    except UrdfError as exc:  # ConversionError included
        return "named error", str(exc).strip().splitlines()[-1][:200]
    except Exception:  # counting crashes is the point
        return "crash", traceback.format_exc().strip().splitlines()[-1][:200]
    return "converted", ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=Path, default=ROBOTS, help="folder of the robots")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "arms")
    args = parser.parse_args()
    rows = []
    for path in sorted(args.robots.rglob("*.urdf")):
        start = time.perf_counter()
        plain, note = convert_one(path)
        repaired, repaired_note = (
            convert_one(path, **REPAIRS) if plain != "converted" else (plain, "")
        )
        row = {
            "urdf": str(path.relative_to(args.robots)),
            "as_published": plain,
            "with_repairs": repaired,
            "error": repaired_note or note,
            "seconds": time.perf_counter() - start,
        }
        rows.append(row)
        print(f"{row['as_published']:>12} | {row['with_repairs']:>12} | {row['urdf']}", flush=True)
    published = sum(r["as_published"] == "converted" for r in rows)
    repaired = sum(r["with_repairs"] == "converted" for r in rows)
    crashes = sum("crash" in (r["as_published"], r["with_repairs"]) for r in rows)
    summary = (
        f"{len(rows)} URDFs: {published} convert as published, {repaired - published} more with "
        f"--repair-inertia and default limits, {len(rows) - repaired} named errors left, "
        f"{crashes} crashes"
    )
    table = markdown_table(
        ["URDF", "as published", "with repairs", "error left"],
        [[r["urdf"], r["as_published"], r["with_repairs"], r["error"]] for r in rows],
    )
    print(summary)
    payload = {"meta": environment_metadata(), "summary": summary, "rows": rows}
    save_results("published_urdfs", payload, f"{summary}\n\n{table}\n", args.results_dir)


if __name__ == "__main__":
    main()
