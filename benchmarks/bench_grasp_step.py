"""Which physics step holds a cube picked off the table: the grasp check's pick (``table`` start,
:mod:`mjx_arm.bench.grasp`) at several physics steps and cubes, in each engine.

The control period stays 1/30 s and the servos keep their 240 Hz gains (the finger presses
23.7 N at every step), so only the integration step changes. Each row: the lift of the cube
(m), its slip in the fingers over the 2 s hold (mm) and whether it was held with a slip of at
most 5 mm (the grasp check's goal). Cubes: the lift scene's (4.5 cm, 0.1 kg, friction 1) and
the corners of a Lift task's randomisation (4 and 5 cm; 0.05 and 0.2 kg; friction 0.7 and 1).

Run from the repository root: ``python benchmarks/bench_grasp_step.py [--engines mujoco mjx]``.
Results: ``benchmarks/results/grasp/grasp_step.{json,md}``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS_DIR, environment_metadata, markdown_table, save_results

RATES = (240, 480, 720, 960)  # physics steps per second
CUBES = (
    (0.0225, 0.1, 1.0),  # the lift scene's cube
    *itertools.product((0.02, 0.025), (0.05, 0.2), (0.7, 1.0)),
)


def run_all(engines: list[str], rates: tuple[int, ...]) -> list[dict]:
    """One row per engine, rate and cube, printed as it finishes."""
    from mjx_arm.bench import grasp

    arm = grasp.gripper_arm()
    rows = []
    for rate, (half, mass, friction) in itertools.product(rates, CUBES):
        cube = grasp.Cube(half, mass, friction)
        model = grasp.grasp_model(arm, 1.0 / rate, cube)
        script = grasp.record_script(model, arm, "table")
        for engine in engines:
            start = time.perf_counter()
            run = grasp.run_engine(engine, model, arm, script)
            met = run["met"]
            row = {"engine": engine, "rate_hz": rate, "cube_half_m": half, "cube_mass_kg": mass,
                   "friction": friction, **run, "seconds": time.perf_counter() - start}  # fmt: skip
            rows.append(row)
            print(
                f"{engine:>8} {rate:>4} Hz cube {2000 * half:.0f} mm {mass} kg mu {friction}: "
                f"lift {run['lift_m']:.3f} m, slip {1000 * run['slip_m']:.2f} mm, "
                f"{'held' if met else 'MISS'}",
                flush=True,
            )
    return rows


def summary_table(rows: list[dict], engines: list[str], rates: tuple[int, ...]) -> str:
    """Cubes held (of all cubes) per engine and rate."""
    lines = []
    for engine in engines:
        cells = []
        for rate in rates:
            mine = [r for r in rows if r["engine"] == engine and r["rate_hz"] == rate]
            cells.append(f"{sum(r['met'] for r in mine)} of {len(mine)}")
        lines.append([engine, *cells])
    return markdown_table(["engine", *(f"{r} Hz" for r in rates)], lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--engines", nargs="+", default=["mujoco", "pybullet", "mjx"])
    parser.add_argument("--rates", nargs="+", type=int, default=list(RATES))
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "grasp")
    args = parser.parse_args()
    rates = tuple(args.rates)
    rows = run_all(args.engines, rates)
    table = summary_table(rows, args.engines, rates)
    detail = markdown_table(
        ["engine", "Hz", "cube (mm)", "mass (kg)", "friction", "lift (m)", "slip (mm)", "held"],
        [[r["engine"], r["rate_hz"], f"{2000 * r['cube_half_m']:.0f}", r["cube_mass_kg"],
          r["friction"], f"{r['lift_m']:.3f}", f"{1000 * r['slip_m']:.2f}",
          "pass" if r["met"] else "MISS"] for r in rows],
    )  # fmt: skip
    print(table)
    payload = {"meta": environment_metadata(accelerator="mjx" in args.engines), "rows": rows}
    text = f"Cubes held with at most 5 mm slip, of {len(CUBES)}:\n\n{table}\n\n{detail}\n"
    save_results("grasp_step", payload, text, args.results_dir)


if __name__ == "__main__":
    main()
