"""A training run's directory: config, metrics (CSV + TensorBoard), checkpoints, transitions.

Layout::

    RUN_DIR/config.json                      every resolved setting (train, task, conversion)
    RUN_DIR/metrics.csv                      one row per evaluation
    RUN_DIR/tb/                              TensorBoard event files
    RUN_DIR/checkpoints/step_000001234/      params (orbax) + meta.json + transitions.npz
"""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

CHECKPOINT_PREFIX = "step_"


class RunDir:
    """Writes and reads one run directory."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        self.checkpoints = self.path / "checkpoints"
        self._tb = None
        self._csv_fields: list[str] | None = None

    # ------------------------------------------------------------------ config

    def save_config(self, config: dict[str, Any]) -> None:
        """Write ``config.json``."""
        (self.path / "config.json").write_text(json.dumps(config, indent=2, sort_keys=True))

    def load_config(self) -> dict[str, Any]:
        """Read ``config.json``."""
        return json.loads((self.path / "config.json").read_text())

    # ------------------------------------------------------------------ metrics

    def log_metrics(self, step: int, metrics: dict[str, float]) -> None:
        """Append one evaluation's metrics to the CSV and to TensorBoard."""
        row = {"step": step, "time": time.time(), **{k: _scalar(v) for k, v in metrics.items()}}
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
        self._write_tb(step, row)

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

    # ------------------------------------------------------------------ checkpoints

    def checkpoint_dir(self, step: int) -> Path:
        """Folder of the checkpoint at ``step``."""
        return self.checkpoints / f"{CHECKPOINT_PREFIX}{step:012d}"

    def save_checkpoint(self, step: int, params: Any, meta: dict[str, Any]) -> Path:
        """Save params (normalizer, policy, value) with orbax, plus ``meta.json``."""
        import orbax.checkpoint as ocp

        folder = self.checkpoint_dir(step)
        folder.mkdir(parents=True, exist_ok=True)
        checkpointer = ocp.PyTreeCheckpointer()
        checkpointer.save((folder / "params").resolve(), params, force=True)
        (folder / "meta.json").write_text(json.dumps({"step": step, **meta}, indent=2))
        return folder

    def latest_checkpoint(self) -> Path | None:
        """The newest checkpoint folder, or None."""
        if not self.checkpoints.exists():
            return None
        found = sorted(
            p
            for p in self.checkpoints.iterdir()
            if p.name.startswith(CHECKPOINT_PREFIX) and (p / "meta.json").exists()
        )
        return found[-1] if found else None

    @staticmethod
    def load_meta(folder: Path) -> dict[str, Any]:
        """The ``meta.json`` of a checkpoint folder."""
        return json.loads((folder / "meta.json").read_text())

    @staticmethod
    def load_params(folder: Path) -> Any:
        """The params saved in a checkpoint folder."""
        import orbax.checkpoint as ocp

        return ocp.PyTreeCheckpointer().restore((folder / "params").resolve())

    @staticmethod
    def save_transitions(folder: Path, transitions: dict[str, np.ndarray]) -> Path:
        """Write ``transitions.npz`` (obs, action, reward, done, ...) into a checkpoint folder."""
        path = folder / "transitions.npz"
        np.savez_compressed(path, **transitions)
        return path

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
    with path.open() as f:
        rows = list(csv.DictReader(f))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
