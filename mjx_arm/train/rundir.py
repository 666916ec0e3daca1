"""A training run's directory: config, metrics (CSV + TensorBoard), checkpoints, transitions.

Layout::

    RUN_DIR/config.json                      every resolved setting (train, task, conversion)
    RUN_DIR/compile.json                     where the start-up's seconds went (per start)
    RUN_DIR/metrics.csv                      one row per evaluation
    RUN_DIR/tb/                              TensorBoard event files
    RUN_DIR/checkpoints/step_000001234/      params (orbax) + meta.json + transitions.npz
    RUN_DIR/.lock                            held by the training that writes the run (its pid)

The checkpoints themselves are written and read by :mod:`mjx_arm.train.checkpoints`.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import InputError, write_atomic
from mjx_arm.train import checkpoints as ckpt
from mjx_arm.train.checkpoints import CHECKPOINT_PREFIX, CheckpointError

__all__ = ["CHECKPOINT_PREFIX", "MIN_FREE_BYTES", "CheckpointError", "RunDir", "RunDirError"]

MIN_FREE_BYTES = 64 * 2**20  # a checkpoint of the default networks takes about 3 MiB
LOCK_NAME = ".lock"


class RunDirError(InputError, OSError):
    """The run directory cannot hold a run (not writable, disk full, in use by another
    training)."""


class RunDir:
    """Writes and reads one run directory."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise RunDirError(
                f"cannot create the run directory {self.path}: {err.strerror or err}"
            ) from err
        self.checkpoints = self.path / "checkpoints"
        self._tb = None
        self._csv_fields: list[str] | None = None

    # ------------------------------------------------------------------ config

    def save_config(self, config: dict[str, Any]) -> None:
        """Write ``config.json`` (atomically)."""
        text = json.dumps(config, indent=2, sort_keys=True)
        write_atomic(text.encode(), self.path / "config.json")

    def save_compile_report(self, report: dict[str, Any]) -> None:
        """Add one start's compile report (:mod:`mjx_arm.train.compile_report`) to
        ``compile.json``: a list, one entry per start of the run (a resume adds one)."""
        path = self.path / "compile.json"
        try:
            starts = json.loads(path.read_text()) if path.is_file() else []
        except (OSError, json.JSONDecodeError):
            starts = []
        starts = starts if isinstance(starts, list) else []
        text = json.dumps([*starts, report], indent=2, sort_keys=True)
        write_atomic(text.encode(), path)

    @contextlib.contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the run directory for one training: a second one started on it fails at once
        instead of writing the same checkpoints and metrics. The lock (``fcntl.flock`` on
        ``.lock``) ends with the process, so a killed run leaves none behind.

        Raises:
            RunDirError: another process holds the run directory (its pid named).
        """
        import fcntl

        path = self.path / LOCK_NAME
        try:
            handle = path.open("a+")
        except OSError as err:
            raise RunDirError(
                f"cannot create the lock file of {self.path}: {err.strerror or err}"
            ) from err
        with handle as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.seek(0)
                owner = f.read().strip() or "unknown"
                raise RunDirError(
                    f"the run directory {self.path} is in use by another training (pid "
                    f"{owner}); wait for it to end, or choose another --run-dir"
                ) from None
            try:
                f.seek(0)
                f.truncate()
                f.write(str(os.getpid()))
                f.flush()
            except OSError as err:  # a disk that filled since the check
                fcntl.flock(f, fcntl.LOCK_UN)
                raise RunDirError(
                    f"cannot write the lock file of {self.path} ({err.strerror or err}); free "
                    "some space and start again"
                ) from err
            try:
                yield
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)

    def load_config(self) -> dict[str, Any]:
        """Read ``config.json``."""
        return json.loads((self.path / "config.json").read_text())

    # ------------------------------------------------------------------ metrics

    def log_metrics(self, step: int, metrics: dict[str, float]) -> None:
        """Append one evaluation's metrics to the CSV and to TensorBoard.

        Raises:
            RunDirError: the disk is full or the folder cannot be written (a cut row is
                dropped on resume: :meth:`truncate_metrics`).
        """
        row = {"step": step, "time": time.time(), **{k: _scalar(v) for k, v in metrics.items()}}
        try:
            self._append_row(row)
        except OSError as err:
            raise RunDirError(
                f"cannot write the metrics of step {step} into {self.path} "
                f"({err.strerror or err}); free some space and resume the run"
            ) from err
        self._write_tb(step, row)

    def _append_row(self, row: dict[str, float]) -> None:
        """Append ``row`` to metrics.csv (widening its header for a new metric)."""
        path = self.path / "metrics.csv"
        if self._csv_fields is None:
            self._csv_fields = _existing_fields(path) or list(row)
        for key in row:
            if key not in self._csv_fields:
                self._csv_fields.append(key)
                _rewrite_header(path, self._csv_fields)
        new = not path.exists()
        with path.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self._csv_fields)
            if new:
                writer.writeheader()
            writer.writerow(row)

    def _write_tb(self, step: int, row: dict[str, float]) -> None:
        writer = self._tensorboard()
        for key, value in row.items():
            if key not in ("step", "time") and math.isfinite(value):
                writer.add_scalar(key, value, step)
        writer.flush()

    def _tensorboard(self):
        if self._tb is None:
            from tensorboardX import SummaryWriter

            self._tb = SummaryWriter(str(self.path / "tb"))
        return self._tb

    def read_metrics(self) -> list[dict[str, float]]:
        """All metric rows written so far."""
        path = self.path / "metrics.csv"
        if not path.exists():
            return []
        with path.open() as f:
            return [
                {k: float(v) if v not in ("", None) else math.nan for k, v in row.items()}
                for row in csv.DictReader(f)
            ]

    def truncate_metrics(self, step: int) -> int:
        """Drop metric rows after ``step`` and rows cut short by a kill; return how many.

        A resumed run trains again from its last checkpoint (``step``); rows a killed run
        logged after it would otherwise appear twice. TensorBoard's event files are append-only
        and keep them; it shows the newest value per step.
        """
        path = self.path / "metrics.csv"
        if not path.exists():
            return 0
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            fields, rows = reader.fieldnames or [], list(reader)
        kept = [r for r in rows if _complete(r, fields) and float(r["step"]) <= step]
        if len(kept) == len(rows):
            return 0
        partial = path.with_name(".partial-metrics.csv")
        with partial.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(kept)
        os.replace(partial, path)
        return len(rows) - len(kept)

    def check_writable(self, free_bytes: int = MIN_FREE_BYTES) -> None:
        """Fail early, with a clear message, where the run directory cannot take a run.

        Raises:
            RunDirError: the folder cannot be written, or its disk has less than
                ``free_bytes`` free.
        """
        probe = self.path / ".write-probe"
        try:
            probe.write_bytes(b"0" * 4096)
            probe.unlink()
        except OSError as err:
            raise RunDirError(
                f"cannot write to the run directory {self.path}: {err.strerror or err}"
            ) from err
        free = shutil.disk_usage(self.path).free
        if free < free_bytes:
            raise RunDirError(
                f"the disk of {self.path} has {free / 2**20:.0f} MiB free; a run needs at least "
                f"{free_bytes / 2**20:.0f} MiB for its checkpoints and metrics"
            )

    # ------------------------------------------------------------------ checkpoints

    def checkpoint_dir(self, step: int) -> Path:
        """Folder of the checkpoint at ``step``."""
        return ckpt.checkpoint_dir(self.checkpoints, step)

    def save_checkpoint(
        self,
        step: int,
        params: Any,
        meta: dict[str, Any],
        transitions: dict[str, np.ndarray] | None = None,
        arrays: dict[str, dict[str, np.ndarray]] | None = None,
        newest_only: tuple[str, ...] = (),
    ) -> Path:
        """Save the checkpoint of ``step``, atomically (see :mod:`mjx_arm.train.checkpoints`),
        then delete the files named in ``newest_only`` from every other checkpoint."""
        folder = self.checkpoint_dir(step)
        saved = ckpt.save_checkpoint(folder, step, params, meta, transitions, arrays)
        for name in newest_only:
            for old in self.checkpoints.glob(f"{CHECKPOINT_PREFIX}*/{name}"):
                if old.parent != saved:
                    old.unlink(missing_ok=True)
        return saved

    def latest_checkpoint(self) -> Path | None:
        """The newest checkpoint folder, or None."""
        return ckpt.latest_checkpoint(self.checkpoints)

    load_meta = staticmethod(ckpt.load_meta)
    load_params = staticmethod(ckpt.load_params)
    save_transitions = staticmethod(ckpt.save_transitions)

    def close(self) -> None:
        """Flush and close TensorBoard."""
        if self._tb is not None:
            self._tb.close()
            self._tb = None


def _scalar(value: Any) -> float:
    try:
        return float(np.asarray(value).mean())
    except (TypeError, ValueError):
        return math.nan


def _complete(row: dict[str, Any], fields: list[str]) -> bool:
    """A CSV row with every field present and a numeric step (not cut short by a kill)."""
    if any(row.get(k) is None for k in fields) or None in row:
        return False
    try:
        float(row["step"])
    except (TypeError, ValueError):
        return False
    return True


def _existing_fields(path: Path) -> list[str] | None:
    if not path.exists():
        return None
    with path.open() as f:
        header = f.readline().strip()
    return header.split(",") if header else None


def _rewrite_header(path: Path, fields: list[str]) -> None:
    """Rewrite the CSV with a wider header when a new metric appears."""
    if not path.exists():
        return
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    partial = path.with_name(".partial-metrics.csv")
    with partial.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(partial, path)  # a kill mid-rewrite leaves the old file whole
