"""Run the URDF tools on mutated files in a worker process and classify what happens.

Each mutant (:mod:`urdf_fuzz.mutate`) goes through four operations: ``validate`` (the API,
all engines, native loads included), ``to_mjcf``, ``mjx-arm validate`` and ``mjx-arm convert``.
They run in a long-lived worker process, so a crash of a native loader (a segfault) or a hang
cannot take the caller down: the worker is replaced and the operation counted.

Each operation ends in one of :data:`STATUSES`:

- ``pass``: the file is accepted (a valid report, MJCF text, exit code 0);
- ``named_error``: a report with named errors, a :class:`~mjx_arm.urdf.errors.UrdfError`, exit
  code 2;
- ``crash``: any other exception, a traceback printed, a finding or error saying the tool
  "failed unexpectedly", another exit code, or the worker process died;
- ``hang``: it took longer than :data:`HANG_SECONDS`.

While an operation runs, an audit hook (``sys.addaudithook``) records every file opened for
reading outside the URDF's folder and the package folders (Python's own module files, and
folders opened to list them, as a temporary folder's clean-up does, aside): ``outside`` lists
them. Native code (MuJoCo's and PyBullet's loaders) opens files without
Python's audit events; the validator and converter hand it only paths they have checked (see
:mod:`mjx_arm.urdf.meshes`).
"""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from urdf_fuzz.mutate import KINDS, Mutant, mutants

HANG_SECONDS = 5.0
OPS = ("validate", "to_mjcf", "cli_validate", "cli_convert")
STATUSES = ("pass", "named_error", "crash", "hang")
# An operation is abandoned (and the worker replaced) after this long.
KILL_SECONDS = 2 * HANG_SECONDS
UNEXPECTED = "failed unexpectedly"
TRACEBACK = "Traceback (most recent call last)"
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND
_MODULE_SUFFIXES = (".py", ".pyc", ".so", ".pth")


@dataclass(frozen=True)
class OpResult:
    """What one operation did with one file.

    Attributes:
        op: one of :data:`OPS`.
        status: one of :data:`STATUSES`.
        seconds: wall-clock time of the operation.
        detail: the first error, or what crashed.
        outside: files opened for reading outside the allowed folders.
    """

    op: str
    status: str
    seconds: float
    detail: str = ""
    outside: tuple[str, ...] = ()


@dataclass(frozen=True)
class Outcome:
    """One mutant and what every operation did with it."""

    kind: str
    base: str
    index: int
    description: str
    size: int
    ops: tuple[OpResult, ...] = field(default_factory=tuple)

    @property
    def status(self) -> str:
        """The worst status of the operations: crash, hang, named_error, then pass."""
        order = ("crash", "hang", "named_error", "pass")
        return min((r.status for r in self.ops), key=order.index, default="pass")

    @property
    def outside(self) -> tuple[str, ...]:
        """Every file opened outside the allowed folders, by any operation."""
        return tuple(sorted({p for r in self.ops for p in r.outside}))

    @property
    def seconds(self) -> float:
        """The slowest operation's time."""
        return max((r.seconds for r in self.ops), default=0.0)


# --------------------------------------------------------------------------- worker side


class _OpenAudit:
    """Records files opened for reading outside ``roots`` while ``roots`` is set."""

    def __init__(self) -> None:
        self.roots: tuple[str, ...] | None = None
        self.hits: list[str] = []
        self.modules = tuple(os.path.realpath(p) for p in sys.path if p)

    def __call__(self, event: str, args: tuple) -> None:
        if event != "open" or self.roots is None:
            return
        path, flags = args[0], args[2]
        if isinstance(path, int) or (isinstance(flags, int) and flags & _WRITE_FLAGS):
            return
        real = os.path.realpath(os.fsdecode(path))
        if os.path.isdir(real):  # a folder listing (a temporary folder's clean-up), no file
            return
        if not (self._inside(real, self.roots) or self._module(real)):
            self.hits.append(real)

    @staticmethod
    def _inside(path: str, roots: Iterable[str]) -> bool:
        return any(path == r or path.startswith(r.rstrip(os.sep) + os.sep) for r in roots)

    def _module(self, path: str) -> bool:
        return path.endswith(_MODULE_SUFFIXES) and self._inside(path, self.modules)

    @contextlib.contextmanager
    def watching(self, roots: Sequence[str]) -> Iterator[list[str]]:
        """Record outside opens while the block runs; yields the list they go to."""
        self.hits = []
        self.roots = tuple(os.path.realpath(r) for r in roots)
        try:
            yield self.hits
        finally:
            self.roots = None


