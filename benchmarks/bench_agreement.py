"""Engine agreement: MJX on Warp and on JAX against C MuJoCo, same states and actions.

A case of ``mjx-arm bench parity`` (:mod:`mjx_arm.bench.parity`): forward kinematics, open-loop
joint divergence, the tared F/T reading while pressing the box, and jitter, for C MuJoCo and
both MJX implementations. Any flag of ``mjx-arm bench parity`` can be added::

    python benchmarks/bench_agreement.py --sequences 64
"""

from __future__ import annotations

import sys

from mjx_arm.cli import main

DEFAULTS = ("--engines", "mujoco", "mjx", "--impls", "warp", "jax")
OUT = "benchmarks/results/agreement"

if __name__ == "__main__":
    sys.exit(main(["bench", "parity", *DEFAULTS, "--out", OUT, *sys.argv[1:]]))
