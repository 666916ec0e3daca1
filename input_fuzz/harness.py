"""Run a :class:`~input_fuzz.cases.Case` in process through :func:`mjx_arm.cli.main` and judge
it.

The harness makes the case's files in a fresh folder (good copies, mutations, missing paths,
other kinds' files), seeds its outputs with good files, runs ``main(argv)`` with stdout and
stderr captured and the folder as the working directory, and checks:

- ``ok``: exit code 0;
- ``named``: exit code 2 with an ``error:`` line (ours, or argparse's ``prog: error:``);
- ``work``: the inputs passed every check and the command reached its long work, which the
  harness stops there (training, MJX, long evaluations, benchmarks, video; :data:`WORK_STUBS`);
- ``traceback``: an exception escaped ``main`` (a bug), or another exit code;
- ``unnamed``: exit code 2 without an ``error:`` line;
- ``hang``: the case took more than :data:`HANG_SECONDS`;
- ``lost``: a good output (a seeded file, a run directory's checkpoint or config) was changed by
  a failing command, or replaced by a broken file;
- ``outside``: a file the case must not touch was changed, removed or added: its inputs, a
  user's file beside its outputs or in a user's folder, ``benchmarks/results/`` (there: written
  by the case's own process, :mod:`input_fuzz.sentinel`);
- ``long``: an ``error:`` line longer than :data:`MAX_ERROR_CHARS` characters;
- ``memory``: the case ran out of memory (a ``MemoryError`` or a native allocation failure
  under the worker's cap, :mod:`input_fuzz.pool`);
- ``crash``: the worker process running the case died (a signal: a native crash);
- ``rss``: the case passed, but its worker's peak resident memory was over
  :data:`RSS_LIMIT_MB` (set by :mod:`input_fuzz.pool`, which measures it).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import signal
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import numpy as np

from input_fuzz import sentinel
from input_fuzz.cases import Case, In, Out
from input_fuzz.corpus import Corpus
from input_fuzz.files import materialise, remove_deep_outputs
from input_fuzz.hostile_run import USER_FILES

HANG_SECONDS = 30.0
ALARM_SECONDS = 120  # a case still running then is stopped (and counted as a hang)
MAX_ERROR_CHARS = 300
STATUSES = ("ok", "named", "work", "traceback", "unnamed", "hang", "lost", "outside")
STATUSES += ("long", "memory", "crash", "rss")
RSS_LIMIT_MB = 1.5e9 / 2**20  # 1.5 GB: a worker's peak resident memory, its imports included
# Native allocation failures that onnxruntime and C++ code raise as other exception types.
MEMORY_TEXTS = ("bad_alloc", "Failed to allocate memory", "Cannot allocate memory")
GOOD = ("ok", "named", "work")  # the statuses of a passing case


class WorkStarted(Exception):
    """Raised by the stubs where a command would start its long work."""


class Hang(Exception):
    """Raised by the alarm in a case that runs too long."""


@dataclass
class Outcome:
    """What one case did: its status, exit code, seconds, argv and the last stderr line;
    ``inputs``: each input slot as ``kind mode[ mutation]``; ``error_line``: the longest
    ``error:`` line printed (its first 400 characters; ``error_chars``: its length);
    ``peak_rss_mb``: the worker's peak resident memory during the case, ``peak_vm_mb``: its
    peak address space so far (both 0 in process); ``outputs``: how each output path was
    named (:data:`~input_fuzz.cases.OUT_NAMES`: ``plain``, ``long``, ``deep``, ``user``)."""

    command: str
    status: str
    code: int | None
    seconds: float
    argv: list[str]
    detail: str
    inputs: list[str] = field(default_factory=list)
    error_line: str = ""
    error_chars: int = 0
    peak_rss_mb: float = 0.0
    peak_vm_mb: float = 0.0
    outputs: list[str] = field(default_factory=list)
    retire: bool = False  # the worker's address space is near its cap: the pool replaces it
    external: str = ""  # benchmarks/results changed during the case, not by it (not counted)


# --------------------------------------------------------------------------- stubs


def _stop(*_args, **_kwargs):
    raise WorkStarted


def _short_episodes(real):
    """``run_episodes`` for at most 2 episodes without video; longer work is stopped."""

    def run(policy, env, episodes=1, seed=0, video=None, *args, **kwargs):
        if episodes > 2 or video is not None:
            raise WorkStarted
        return real(policy, env, episodes, seed, video, *args, **kwargs)

    return run


def _cpu_envs_only(real):
    """``make_envs`` for the C MuJoCo backend (built in well under a second); MJX is stopped."""

    def make(config, task, **options):
        if config.backend != "mujoco":
            raise WorkStarted
        return real(config, task, **options)

    return make


WORK_STUBS = {
    "mjx_arm.train.ppo.run_ppo": _stop,
    "mjx_arm.evaluate.core.run_batched": _stop,
    "mjx_arm.sim2real.deploy.make_eval_env": _stop,
    "mjx_arm.demo.train_reach": _stop,
    "mjx_arm.bench.parity.run_parity": _stop,
    "mjx_arm.bench.grasp.grasp_check": _stop,
    "mjx_arm.bench.transfer.transfer_matrix": _stop,
    "mjx_arm.bench.seeds.run_seeds": _stop,
    "mjx_arm.replay.rendering_available": lambda: (False, "no rendering in the input fuzz"),
}


# Where a case's native output (fds 1 and 2) goes: a file per worker, set by the pool
# (native_log), that it reads when the worker dies; None: /dev/null.
NATIVE_LOG: Path | None = None


def native_log(pid: int, folder: Path) -> Path:
    """The native-output file of the worker of process id ``pid`` (in ``folder``)."""
    return folder / f"native-{pid}.txt"


REAL_WORK = ("mjx_arm.bench.parity.run_parity",)  # what a case marked ``real`` runs


@contextlib.contextmanager
def stubs(real: bool = False) -> Iterator[None]:
    """The long work of every command stopped (:data:`WORK_STUBS`); with ``real``, but
    :data:`REAL_WORK`."""
    import mjx_arm.evaluate.core as core
    import mjx_arm.train.ppo as ppo

    with contextlib.ExitStack() as stack:
        for target, stub in WORK_STUBS.items():
            if not (real and target in REAL_WORK):
                stack.enter_context(mock.patch(target, stub))
        stack.enter_context(
            mock.patch.object(core, "run_episodes", _short_episodes(core.run_episodes))
        )
        stack.enter_context(mock.patch.object(ppo, "make_envs", _cpu_envs_only(ppo.make_envs)))
        yield


# --------------------------------------------------------------------------- good outputs


DIGEST_BYTES = 64 * 2**20  # a larger file (a hostile sparse one) is known by its size


def _hash(path: Path) -> str:
    """SHA-256 of a file read in chunks; its size alone over :data:`DIGEST_BYTES`, and its
    target for a link (to /dev/zero, say)."""
    if path.is_symlink():
        return f"link to {os.readlink(path)}"
    size = path.stat().st_size
    if size > DIGEST_BYTES:
        return f"{size} bytes"
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(2**20):
            digest.update(chunk)
    return digest.hexdigest()


def _digest(path: Path) -> dict[str, str]:
    """Relative path -> :func:`_hash` of every file at or under ``path`` (the lock file left
    out)."""
    if path.is_file():
        return {"": _hash(path)}
    if not path.is_dir():
        return {}
    return {
        str(p.relative_to(path)): _hash(p)
        for p in sorted(path.rglob("*"))
        if (p.is_file() or p.is_symlink()) and p.name != ".lock"
    }


def _newest_checkpoint(checkpoints: Path) -> Path | None:
    """The newest usable checkpoint folder (``step_N`` or ``.old-step_N``), found without
    moving anything (``latest_checkpoint`` moves an ``.old-`` one back: the case's to do)."""
    from mjx_arm.train.checkpoints import checkpoint_step, usable

    if not checkpoints.is_dir() or checkpoints.is_symlink():
        return None
    found = [p for p in checkpoints.iterdir() if checkpoint_step(p) is not None and usable(p)]
    return max(found, key=lambda p: (checkpoint_step(p), p.name), default=None)


def _run_dir_state(path: Path) -> dict[str, str]:
    """What a run directory must keep: config.json and its newest usable checkpoint."""
    from mjx_arm.train.checkpoints import checkpoint_step

    latest = _newest_checkpoint(path / "checkpoints") if path.is_dir() else None
    if latest is None:
        return {}
    kept = {"config.json": _digest(path / "config.json").get("", "")}
    step = checkpoint_step(latest)
    kept.update({f"{step}/{k}": v for k, v in _digest(latest).items()})
    return kept


def snapshot(argv: list[str], outputs: dict[Path, Out]) -> dict[Path, tuple[bool, dict]]:
    """The good outputs before a case: seeded output files (``False``, their digest), and
    every run directory named (``True``, :func:`_run_dir_state`)."""
    state = {path: (False, _digest(path)) for path, slot in outputs.items() if slot.seeded}
    for token in argv:
        path = Path(token)
        if path.is_absolute() and (path / "checkpoints").is_dir():
            state[path] = (True, _run_dir_state(path))
    return state


def valid_output(path: Path) -> bool:
    """Whether a written output is whole: it parses as its kind."""
    import tomllib

    if path.is_dir() or path.suffix in ("", ".txt", ".mp4", ".gif", ".script"):
        return path.exists()
    data = path.read_bytes()
    try:
        if path.suffix in (".npz", ".onnx"):
            if path.suffix == ".onnx" or b"metadata" in data[:4096]:
                from mjx_arm.policy import load

                load(path)
            else:
                np.load(io.BytesIO(data), allow_pickle=False).files  # noqa: B018
        elif path.suffix == ".json":
            json.loads(data)
        elif path.suffix == ".toml":
            tomllib.loads(data.decode())
        elif path.suffix == ".png":
            return data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 100
        elif path.suffix == ".xml":
            return b"<mujoco" in data
    except Exception:  # any failure to read it back: a broken output
        return False
    return True


def _changed(path: Path, digest: dict[str, str]) -> bool:
    """Whether a file that was there (of ``digest``) is changed or gone: a new file beside
    them (an error report in an output folder) spoils nothing."""
    now = _digest(path)
    return any(now.get(k) != v for k, v in digest.items()) or (not digest and bool(now))


def lost_outputs(before: dict[Path, tuple[bool, dict]], failed: bool) -> list[str]:
    """Good outputs a case spoiled: changed by a failing command, or left broken; a run
    directory's config or newest usable checkpoint changed."""
    lost = []
    for path, (is_run, digest) in before.items():
        if is_run:
            now = _run_dir_state(path)
            if any(now.get(k) != v for k, v in digest.items()):
                lost.append(f"{path.name}: checkpoint or config changed")
        elif _changed(path, digest) and (failed or not valid_output(path)):
            lost.append(f"{path.name}: {'changed by a failing command' if failed else 'broken'}")
    return lost


# --------------------------------------------------------------------------- running


@contextlib.contextmanager
def _quiet_fds() -> Iterator[None]:
    """File descriptors 1 and 2 to :data:`NATIVE_LOG` (emptied), or /dev/null: the engines' C
    code prints there (what a native crash said, for the pool to report)."""
    saved = [os.dup(1), os.dup(2)]
    with open(NATIVE_LOG or os.devnull, "wb") as null:
        os.dup2(null.fileno(), 1)
        os.dup2(null.fileno(), 2)
    try:
        yield
    finally:
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)