def _op_validate(path: Path, out_dir: Path) -> tuple[str, str]:
    from mjx_arm.urdf.validate import validate

    report = validate(path, engine="all")
    for finding in report.findings:
        if UNEXPECTED in finding.problem or not (finding.element and finding.problem):
            return "crash", str(finding)
    return ("named_error", str(report.errors[0])) if report.errors else ("pass", "")


def _op_to_mjcf(path: Path, out_dir: Path) -> tuple[str, str]:
    from mjx_arm.urdf import UrdfError, to_mjcf

    try:
        text = to_mjcf(path)
    except UrdfError as exc:
        message = str(exc)
        return ("crash" if UNEXPECTED in message else "named_error"), message.splitlines()[0]
    return ("pass", "") if text.lstrip().startswith("<mujoco") else ("crash", "no MJCF")


def _op_cli(args: list[str]) -> tuple[str, str]:
    from mjx_arm.cli import main

    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(args)
    text = (stdout.getvalue() + stderr.getvalue()).strip()
    if UNEXPECTED in text or code not in (0, 2):
        return "crash", f"exit code {code}: {text[-300:]}"
    return ("pass", "") if code == 0 else ("named_error", text.splitlines()[-1] if text else "")


def _op_cli_validate(path: Path, out_dir: Path) -> tuple[str, str]:
    return _op_cli(["validate", str(path), "--engine", "all"])


def _op_cli_convert(path: Path, out_dir: Path) -> tuple[str, str]:
    return _op_cli(["convert", str(path), "-o", str(out_dir / "converted.xml")])


_OPERATIONS: dict[str, Callable[[Path, Path], tuple[str, str]]] = {
    "validate": _op_validate,
    "to_mjcf": _op_to_mjcf,
    "cli_validate": _op_cli_validate,
    "cli_convert": _op_cli_convert,
}


class _Log:
    """The worker's file descriptors 1 and 2 go to one file; :meth:`since` reads what is new."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / "worker.log"
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        self.offset = 0

    def since(self) -> str:
        """Text written since the last call."""
        sys.stdout.flush()
        sys.stderr.flush()
        with open(self.path, "rb") as f:
            f.seek(self.offset)
            data = f.read()
        self.offset += len(data)
        return data.decode("utf-8", errors="replace")


def _run_op(op: str, path: Path, roots: Sequence[str], audit: _OpenAudit, log: _Log, out: Path):
    """Run one operation under the audit hook; return an :class:`OpResult`."""
    log.since()
    start = time.perf_counter()
    with audit.watching(roots) as hits:
        try:
            status, detail = _OPERATIONS[op](path, out)
        except BaseException as exc:  # anything escaping is what this harness looks for
            status, detail = "crash", f"{type(exc).__name__}: {exc}"
    seconds = time.perf_counter() - start
    printed = log.since()
    if TRACEBACK in printed:
        status, detail = "crash", "printed a traceback: " + printed[-300:]
    if status != "crash" and seconds > HANG_SECONDS:
        status = "hang"
    return OpResult(op, status, seconds, detail[:500], tuple(sorted(set(hits))))


def _worker_main(conn, warmup: str) -> None:
    """Serve (op, path, roots) requests on ``conn`` until it closes."""
    out = Path(tempfile.mkdtemp(prefix="mjx_arm_fuzz_"))
    os.chdir(out)  # MuJoCo writes MUJOCO_LOG.TXT into the working folder
    log = _Log(out)
    audit = _OpenAudit()
    sys.addaudithook(audit)
    for op in OPS:  # import and warm every code path once, unaudited
        _OPERATIONS[op](Path(warmup), out)
    conn.send("ready")
    try:
        while True:
            try:
                op, path, roots = conn.recv()
            except EOFError:
                return
            conn.send(_run_op(op, Path(path), roots, audit, log, out))
    finally:
        shutil.rmtree(out, ignore_errors=True)


# --------------------------------------------------------------------------- caller side


class FuzzWorker:
    """A worker process that runs the operations; replaced when it dies or hangs.

    Args:
        warmup: a valid URDF the worker converts once before serving (imports, caches).
        start_seconds: how long the worker may take to start.
    """

    def __init__(self, warmup: Path, start_seconds: float = 120.0) -> None:
        self.warmup, self.start_seconds = warmup, start_seconds
        self._context = multiprocessing.get_context("spawn")
        self._process = None
        self._conn = None
        self.restarts = 0

    def _start(self) -> None:
        parent, child = self._context.Pipe()
        self._process = self._context.Process(
            target=_worker_main, args=(child, str(self.warmup)), daemon=True
        )
        self._process.start()
        child.close()
        self._conn = parent
        try:
            ready = parent.poll(self.start_seconds) and parent.recv() == "ready"
        except EOFError:
            ready = False
        if not ready:
            self.stop()
            raise RuntimeError("the fuzz worker did not start")

    def run(self, op: str, path: Path, roots: Sequence[Path]) -> OpResult:
        """Run ``op`` on ``path`` with reads allowed under ``roots``."""
        if self._process is None or not self._process.is_alive():
            self._start()
        start = time.perf_counter()
        try:
            self._conn.send((op, str(path), [str(r) for r in roots]))
            if self._conn.poll(KILL_SECONDS):
                return self._conn.recv()
            status, detail = "hang", f"no answer after {KILL_SECONDS:g} s"
        except (EOFError, OSError, BrokenPipeError):
            self._process.join(1.0)
            status, detail = "crash", f"worker died (exit code {self._process.exitcode})"
        self.stop()
        self.restarts += 1
        return OpResult(op, status, time.perf_counter() - start, detail)

    def stop(self) -> None:
        """End the worker process."""
        if self._conn is not None:
            self._conn.close()
        if self._process is not None and self._process.pid is not None:
            self._process.join(0.5)
            if self._process.is_alive():
                self._process.kill()
                self._process.join()
        self._process = self._conn = None

    def __enter__(self) -> FuzzWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def default_bases() -> dict[str, Path]:
    """The valid URDFs to mutate: the shipped arm, and pybullet_data's Panda and KUKA iiwa."""
    from mjx_arm.paths import default_arm_urdf

    bases = {"ur5e": default_arm_urdf()}
    with contextlib.suppress(ImportError):
        import pybullet_data

        data = Path(pybullet_data.getDataPath())
        bases["panda"] = data / "franka_panda" / "panda.urdf"
        bases["kuka_iiwa"] = data / "kuka_iiwa" / "model.urdf"
    return bases


