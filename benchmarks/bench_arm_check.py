"""``mjx-arm arm --check`` over every arm URDF of a folder: what each arm's derived setup is and
which tasks it can do, or why not.

Each URDF goes through the pipeline as a new user would, as published, then (where that is a
named error) with the converter's repairs (``repair_inertia`` and default effort / velocity
limits). An arm of 5 to 7 joints gets its setup derived for Reach, Touch and Lift
(:func:`mjx_arm.arm.verdict.task_verdict`); a URDF that is no such arm, or that stays invalid,
is a named error; anything else is a crash (a traceback). The goal: no crash, and every verdict
states its reason.

Run from the repository root: ``python benchmarks/bench_arm_check.py`` (default folder: the
installed example-robot-data; ``--robots DIR`` for another, ``--name`` for the file stem).
Results: ``benchmarks/results/arms/NAME.{json,md}``.
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
REPAIRS = {"repair_inertia": True, "default_effort": 50.0, "default_velocity": 2.0}
TASKS = ("reach", "touch", "lift")


def check_one(path: Path, **repairs) -> dict:
    """The outcome of checking ``path``: ``checked`` with each task's verdict and the arm's
    derived facts, ``named error`` with its last line, or ``crash`` with the exception."""
    import numpy as np

    from mjx_arm.arm.config import ArmConfig, ArmConfigError
    from mjx_arm.arm.info import validated_arm_info
    from mjx_arm.arm.setup import arm_setup
    from mjx_arm.arm.verdict import task_verdict
    from mjx_arm.inputs import InputError
    from mjx_arm.task.config import task_config
    from mjx_arm.urdf.errors import UrdfError

    try:
        arm = validated_arm_info(ArmConfig(urdf=str(path), **repairs), "mujoco")
        verdicts = {name: task_verdict(arm, task_config(name)) for name in TASKS}
        touch = arm_setup(arm, task_config("touch"))
    except (ArmConfigError, UrdfError, InputError) as exc:
        return {"outcome": "named error", "message": str(exc).strip().splitlines()[-1][:200]}
    except Exception:  # counting crashes is the point
        return {"outcome": "crash", "message": traceback.format_exc().strip()[-400:]}
    return {
        "outcome": "checked",
        "joints": arm.n_joints,
        "ee_link": arm.ee_link,
        "ee_offset": [round(float(v), 4) for v in arm.ee_offset],
        "kv_factor": round(arm.kv_factor, 3),
        "reach_scale": round(arm.reach_scale, 3),
        "touch_home_height": round(float(_home_height(arm, touch)), 3),
        "verdicts": {name: {"can": ok, "why": why} for name, (ok, why) in verdicts.items()},
        "gripper": None if arm.gripper is None else arm.gripper.joint,
        "full_turn_joints": int(np.sum(arm.full_turn)),
    }


def _home_height(arm, setup) -> float:
    import numpy as np

    from mjx_arm.arm.info import tool_down_solver

    return tool_down_solver(arm).ik.pose(np.asarray(setup.home_qpos))[0][2]


def check_path(path: Path) -> dict:
    """As published, then with the repairs where that was a named error."""
    start = time.perf_counter()
    result = check_one(path)
    if result["outcome"] == "named error":
        repaired = check_one(path, **REPAIRS)
        if repaired["outcome"] != "named error":
            result = {**repaired, "repaired": True}
    return {**result, "seconds": round(time.perf_counter() - start, 2)}


def _row(name: str, result: dict) -> list[str]:
    if result["outcome"] != "checked":
        return [name, result["outcome"], result["message"][:120], "", ""]
    cells = [
        f"{'yes' if v['can'] else 'no'}" + ("" if v["can"] else f": {v['why']}")
        for v in result["verdicts"].values()
    ]
    arm = f"{result['joints']} joints, ee {result['ee_link']}"
    if result.get("repaired"):
        arm += " (repaired)"
    return [name, arm, *cells]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=Path, default=ROBOTS, help="folder of the robots")
    parser.add_argument("--name", default="arm_check", help="file stem of the results")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "arms")
    args = parser.parse_args()
    results = {}
    for path in sorted(args.robots.rglob("*.urdf")):
        name = str(path.relative_to(args.robots))
        results[name] = check_path(path)
        print(f"{name}: {results[name]['outcome']} ({results[name]['seconds']} s)", flush=True)
    arms = {n: r for n, r in results.items() if r["outcome"] == "checked"}
    crashes = sum(r["outcome"] == "crash" for r in results.values())
    summary = (
        f"{len(results)} URDFs: {len(arms)} arms of 5-7 joints checked, "
        f"{len(results) - len(arms) - crashes} named errors, {crashes} crashes"
    )
    rows = [_row(name, r) for name, r in results.items() if r["outcome"] != "named error"]
    table = markdown_table(["URDF", "arm", *TASKS], rows)
    print(f"\n{summary}\n\n{table}")
    meta = environment_metadata()
    save_results(
        args.name,
        {"meta": meta, "robots": str(args.robots), "summary": summary, "results": results},
        f"{summary}\n\n{table}\n",
        args.results_dir,
    )


if __name__ == "__main__":
    main()
