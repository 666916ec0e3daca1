"""Did a run repeat? Two run directories of the same config compared, row by row and
checkpoint by checkpoint, down to the bit.

``mjx-arm train ... --check-repeat`` trains the same config twice and calls
:func:`compare_runs`: the first evaluation step where a logged figure differs, or the first
checkpoint whose params differ, is what a user needs to know where two runs part.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

# Columns that measure time, which no two runs share.
TIMING_COLUMNS = frozenset(
    {
        "time",
        "eval/walltime",
        "eval/epoch_eval_time",
        "eval/sps",
        "training/sps",
        "training/walltime",
        "training/rollout_s",
        "training/update_s",
    }
)


@dataclass(frozen=True)
class RepeatReport:
    """How two runs compare.

    Attributes:
        rows: evaluations compared (the shorter run's count).
        checkpoints: checkpoints whose params were compared.
        first_step: the first step where they differ (None: identical).
        column: what differs there (a metrics column, or ``params``).
        values: the two runs' values of that column at that step.
    """

    rows: int
    checkpoints: int
    first_step: int | None = None
    column: str = ""
    values: tuple[float, float] = (0.0, 0.0)

    @property
    def identical(self) -> bool:
        """Whether nothing compared differs."""
        return self.first_step is None

    def line(self) -> str:
        """One line for the console."""
        if self.identical:
            return (
                f"repeat: identical ({self.rows} evaluations, {self.checkpoints} checkpoints, "
                "bit for bit)"
            )
        a, b = self.values
        return (
            f"repeat: the runs part at step {self.first_step:,}: {self.column} "
            f"{a!r} vs {b!r} ({self.rows} evaluations compared)"
        )


def compare_runs(a: str | Path, b: str | Path) -> RepeatReport:
    """Compare run directories ``a`` and ``b``: every metrics row but its timing columns,
    then the params of every checkpoint they share. The first difference in step order wins."""
    from mjx_arm.train.rundir import RunDir

    rows_a, rows_b = RunDir(a).read_metrics(), RunDir(b).read_metrics()
    rows = min(len(rows_a), len(rows_b))
    row_diff = _first_row_difference(rows_a[:rows], rows_b[:rows])
    ckpt_a, ckpt_b = _checkpoints(a), _checkpoints(b)
    steps = sorted(set(ckpt_a) & set(ckpt_b))
    param_step = next((s for s in steps if not _same_params(ckpt_a[s], ckpt_b[s])), None)
    report = RepeatReport(rows, len(steps))
    if row_diff is not None and (param_step is None or row_diff[0] <= param_step):
        return RepeatReport(rows, len(steps), *row_diff)
    if param_step is not None:
        return RepeatReport(rows, len(steps), param_step, "params", (np.nan, np.nan))
    return report


def _first_row_difference(
    rows_a: list[dict[str, float]], rows_b: list[dict[str, float]]
) -> tuple[int, str, tuple[float, float]] | None:
    """(step, column, values) of the first metrics value that differs, bit for bit."""
    for ra, rb in zip(rows_a, rows_b, strict=True):
        for column in sorted(set(ra) | set(rb)):
            if column in TIMING_COLUMNS:
                continue
            va, vb = ra.get(column, np.nan), rb.get(column, np.nan)
            if not _same_bits(va, vb):
                return int(ra.get("step", -1)), column, (va, vb)
    return None


def _same_bits(a: float, b: float) -> bool:
    return np.float64(a).tobytes() == np.float64(b).tobytes()


def _checkpoints(run: str | Path) -> dict[int, Path]:
    """Step -> checkpoint folder of a run."""
    from mjx_arm.train.rundir import RunDir

    folder = Path(run) / "checkpoints"
    found = {}
    for path in sorted(folder.glob("step_*")) if folder.is_dir() else []:
        meta = RunDir.load_meta(path)
        found[int(meta["step"])] = path
    return found


def _same_params(a: Path, b: Path) -> bool:
    """Whether checkpoint folders ``a`` and ``b`` hold the same params, bit for bit."""
    import jax

    from mjx_arm.train.rundir import RunDir

    pa, pb = RunDir.load_params(a), RunDir.load_params(b)
    leaves_a, leaves_b = jax.tree.leaves(pa), jax.tree.leaves(pb)
    if len(leaves_a) != len(leaves_b):
        return False
    return all(
        np.asarray(x).tobytes() == np.asarray(y).tobytes()
        for x, y in zip(leaves_a, leaves_b, strict=True)
    )