@contextlib.contextmanager
def _locks(case: Case, argv: list[str]) -> Iterator[None]:
    """Hold the lock of every run directory of ``case`` (another training's), if asked."""
    import fcntl

    with contextlib.ExitStack() as stack:
        for token in argv if case.lock else []:
            path = Path(token)
            if not (path.is_absolute() and path.is_dir()):
                continue
            try:  # a .lock made special (a socket, a folder) is not held
                f = stack.enter_context((path / ".lock").open("a+"))
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                f.write("4242")
                f.flush()
            except OSError:
                continue
        yield


def _alarm(*_args) -> None:
    raise Hang


def error_lines(text: str) -> list[str]:
    """The ``error:`` lines of a command's stderr (ours, or argparse's ``prog: error:``)."""
    return [line for line in text.splitlines() if line.startswith("error:") or ": error:" in line]


def _call_main(argv: list[str], err: io.StringIO) -> tuple[str, int | None, str]:
    """(status, exit code, detail) of ``mjx_arm.cli.main(argv)``."""
    from mjx_arm.cli import main

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(ALARM_SECONDS)
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except WorkStarted:
        return "work", None, ""
    except Hang:
        return "hang", None, f"stopped after {ALARM_SECONDS} s"
    except MemoryError:
        return "memory", None, traceback.format_exc()[-3000:]
    except Exception as exc:  # a bug: what the fuzz looks for
        memory = any(text in str(exc) for text in MEMORY_TEXTS)
        return ("memory" if memory else "traceback"), None, traceback.format_exc()[-3000:]
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    named = bool(error_lines(err.getvalue()))
    last = lines[-1] if lines else ""
    if code == 0:
        return "ok", code, last
    if code == 2:
        return ("named" if named else "unnamed"), code, last
    return "traceback", code, f"exit code {code}: {err.getvalue()[-2000:]}"


