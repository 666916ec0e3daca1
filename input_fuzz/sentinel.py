"""Files a case must not touch, recorded before and compared after it.

A command may write its named outputs and nothing else. The sentinels of a case are every file
and folder under these roots, but its named outputs:

- the case's folder: its inputs (each file argument, the mesh files beside a URDF, every file
  of a run directory), a file of the user's put beside its outputs (:data:`USER_FILE`), the
  files of a user's folder given as an output folder, and a ``benchmarks/results/`` tree of the
  user's for the benchmarks (which write into ``runs/`` of the working folder by default);
- the corpus of good files (what "other" slots and outside links point to);
- the repository's ``benchmarks/results/`` tree (a benchmark writes there only where ``--out``
  names it).

The repository's tree is shared with other processes (another benchmark may write its results
while a case runs), so a change there counts only where this process wrote there during the
case: :func:`watch_writes` records, by an audit hook (:func:`sys.addaudithook`), every write a
process makes from Python under that tree (an ``open`` for writing, a rename, a removal, a new
folder). A change there that no such write explains is another process's: the harness reports
it apart and does not count it.

Each entry is recorded by ``lstat`` (a link is not followed, a FIFO is not opened): a file's
type, size and modification time in ns, a folder's type; an entry changed, removed or added is
a change. Left out: the named outputs, a run directory ``train`` writes into, and two
allowances: a run directory's ``.lock`` (a command may hold it while it reads) and a checkpoint
left as ``.old-step_N`` that a reader moves back to ``step_N`` (contents unchanged; names are
compared without the ``.old-`` prefix).
"""

from __future__ import annotations

import os
import stat
import sys
from collections.abc import Iterable
from pathlib import Path

REPO_RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
USER_FILE = "user_notes.txt"
IGNORED = (".lock", "__pycache__")
OLD = ".old-"

State = dict[str, tuple[int, int, int]]  # path -> (file type, size, mtime ns)


def _entry(info: os.stat_result) -> tuple[int, int, int]:
    """(type, size, mtime ns) of a file; a folder's type only (its times change with its
    entries, which are recorded themselves)."""
    kind = stat.S_IFMT(info.st_mode)
    return (kind, 0, 0) if kind == stat.S_IFDIR else (kind, info.st_size, info.st_mtime_ns)


def _key(path: str) -> str:
    """``path`` with the ``.old-`` prefix of any part removed."""
    return "/".join(part.removeprefix(OLD) for part in path.split("/"))


def record(roots: Iterable[Path], skip: Iterable[Path] = ()) -> State:
    """The sentinel state of every entry at or under ``roots`` (folders walked, links not
    followed), but ``skip`` and what lies under it."""
    skipped = {os.path.abspath(p) for p in skip}
    state: State = {}
    for root in roots:
        root = os.path.abspath(root)
        if root in skipped:
            continue
        try:
            info = os.lstat(root)
        except OSError:
            continue
        state[_key(root)] = _entry(info)
        if not stat.S_ISDIR(info.st_mode):
            continue
        for folder, dirs, files in os.walk(root, onerror=lambda _err: None):
            dirs[:] = [d for d in dirs if os.path.join(folder, d) not in skipped]
            for name in files + dirs:
                path = os.path.join(folder, name)
                if name in IGNORED or path in skipped:
                    continue
                try:
                    state[_key(path)] = _entry(os.lstat(path))
                except OSError:
                    continue
    return state


def changes(before: State, after: State) -> list[str]:
    """What changed between two records: ``changed``, ``removed`` or ``added`` paths."""
    found = [f"changed {p}" for p in before if p in after and after[p] != before[p]]
    found += [f"removed {p}" for p in before if p not in after]
    found += [f"added {p}" for p in after if p not in before]
    return found


# Audit events of writes (and what names the path), and open flags that write.
_WRITE_EVENTS = {
    "os.rename": 1,  # os.replace too: (src, dst, ...), the destination
    "os.remove": 0,
    "os.rmdir": 0,
    "os.mkdir": 0,
    "os.truncate": 0,
    "os.symlink": 1,
    "os.link": 1,
    "shutil.copyfile": 1,
    "shutil.rmtree": 0,
}
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
_writes: list[str] = []
_hooked = False


def _written_path(event: str, args: tuple) -> object:
    """The path a write-ish audit event writes, or None for a read or another event."""
    if event == "open":
        path, mode, flags = args
        writing = (isinstance(mode, str) and any(c in mode for c in "wax+")) or (
            isinstance(flags, int) and flags & _WRITE_FLAGS
        )
        return path if writing else None
    index = _WRITE_EVENTS.get(event)
    return None if index is None or len(args) <= index else args[index]


def _audit(event: str, args: tuple) -> None:
    if event != "open" and event not in _WRITE_EVENTS:
        return
    path = _written_path(event, args)
    if isinstance(path, str | bytes | os.PathLike):
        text = os.path.abspath(os.fsdecode(path))
        if text.startswith(str(REPO_RESULTS) + os.sep) or text == str(REPO_RESULTS):
            _writes.append(f"{event} {text}")


def watch_writes() -> None:
    """Start (again) recording this process's writes under :data:`REPO_RESULTS`."""
    global _hooked
    if not _hooked:
        sys.addaudithook(_audit)
        _hooked = True
    _writes.clear()


def watched_writes() -> list[str]:
    """The writes under :data:`REPO_RESULTS` since :func:`watch_writes` (``event path``)."""
    return list(dict.fromkeys(_writes))


def split_shared(found: list[str]) -> tuple[list[str], list[str]]:
    """``found`` (:func:`changes`) as (those outside :data:`REPO_RESULTS`, those inside)."""
    inside = [c for c in found if c.split(" ", 1)[1].startswith(str(REPO_RESULTS))]
    return [c for c in found if c not in inside], inside
