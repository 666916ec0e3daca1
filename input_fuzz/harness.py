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
- ``long``: an ``error:`` line longer than :data:`MAX_ERROR_CHARS` characters;
- ``memory``: the case ran out of memory (a ``MemoryError`` or a native allocation failure
  under the worker's cap, :mod:`input_fuzz.pool`);
- ``crash``: the worker process running the case died (a signal: a native crash).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
import signal
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import numpy as np

from input_fuzz.cases import Case, In, Out
from input_fuzz.corpus import Corpus
from input_fuzz.mutate import mutate

HANG_SECONDS = 30.0
ALARM_SECONDS = 120  # a case still running then is stopped (and counted as a hang)
MAX_ERROR_CHARS = 300
STATUSES = ("ok", "named", "work", "traceback", "unnamed", "hang", "lost")
STATUSES += ("long", "memory", "crash")
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
    peak address space so far (both 0 in process)."""

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


@contextlib.contextmanager
def stubs() -> Iterator[None]:
    """The long work of every command stopped (:data:`WORK_STUBS`)."""
    import mjx_arm.evaluate.core as core
    import mjx_arm.train.ppo as ppo

    with contextlib.ExitStack() as stack:
        for target, stub in WORK_STUBS.items():
            stack.enter_context(mock.patch(target, stub))
        stack.enter_context(
            mock.patch.object(core, "run_episodes", _short_episodes(core.run_episodes))
        )
        stack.enter_context(mock.patch.object(ppo, "make_envs", _cpu_envs_only(ppo.make_envs)))
        yield


# --------------------------------------------------------------------------- files

GOOD_OUTPUT = {".json": b'{"good": true}\n', ".txt": b"good\n", ".script": b"def good():\nend\n"}


def _fill_in(slot: In, corpus: Corpus, folder: Path, index: int) -> tuple[Path, str]:
    """The path of an input slot, made in ``folder``, and what it is (``kind mode[ how]``)."""
    good = corpus.run_dir if slot.kind == "run_dir" else corpus.files().get(slot.kind)
    label = f"{slot.kind} {slot.mode}"
    if good is None:  # onnx without the onnx package: another kind's good file
        good, label = corpus.policy, f"{slot.kind} other"
    name = folder / f"in{index}_{slot.kind}{'' if slot.kind == 'run_dir' else good.suffix}"
    rng = np.random.default_rng(slot.seed)
    if slot.mode == "missing":
        return name.with_name("missing_" + name.name), label
    if slot.mode == "other":
        files = list(corpus.files().values())
        return files[int(rng.integers(len(files)))], label
    if slot.mode in ("mutated", "hostile"):
        what = mutate(slot.kind, good, name, rng, hostile=slot.mode == "hostile")
        how, _, rest = what.partition(": ")
        if how.startswith("hostile_"):  # a dispatcher: its own edit names the mutation
            how = rest.partition(": ")[0]
        return name, f"{label} {how}"
    if slot.kind == "run_dir":
        shutil.copytree(good, name)
    else:
        shutil.copy(good, name)
    return name, label


def _seed_output(slot: Out, corpus: Corpus, path: Path) -> None:
    """A good file at ``path`` before the case (what a failing command must not spoil)."""
    if not slot.seeded:
        return
    if slot.suffix == "":
        path.mkdir(parents=True, exist_ok=True)
        (path / "good.txt").write_bytes(b"good\n")
        return
    sources = {".npz": corpus.policy, ".onnx": corpus.onnx, ".toml": corpus.arm_file}
    source = sources.get(slot.suffix)
    if source is not None:
        shutil.copy(source, path)
    else:
        path.write_bytes(GOOD_OUTPUT.get(slot.suffix, b"good output\n"))


def materialise(
    case: Case, corpus: Corpus, folder: Path, inputs: list[str] | None = None
) -> tuple[list[str], dict[Path, Out]]:
    """The argv of ``case`` with its files made in ``folder``; and its output paths. Each input
    slot's ``kind mode[ how]`` is appended to ``inputs``."""
    argv, outputs = [], {}
    for i, token in enumerate(case.argv):
        if isinstance(token, In):
            path, label = _fill_in(token, corpus, folder, i)
            argv.append(str(path))
            if inputs is not None:
                inputs.append(label)
        elif isinstance(token, Out):
            path = folder / f"out{i}{token.suffix}"
            _seed_output(token, corpus, path)
            outputs[path] = token
            argv.append(str(path))
        else:
            argv.append(str(token))
    return argv, outputs


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


def _run_dir_state(path: Path) -> dict[str, str]:
    """What a run directory must keep: config.json and its newest usable checkpoint."""
    from mjx_arm.train.checkpoints import latest_checkpoint

    latest = latest_checkpoint(path / "checkpoints") if path.is_dir() else None
    if latest is None:
        return {}
    kept = {"config.json": _digest(path / "config.json").get("", "")}
    kept.update({f"{latest.name}/{k}": v for k, v in _digest(latest).items()})
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
    """File descriptors 1 and 2 to /dev/null (the engines' C code prints there)."""
    saved = [os.dup(1), os.dup(2)]
    with open(os.devnull, "wb") as null:
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
            if path.is_absolute() and path.is_dir():
                f = stack.enter_context((path / ".lock").open("a+"))
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                f.write("4242")
                f.flush()
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


def run_case(case: Case, corpus: Corpus, folder: Path) -> Outcome:
    """Make the case's files in ``folder`` (created), run it and judge it."""
    folder.mkdir(parents=True, exist_ok=True)
    inputs: list[str] = []
    argv, outputs = materialise(case, corpus, folder, inputs)
    before = snapshot(argv, outputs)
    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    start = time.perf_counter()
    try:
        os.chdir(folder)
        with (
            _locks(case, argv),
            stubs(),
            _quiet_fds(),
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            status, code, detail = _call_main(argv, err)
    finally:
        os.chdir(cwd)
    seconds = time.perf_counter() - start
    longest = max(error_lines(err.getvalue()), key=len, default="")
    if seconds > HANG_SECONDS:
        status = "hang"
    elif status in GOOD:
        lost = lost_outputs(before, failed=code not in (0, None))
        if lost:
            status, detail = "lost", "; ".join(lost)
        elif len(longest) > MAX_ERROR_CHARS:
            status, detail = "long", f"{len(longest)} characters: {longest[:400]}"
    outcome = Outcome(case.command, status, code, seconds, argv, detail, inputs, longest[:400])
    outcome.error_chars = len(longest)
    return outcome


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