# Flags whose value is written: an input slot there (a config file as --out) is an output.
OUTPUT_FLAGS = ("-o", "--output", "--out", "--run-dir", "--video", "--trajectory", "--script",
                "--picture")  # fmt: skip


def _sentinel_roots(
    case: Case, corpus: Corpus, folder: Path, argv: list[str], outputs: dict[Path, Out]
) -> tuple[list[Path], list[Path]]:
    """(roots, skipped) of the files the case must not touch (:mod:`input_fuzz.sentinel`):
    its folder, the corpus and the repository's results, less its named outputs, ``runs/``
    (the benchmarks' default output), the run directories ``train`` writes and an input given
    as an output (after one of :data:`OUTPUT_FLAGS`)."""
    skip = [*outputs, folder / "runs"]
    slots = list(zip(case.argv, argv, strict=True))
    for i, (token, path) in enumerate(slots):  # an input given where an output goes
        flag = slots[i - 1][0] if i else ""
        train_run = case.command == "train" and getattr(token, "kind", "") == "run_dir"
        if isinstance(token, In) and (flag in OUTPUT_FLAGS or train_run):
            skip += [Path(path)] if Path(path).parent == folder else []
    users = [path / name for path, slot in outputs.items() if slot.name == "user"
             for name in USER_FILES]  # fmt: skip
    return [folder, corpus.folder, sentinel.REPO_RESULTS, *users], skip


