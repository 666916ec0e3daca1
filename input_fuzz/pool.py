"""Run cases in worker processes under a memory cap, so that a native crash or a memory bomb
costs one worker, never the caller or the machine.

Each worker (started by ``spawn``: no JAX state forked) sets ``resource.setrlimit`` on its
address space (:data:`CAP_BYTES`, :data:`CAP_LIMIT`) before it imports anything, builds nothing
(the caller's :class:`~input_fuzz.corpus.Corpus` is passed in), runs the harness's warm-up
cases (:data:`~input_fuzz.harness.WARM_UP`: the start-up of JAX and the engines, paid once),
and runs cases with :func:`input_fuzz.harness.run_case`. Once a case's files are made it
resets the kernel's peak-RSS mark (``/proc/self/clear_refs``), after the case it reads
``VmHWM``: the case's own peak resident memory (the worker's imports included); a passing case
over :data:`~input_fuzz.harness.RSS_LIMIT_MB` is ``rss``.

A worker run by root gives up the capabilities that let root ignore file permissions
(:func:`drop_permission_override`), so that a read-only folder is read-only to the commands it
runs, as it is to a user.

A worker that dies during a case (a signal, or an exit) makes that case ``crash`` (``memory``
when the kernel killed it, SIGKILL) and is replaced, as is one whose case ran out of memory or
whose address space has grown past :data:`RETIRE_BYTES`; one that runs past
:data:`KILL_SECONDS` is killed and its case is a ``hang``. What the case's native code printed
last (:data:`~input_fuzz.harness.NATIVE_LOG`) is added to a crash's or a hang's detail.

The cap was chosen by measurement (benchmarks/bench_input_fuzz.py reports it with each case's
peak RSS): a worker that has imported ``mjx_arm.cli`` and run every command maps about 2.2 GB
of address space (JAX, XLA, MuJoCo, PyBullet, onnxruntime and their thread stacks) and a
normal case's peak RSS stays under 0.5 GB; 4 GiB leaves room for the largest policy the
readers accept (512 MiB) and stops any 3 GiB allocation.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import resource
import signal
import time
from collections.abc import Iterable, Iterator
from multiprocessing.connection import wait
from pathlib import Path

from input_fuzz.cases import Case
from input_fuzz.corpus import Corpus
from input_fuzz.harness import ALARM_SECONDS, Outcome

CAP_BYTES = 4 * 2**30
CAP_LIMIT = "RLIMIT_AS"
# A worker whose address space has grown past this after a case is replaced: a case (and the
# making of its files) starts with at least 0.8 GiB under the cap. Near the cap, a thread's
# stack cannot be mapped, and XLA aborts or waits: the worker's state, not the case's doing.
RETIRE_BYTES = CAP_BYTES - 0.8 * 2**30
KILL_SECONDS = ALARM_SECONDS + 30  # the harness's own alarm comes first


def set_cap(cap: int = CAP_BYTES, limit: str = CAP_LIMIT) -> None:
    """Cap this process's address space (or data segment) at ``cap`` bytes."""
    which = getattr(resource, limit)
    resource.setrlimit(which, (cap, cap))


_PERMISSION_CAPS = (1, 2)  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH
_CAP_VERSION_3 = 0x20080522


def drop_permission_override() -> bool:
    """Take the capabilities that let root ignore file permissions out of this thread's
    effective set (threads started later inherit it); whether it was done (Linux only)."""
    import ctypes

    class Header(ctypes.Structure):
        _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]

    class Data(ctypes.Structure):
        _fields_ = [(name, ctypes.c_uint32) for name in ("effective", "permitted", "inherit")]

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        header, data = Header(_CAP_VERSION_3, 0), (Data * 2)()
        if libc.capget(ctypes.byref(header), data) != 0:
            return False
        for bit in _PERMISSION_CAPS:
            data[0].effective &= ~(1 << bit)
        return libc.capset(ctypes.byref(header), data) == 0
    except (OSError, AttributeError):
        return False


