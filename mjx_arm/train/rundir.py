"""A training run's directory: config, metrics (CSV + TensorBoard), checkpoints, transitions.

Layout::

    RUN_DIR/config.json                      every resolved setting (train, task, conversion)
    RUN_DIR/compile.json                     where the start-up's seconds went (per start)
    RUN_DIR/metrics.csv                      one row per evaluation
    RUN_DIR/tb/                              TensorBoard event files
    RUN_DIR/checkpoints/step_000001234/      params (orbax) + meta.json + transitions.npz
    RUN_DIR/.lock                            held by the training that writes the run (its pid)
    RUN_DIR/.mjx_arm_run                     marks the folder as a run directory (MARKER)

A new run takes a new or empty folder, or a run directory of this project (:func:`claim`);
any other folder of the user's is refused, never written into. Every file of the run is read
as a bounded regular file inside the run directory (:func:`mjx_arm.inputs.open_regular`) and
written without following a link (a temporary file renamed into place, or ``O_NOFOLLOW``).
The checkpoints themselves are written and read by :mod:`mjx_arm.train.checkpoints`.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import json
import math
import os
import shutil
import stat
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import InputError, MiB, read_json_object, read_text, write_atomic
from mjx_arm.train import checkpoints as ckpt
from mjx_arm.train.checkpoints import CHECKPOINT_PREFIX, CheckpointError
from mjx_arm.train.tb_events import ScalarWriter, event_file_name

__all__ = [
    "CHECKPOINT_PREFIX",
    "MARKER",
    "MIN_FREE_BYTES",
    "CheckpointError",
    "RunDir",
    "RunDirError",
    "claim",
    "is_run_dir",
]

MIN_FREE_BYTES = 64 * 2**20  # a checkpoint of the default networks takes about 3 MiB
LOCK_NAME = ".lock"
MARKER = ".mjx_arm_run"  # written into the folder of every new run
METRICS = "metrics.csv"
MAX_METRICS_BYTES = 64 * MiB  # a row of 60 metrics takes about 1 kB: 60,000 evaluations
# Where a run writes through a folder of its own: a link there out of the run is refused.
WRITTEN_FOLDERS = ("checkpoints", "tb", "logs")


class RunDirError(InputError, OSError):
    """The run directory cannot hold a run (not writable, disk full, in use by another
    training)."""


def is_run_dir(path: str | Path) -> bool:
    """Whether ``path`` is a run directory of this project: it holds :data:`MARKER` (every run
    since the marker), or a ``config.json`` with a ``train`` table (every run before it)."""
    path = Path(path)
    if (path / MARKER).is_file() and not (path / MARKER).is_symlink():
        return True
    try:
        config = read_json_object(path / "config.json", "run config", within=path)
    except InputError:
        return False
    return isinstance(config.get("train"), dict)


def claim(path: str | Path) -> Path:
    """Make ``path`` the folder of a new run: created where missing, then marked
    (:data:`MARKER`). Whether it already holds a run (a checkpoint) is for the training to say.

    Raises:
        RunDirError: ``path`` is a file, or a folder that holds files and is not a run directory
            of this project (a folder of the user's: nothing in it is replaced or added).
    """
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise RunDirError(f"the run directory {str(path)!r} is a file; give a new or empty folder")
    try:
        held = sorted(p.name for p in path.iterdir()) if path.is_dir() else []
    except OSError as err:
        raise RunDirError(f"cannot list the run directory {path}: {err.strerror}") from err
    if held and not is_run_dir(path):
        shown = ", ".join(held[:3]) + (", ..." if len(held) > 3 else "")
        raise RunDirError(
            f"{str(path)!r} holds files ({shown}) and is not an mjx-arm run directory, so a run "
            "does not write into it: give a new or empty folder as --run-dir, or continue a run "
            "with --resume RUN_DIR"
        )
    RunDir(path).check_links()
    write_atomic(b"an mjx-arm training run directory\n", path / MARKER)
    return path


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
        text = json.dumps([*self.compile_reports(), report], indent=2, sort_keys=True)
        write_atomic(text.encode(), self.path / "compile.json")

    def compile_reports(self) -> list[dict[str, Any]]:
        """The compile reports of ``compile.json``, one per start (none where it is missing or
        damaged: a bounded regular file of the run, a JSON list)."""
        try:
            text = read_text(self.path / "compile.json", "compile report", within=self.path)
            starts = json.loads(text)
        except (InputError, ValueError, RecursionError):
            return []
        return [s for s in starts if isinstance(s, dict)] if isinstance(starts, list) else []

    @contextlib.contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the run directory for one training: a second one started on it fails at once
        instead of writing the same checkpoints and metrics. The lock (``fcntl.flock`` on
        ``.lock``, opened without following a link) ends with the process, so a killed run
        leaves none behind.

        Raises:
            RunDirError: another process holds the run directory (its pid named), or ``.lock``
                is a link or not a regular file.
        """
        import fcntl

        fd = open_no_follow(self.path / LOCK_NAME, os.O_RDWR | os.O_CREAT, "lock file")
        with os.fdopen(fd, "r+", errors="replace") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.seek(0)
                owner = f.read(32).strip() or "unknown"
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
        """Read ``config.json`` (an InputFileError where it is missing, not a bounded regular
        file of the run, or not a JSON object)."""
        return read_json_object(self.path / "config.json", "run config", within=self.path)

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
        except InputError:  # a metrics file that is not the run's to write (named already)
            raise
        except OSError as err:
            raise RunDirError(
                f"cannot write the metrics of step {step} into {self.path} "
                f"({err.strerror or err}); free some space and resume the run"
            ) from err
        self._write_tb(step, row)

    def _append_row(self, row: dict[str, float]) -> None:
        """Append ``row`` to metrics.csv (widening its header for a new metric), never through
        a link."""
        path = self.path / METRICS
        if self._csv_fields is None:
            self._csv_fields = self._metrics()[0] or list(row)
        widened = [key for key in row if key not in self._csv_fields]
        if widened:
            self._csv_fields += widened
            fields, rows = self._metrics()
            if fields:  # a kill mid-rewrite leaves the old file whole
                write_atomic(_csv_bytes(self._csv_fields, rows), path)
        fd = open_no_follow(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, "metrics file")
        with os.fdopen(fd, "a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self._csv_fields)
            if os.fstat(fd).st_size == 0:
                writer.writeheader()
            writer.writerow(row)

    def _write_tb(self, step: int, row: dict[str, float]) -> None:
        scalars = {k: v for k, v in row.items() if k not in ("step", "time") and math.isfinite(v)}
        self._tensorboard().add_scalars(step, scalars)

    def _tensorboard(self) -> ScalarWriter:
        """The event file of this start of the run (a new one per start; TensorBoard reads
        every file in ``tb/``)."""
        if self._tb is None:
            folder = self.path / "tb"
            folder.mkdir(exist_ok=True)
            path = folder / event_file_name()
            fd = open_no_follow(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, "TensorBoard file")
            self._tb = ScalarWriter(os.fdopen(fd, "ab"))
        return self._tb

    def _metrics(self) -> tuple[list[str], list[dict[str, Any]]]:
        """The header and rows of metrics.csv, read as a bounded regular file of the run
        (empty where there is none yet).

        Raises:
            RunDirError: a metrics.csv that cannot be read (not a regular file, too big, not
                UTF-8 or not CSV), or without a step column.
        """
        path = self.path / METRICS
        if not os.path.lexists(path):
            return [], []
        fix = f"move {path} aside (the run's metrics then start afresh) and run again"
        try:
            text = read_text(path, "metrics file", MAX_METRICS_BYTES, within=self.path)
            reader = csv.DictReader(io.StringIO(text, newline=""))
            fields, rows = list(reader.fieldnames or []), list(reader)
        except InputError as err:  # its own fix ("give the path of a file") is not this one
            raise RunDirError(f"{str(err).split('; ')[0]}; {fix}") from err
        except csv.Error as err:
            raise RunDirError(f"{path} is not a CSV file of metrics ({err}); {fix}") from err
        if fields and "step" not in fields:
            raise RunDirError(f"{path} has no step column: not an mjx-arm run's metrics; {fix}")
        return fields, rows

    def read_metrics(self) -> list[dict[str, float]]:
        """All metric rows written so far (a value that is not a number: NaN).

        Raises:
            RunDirError: a metrics.csv that cannot be read (:meth:`_metrics`).
        """
        return [
            {k: _number(v) for k, v in row.items() if k is not None} for row in self._metrics()[1]
        ]

    def truncate_metrics(self, step: int) -> int:
        """Drop metric rows after ``step`` and rows cut short by a kill; return how many.

        A resumed run trains again from its last checkpoint (``step``); rows a killed run
        logged after it would otherwise appear twice. TensorBoard's event files are append-only
        and keep them; it shows the newest value per step.

        Raises:
            RunDirError: a metrics.csv that cannot be read (:meth:`_metrics`).
        """
        fields, rows = self._metrics()
        kept = [r for r in rows if _complete(r, fields) and float(r["step"]) <= step]
        if len(kept) == len(rows):
            return 0
        write_atomic(_csv_bytes(fields, kept), self.path / METRICS)
        return len(rows) - len(kept)

    def check_writable(self, free_bytes: int = MIN_FREE_BYTES) -> None:
        """Fail early, with a clear message, where the run directory cannot take a run.

        Raises:
            RunDirError: the folder cannot be written, its disk has less than
                ``free_bytes`` free, or a folder the run writes into is a link out of it.
        """
        self.check_links()
        try:  # a new file of its own (O_EXCL): never one of the folder's, nor a link's target
            handle, probe = tempfile.mkstemp(prefix=".write-probe-", dir=self.path)
            with os.fdopen(handle, "wb") as f:
                f.write(b"0" * 4096)
            os.unlink(probe)
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

    def check_links(self) -> None:
        """Refuse a folder the run writes into (:data:`WRITTEN_FOLDERS`) that is a link out of
        the run directory (a :class:`RunDirError` naming its target)."""
        root = os.path.realpath(self.path)
        for name in WRITTEN_FOLDERS:
            target = Path(os.path.realpath(self.path / name))
            if (self.path / name).is_symlink() and not target.is_relative_to(root):
                raise RunDirError(
                    f"{self.path / name} is a link to {target}, outside the run directory: a "
                    "run writes only inside its folder; remove the link and start again"
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
                if old.parent != saved and not old.parent.is_symlink():  # never out of the run
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


def _number(value: Any) -> float:
    """A CSV cell as a number (NaN where empty, missing or not a number)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _csv_bytes(fields: list[str], rows: list[dict[str, Any]]) -> bytes:
    """A CSV file of ``rows`` under the header ``fields`` (cells of other keys dropped)."""
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=fields, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue().encode()


def open_no_follow(path: Path, flags: int, what: str) -> int:
    """A descriptor of the regular file ``path`` opened with ``flags`` (``O_CREAT``: created,
    mode 0644) without following a link, so nothing is ever written through one.

    Raises:
        RunDirError: ``path`` is a link or not a regular file (a FIFO, a device), or cannot be
            opened.
    """
    try:
        fd = os.open(path, flags | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise RunDirError(
                f"the {what} {path} is a symbolic link: refused, a run writes no file through a "
                "link; remove the link and start again"
            ) from err
        raise RunDirError(f"cannot open the {what} {path}: {err.strerror or err}") from err
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise RunDirError(
            f"the {what} {path} is not a regular file (a FIFO or a device): refused; remove it "
            "and start again"
        )
    os.set_blocking(fd, True)
    return fd