def _run(case: Case, argv: list[str], folder: Path) -> tuple[str, int | None, str, str]:
    """(status, exit code, detail, stderr) of ``argv`` run in ``folder``."""
    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        with (
            _locks(case, argv),
            stubs(case.real),
            _quiet_fds(),
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            status, code, detail = _call_main(argv, err)
    finally:
        os.chdir(cwd)
    return status, code, detail, err.getvalue()


def run_case(case: Case, corpus: Corpus, folder: Path, on_start=None) -> Outcome:
    """Make the case's files in ``folder`` (created), run it and judge it; ``on_start()`` is
    called once the files are made (the pool resets its peak-memory mark there)."""
    folder.mkdir(parents=True, exist_ok=True)
    inputs: list[str] = []
    argv, outputs = materialise(case, corpus, folder, inputs)
    roots, skip = _sentinel_roots(case, corpus, folder, argv, outputs)
    untouched = sentinel.record(roots, skip)
    before = snapshot(argv, outputs)
    if on_start is not None:
        on_start()
    start = time.perf_counter()
    sentinel.watch_writes()
    try:
        status, code, detail, stderr = _run(case, argv, folder)
        seconds = time.perf_counter() - start
        touched, shared = sentinel.split_shared(
            sentinel.changes(untouched, sentinel.record(roots, skip))
        )
        written = sentinel.watched_writes()
        touched += written
    finally:
        remove_deep_outputs()
    longest = max(error_lines(stderr), key=len, default="")
    if seconds > HANG_SECONDS:
        status = "hang"
    elif status in GOOD:
        lost = lost_outputs(before, failed=code not in (0, None))
        if lost:
            status, detail = "lost", "; ".join(lost)
        elif touched:
            status, detail = "outside", "; ".join(touched)[:2000]
        elif len(longest) > MAX_ERROR_CHARS:
            status, detail = "long", f"{len(longest)} characters: {longest[:400]}"
    outcome = Outcome(case.command, status, code, seconds, argv, detail, inputs, longest[:400])
    outcome.error_chars = len(longest)
    outcome.outputs = [slot.name or "plain" for slot in outputs.values()]
    if shared and not written:  # another process wrote benchmarks/results meanwhile
        outcome.external = "; ".join(shared)[:500]
    return outcome


# What a worker runs once before its first case: the first training, arm check and
# evaluation of a process pay JAX's and the engines' start-up (8 s on an idle 2-core CPU,
# 25 s under load), which is no input's doing and would read as a hang.
WARM_UP = (
    Case("train", ["train", "--quiet", "--preset", "cpu", "--backend", "mujoco", "--run-dir",
                   Out("", False)]),
    Case("arm", ["arm", In("urdf", "good", 0)]),
    Case("eval", ["eval", "--episodes", "1", In("policy", "good", 0)]),
)  # fmt: skip


def warm_up(corpus: Corpus, folder: Path) -> None:
    """Run :data:`WARM_UP` in ``folder`` (created); their outcomes are not kept."""
    for i, case in enumerate(WARM_UP):
        run_case(case, corpus, folder / f"warm{i}")


def tally(outcomes: list[Outcome], key=lambda o: [o.command]) -> dict[str, dict[str, float]]:
    """Per ``key(outcome)`` (a list of row names; default: its command) and ``all``: cases,
    each status's count, the largest seconds and peak RSS (MB), and the longest error line's
    characters."""
    rows: dict[str, dict[str, float]] = {}
    empty = {"cases": 0, **dict.fromkeys(STATUSES, 0), "max_s": 0.0, "max_rss_mb": 0.0}
    for o in outcomes:
        for name in [*dict.fromkeys(key(o)), "all"]:
            row = rows.setdefault(name, {**empty, "longest_error": 0})
            row["cases"] += 1
            row[o.status] += 1
            row["max_s"] = max(row["max_s"], o.seconds)
            row["max_rss_mb"] = max(row["max_rss_mb"], o.peak_rss_mb)
            row["longest_error"] = max(row["longest_error"], o.error_chars)
    return dict(sorted(rows.items(), key=lambda kv: (kv[0] == "all", kv[0])))
