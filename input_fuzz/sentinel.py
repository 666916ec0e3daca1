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
