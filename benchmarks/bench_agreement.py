"""Engine agreement: MJX on Warp and on JAX against C MuJoCo, same states and actions.

Forward kinematics at random joint angles, joint angles after open-loop actions in free motion,
and the tared F/T reading while pressing the box (commands recorded in C MuJoCo, replayed in
MJX); see :mod:`mjx_arm.envs.agreement`. Prints a table and saves JSON::

    python benchmarks/bench_agreement.py --impls warp jax --sequences 64
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import environment_metadata, markdown_table, save_results

GOALS = {"fk_max_m": 1e-6, "open_loop_median_rad": 1e-2, "press_force_rel_warp": 0.05}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--impls", nargs="+", default=["warp", "jax"])
    parser.add_argument("--configs", type=int, default=64, help="random poses for FK")
    parser.add_argument("--sequences", type=int, default=64, help="open-loop action sequences")
    parser.add_argument("--seconds", type=float, default=1.0, help="open-loop duration")
    parser.add_argument("--name", default=None)
    parser.add_argument("--results-dir", type=Path, default=None)
    args = parser.parse_args()

    from mjx_arm.envs.agreement import agreement

    start = time.time()
    figures = agreement(tuple(args.impls), args.configs, args.sequences, args.seconds)
    rows = [
        [
            f"MJX {impl} vs C MuJoCo",
            f"{f['fk_max_m']:.1e}",
            f"{f['open_loop_qpos_median_rad']:.1e}",
            f"{f['open_loop_qpos_max_rad']:.1e}",
            " / ".join(f"{a:.1f}" for a in f["press_force_mjx_n"]),
            " / ".join(f"{c:.1f}" for c in f["press_force_c_n"]),
            f"{100 * f['press_force_max_rel']:.2f}%",
        ]
        for impl, f in figures.items()
    ]
    headers = [
        "pair",
        "FK max (m)",
        f"joints after {args.seconds:g} s, median (rad)",
        "max (rad)",
        "press |F| MJX (N)",
        "press |F| C (N)",
        "press max rel. diff",
    ]
    table = markdown_table(headers, rows)
    print(table)
    meta = environment_metadata(accelerator=True)
    name = args.name or f"agreement_{meta['device']['kind'].replace(' ', '_')}"
    save_results(
        name,
        {
            "meta": meta,
            "settings": vars(args) | {"results_dir": None},
            "figures": figures,
            "goals": GOALS,
            "wall_s": time.time() - start,
        },
        table,
        args.results_dir,
    )


if __name__ == "__main__":
    main()
