"""Transfer matrix: one trained policy evaluated in every engine of the contract.

The same as ``mjx-arm bench transfer`` (:mod:`mjx_arm.bench.transfer`), whose flags it takes::

    python benchmarks/transfer_matrix.py RUN_DIR_OR_POLICY --episodes 200 --name transfer_touch
"""

from __future__ import annotations

import sys

from mjx_arm.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "transfer", *sys.argv[1:]]))