def reset_peak_rss() -> None:
    """Reset the kernel's peak-RSS mark of this process (``VmHWM``)."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def memory_mb(field: str = "VmHWM") -> float:
    """A memory figure of this process from ``/proc/self/status``, in MB: ``VmHWM`` (peak
    resident memory since the last :func:`reset_peak_rss`) or ``VmPeak`` (peak address space)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) / 1024
    return 0.0


def probe(case: Case, corpus: Corpus, folder: Path) -> Outcome:
    """A runner that checks the pool itself (tests/test_input_fuzz.py): ``case.command``
    "segfault" kills the worker by SIGSEGV, "allocate" asks for ``case.argv[0]`` bytes (a
    MemoryError under the cap: ``memory``), "touch" fills that many bytes (resident: ``ok``,
    which the pool judges by its peak RSS), "write" tries to make a file in the folder
    ``case.argv[0]`` (the detail says "written" or "refused"), anything else is ``ok``."""
    start = time.perf_counter()
    status, detail = "ok", ""
    if case.command == "segfault":
        import ctypes

        ctypes.string_at(0)
    elif case.command in ("allocate", "touch"):
        try:
            block = bytearray(int(case.argv[0]))
            if case.command == "touch":  # a byte in every page: all of it resident
                block[::4096] = b"\x01" * len(range(0, len(block), 4096))
        except MemoryError:
            status = "memory"
    elif case.command == "write":
        try:
            (Path(case.argv[0]) / "probe.txt").write_text("x")
            detail = "written"
        except OSError:
            detail = "refused"
    return Outcome(case.command, status, 0, time.perf_counter() - start, [], detail)


def _serve(conn, corpus: Corpus, cap: int, limit: str, runner) -> None:
    """A worker's loop: ``(case, folder)`` in, :class:`Outcome` out; None ends it. The
    error-report files the commands write go beside the corpus, not into the user's home."""
    set_cap(cap, limit)
    drop_permission_override()
    os.environ["XDG_STATE_HOME"] = str(corpus.folder.parent / "state")
    import mjx_arm.cli  # noqa: F401  (imported once, before the first case is timed)
    from input_fuzz import harness
    from input_fuzz.harness import GOOD, RSS_LIMIT_MB, run_case, warm_up

    harness.NATIVE_LOG = harness.native_log(os.getpid(), corpus.folder.parent)
    if runner is None:
        warm_up(corpus, corpus.folder.parent / f"warm_up_{os.getpid()}")
    conn.send("ready")
    while (job := conn.recv()) is not None:
        case, folder = job
        reset_peak_rss()
        if runner is None:
            outcome = run_case(case, corpus, folder, on_start=reset_peak_rss)
        else:
            outcome = runner(case, corpus, folder)
        outcome.peak_rss_mb, outcome.peak_vm_mb = memory_mb("VmHWM"), memory_mb("VmPeak")
        outcome.retire = memory_mb("VmSize") * 2**20 > RETIRE_BYTES
        if outcome.status in GOOD and outcome.peak_rss_mb > RSS_LIMIT_MB:
            outcome.detail = f"peak RSS {outcome.peak_rss_mb:.0f} MB; {outcome.detail}"
            outcome.status = "rss"
        conn.send(outcome)


class _Worker:
    """One worker process and the case it runs (``job``, started at ``since``)."""

    def __init__(self, corpus: Corpus, cap: int, limit: str, runner=None):
        context = multiprocessing.get_context("spawn")
        self.conn, child = context.Pipe()
        args = (child, corpus, cap, limit, runner)
        self.process = context.Process(target=_serve, args=args, daemon=True)
        self.process.start()
        child.close()
        self.conn.recv()  # "ready": imports done
        self.job: tuple[Case, Path] | None = None
        self.since = 0.0

    def start(self, job: tuple[Case, Path]) -> None:
        self.job, self.since = job, time.perf_counter()
        self.conn.send(job)

    def stop(self) -> None:
        with contextlib.suppress(OSError):
            self.conn.send(None)
        self.process.join(5)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()


def _lost(job: tuple[Case, Path], seconds: float, status: str, detail: str) -> Outcome:
    case, _ = job
    argv = [str(t) for t in case.argv]
    return Outcome(case.command, status, None, seconds, argv, detail)