def copy_bases(bases: Mapping[str, Path], workdir: Path) -> dict[str, Path]:
    """Copy each base URDF with its folder's meshes to ``workdir/NAME/``; return the copies.

    Mutants are written beside their base's copy, so relative and ``package://`` meshes resolve
    inside the folder the audit allows.
    """
    copies = {}
    for name, urdf in bases.items():
        folder = workdir / name
        if name == "ur5e":  # the shipped arm has no meshes; its folder holds other assets
            folder.mkdir(parents=True, exist_ok=True)
            shutil.copy(urdf, folder / urdf.name)
        else:
            shutil.copytree(urdf.parent, folder, dirs_exist_ok=True)
        copies[name] = (folder / urdf.name).resolve()
    return copies


def run_fuzz(
    count: int,
    seed: int,
    workdir: Path,
    ops: Sequence[str] = OPS,
    bases: Mapping[str, Path] | None = None,
    progress: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Mutate the bases ``count`` times and run ``ops`` on every mutant.

    Args:
        count: mutants to try.
        seed: the mutation stream's seed.
        workdir: an empty folder for the base copies and the mutants.
        ops: the operations to run (:data:`OPS`).
        bases: name -> valid URDF (default: :func:`default_bases`).
        progress: called with each outcome as it is done.

    Returns:
        One :class:`Outcome` per mutant, in stream order.
    """
    copies = copy_bases(bases or default_bases(), workdir)
    originals = {name: path.read_bytes() for name, path in copies.items()}
    outcomes = []
    with FuzzWorker(copies["ur5e"] if "ur5e" in copies else next(iter(copies.values()))) as w:
        for m in mutants(originals, count, seed):
            outcome = _try(w, m, copies[m.base].parent, ops)
            outcomes.append(outcome)
            if progress is not None:
                progress(outcome)
    return outcomes


def _try(worker: FuzzWorker, m: Mutant, folder: Path, ops: Sequence[str]) -> Outcome:
    path = folder / f"{m.name}.urdf"
    path.write_bytes(m.data)
    try:
        results = tuple(worker.run(op, path, [folder]) for op in ops)
    finally:
        path.unlink()
    return Outcome(m.kind, m.base, m.index, m.description, len(m.data), results)


def tally(outcomes: Iterable[Outcome]) -> dict[str, dict[str, float]]:
    """Per mutation kind (and ``all``): tried, each status, outside reads, slowest seconds."""
    table: dict[str, dict[str, float]] = {}
    for o in outcomes:
        for key in (o.kind, "all"):
            row = table.setdefault(key, {"tried": 0, **dict.fromkeys(STATUSES, 0)})
            row["tried"] += 1
            row[o.status] += 1
            row["outside_reads"] = row.get("outside_reads", 0) + bool(o.outside)
            row["max_seconds"] = max(row.get("max_seconds", 0.0), o.seconds)
    order = [k for k in (*KINDS, "all") if k in table]
    return {k: table[k] for k in order}