class Pool:
    """``workers`` worker processes under a memory cap (see the module docstring).

    Args:
        corpus: the good inputs, built by the caller.
        workers: how many cases run at once (1 or 2 on a small machine).
        cap: the cap in bytes on each worker's ``limit`` (``RLIMIT_AS`` or ``RLIMIT_DATA``).
        runner: what runs a case in a worker, ``(case, corpus, folder) -> Outcome`` (a
            module-level function; None: :func:`input_fuzz.harness.run_case`).
    """

    def __init__(
        self,
        corpus: Corpus,
        workers: int = 2,
        cap: int = CAP_BYTES,
        limit: str = CAP_LIMIT,
        runner=None,
    ):
        self.corpus, self.cap, self.limit, self.runner = corpus, cap, limit, runner
        self.workers = [self._start() for _ in range(workers)]
        self.restarts = 0

    def _start(self) -> _Worker:
        return _Worker(self.corpus, self.cap, self.limit, self.runner)

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *_exc) -> None:
        for worker in self.workers:
            worker.stop()

    def run(self, jobs: Iterable[tuple[Case, Path]]) -> Iterator[Outcome]:
        """The outcome of every ``(case, folder)`` job, in the order they finish."""
        pending = iter(jobs)
        idle = list(range(len(self.workers)))
        busy: dict[int, _Worker] = {}
        while True:
            while idle and (job := next(pending, None)) is not None:
                i = idle.pop()
                self.workers[i].start(job)
                busy[i] = self.workers[i]
            if not busy:
                return
            yield from self._collect(busy, idle)

    def _collect(self, busy: dict[int, _Worker], idle: list[int]) -> Iterator[Outcome]:
        """Wait for a worker to answer, die or run out of time; free it (or replace it)."""
        waitables = {w.conn: i for i, w in busy.items()}
        waitables.update({w.process.sentinel: i for i, w in busy.items()})
        ready = wait(list(waitables), timeout=1.0)
        now = time.perf_counter()
        for i, worker in list(busy.items()):
            answered = worker.conn in ready and worker.conn.poll()
            outcome = self._answer(worker) if answered else None
            if outcome is None and worker.process.is_alive():
                if now - worker.since < KILL_SECONDS:
                    continue
                worker.process.kill()
                worker.process.join()
                detail = "worker killed" + self._native_tail(worker)
                outcome = _lost(worker.job, now - worker.since, "hang", detail)
            elif outcome is None:
                outcome = self._died(worker, now)
            if outcome.status == "memory" or outcome.retire:  # a fresh worker: room under the cap
                worker.stop()
            if not worker.process.is_alive():
                self.workers[i] = self._start()
                self.restarts += 1
            del busy[i]
            idle.append(i)
            yield outcome

    @staticmethod
    def _answer(worker: _Worker) -> Outcome | None:
        try:
            return worker.conn.recv()
        except (EOFError, OSError):
            return None

    def _native_tail(self, worker: _Worker) -> str:
        """``; its native output ended: ...`` (the last 800 bytes the worker's case printed
        from native code), or "" when it printed nothing."""
        from input_fuzz.harness import native_log

        log = native_log(worker.process.pid, self.corpus.folder.parent)
        said = log.read_bytes()[-800:].decode("utf-8", "replace") if log.is_file() else ""
        return f"; its native output ended: {said.strip()}" if said.strip() else ""

    def _died(self, worker: _Worker, now: float) -> Outcome:
        """The outcome of a worker that died: the signal or exit code, and the tail of what
        its native code printed during the case."""
        worker.process.join()
        code = worker.process.exitcode or 0
        said = self._native_tail(worker)
        if code < 0:
            name = signal.Signals(-code).name
            status = "memory" if -code == signal.SIGKILL else "crash"
            detail = f"worker killed by {name}{said}"
            return _lost(worker.job, now - worker.since, status, detail)
        return _lost(
            worker.job, now - worker.since, "crash", f"worker exited with code {code}{said}"
        )
