"""Mesh files and the files they name, opened safely: only a regular file is read, and only up
to a size bound.

A reader given a FIFO blocks until something writes to it (forever, for a validator), a
character device such as ``/dev/zero`` never ends, and the size a folder listing shows can be
stale by the time the file is read. So every mesh file and every side file (an OBJ's material
library and its textures, a glTF's buffers) is opened without blocking, checked to be a
regular file on the open descriptor (:func:`os.fstat`: no race with a rename between the check
and the read), and read up to its limit plus one byte, so a file that grows after the check is
refused too. Paths in messages are shortened to their tail (:func:`short_path`): a report line
stays under 300 characters however deep the folders are.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from mjx_arm.urdf.errors import ConversionError

__all__ = ["MIB", "UnsafeFileError", "file_kind", "read_regular", "short_path", "side_path"]

MIB = 2**20
# Characters of a path shown in a message: its tail, after "...".
PATH_CHARS = 60
_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)
_OPEN_FLAGS = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
_FIX_REGULAR = "point it at a regular file (a FIFO, device or socket is never read)"
_FIX_SMALLER = "simplify the mesh or shrink the file (e.g. in MeshLab or Blender)"
_FIX_SIDE = (
    "keep a mesh's material libraries, textures and buffers in its folder, named relative to it"
)


class UnsafeFileError(ConversionError):
    """A mesh or side file that is not read: not a regular file, or larger than its limit.

    Attributes:
        problem: what is wrong (``is a FIFO (named pipe), not a regular file``).
        fix: how to fix it.
    """

    def __init__(self, path: str | Path, problem: str, fix: str) -> None:
        super().__init__(f"{short_path(path)} {problem}; {fix}")
        self.problem, self.fix = problem, fix


def short_path(path: str | Path, chars: int = PATH_CHARS) -> str:
    """``path`` as text of at most ``chars`` characters: whole when it fits, else ``...``
    and its tail (from a ``/`` where one falls in the tail)."""
    text = str(path)
    if len(text) <= chars:
        return text
    tail = text[-(chars - 3) :]
    cut = tail.find("/")
    return "..." + (tail[cut:] if 0 <= cut < len(tail) - 1 else tail)


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, for a message: "a FIFO (named pipe)", ..."""
    for test, name in _KINDS:
        if test(mode):
            return name
    return "a regular file" if stat.S_ISREG(mode) else "a special file"


def read_regular(
    path: str | Path, limit: int, what: str = "mesh file", head: int | None = None
) -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit`` of them.

    Args:
        path: the file (a symbolic link is followed: the caller checks where it leads).
        limit: the most bytes it may have.
        what: what it is, for the message ("mesh file", "material library").
        head: read only its first ``head`` bytes (None: all of it).

    Raises:
        UnsafeFileError: not a regular file, or more than ``limit`` bytes (before or while
            it is read).
        OSError: it cannot be opened or read (missing, no permission).
    """
    fd = _open(path)
    try:  # checked on the open descriptor, before Python wraps it (it refuses a folder)
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = file_kind(info.st_mode)
            raise UnsafeFileError(path, f"is {kind}, not a regular file", _FIX_REGULAR)
        if info.st_size > limit:
            raise UnsafeFileError(path, too_large(info.st_size, limit, what), _FIX_SMALLER)
        stream = os.fdopen(fd, "rb", buffering=0)
    except BaseException:
        os.close(fd)
        raise
    with stream as f:
        wanted = limit + 1 if head is None else min(head, limit + 1)
        chunks, got = [], 0
        while got < wanted:
            chunk = f.read(min(wanted - got, 4 * MIB))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
    if got > limit:
        raise UnsafeFileError(path, f"grew above {limit / MIB:.0f} MiB while read", _FIX_SMALLER)
    return b"".join(chunks)


def _open(path: str | Path) -> int:
    """A descriptor of ``path`` opened without blocking (a FIFO opens at once).

    Raises:
        UnsafeFileError: it cannot be opened and is not a regular file (a socket).
        OSError: it cannot be opened (missing, no permission).
    """
    try:
        return os.open(path, _OPEN_FLAGS)
    except OSError as exc:
        try:
            mode = os.stat(path).st_mode
        except (OSError, ValueError):
            raise exc from None
        if stat.S_ISREG(mode):
            raise
        problem = f"is {file_kind(mode)}, not a regular file"
        raise UnsafeFileError(path, problem, _FIX_REGULAR) from exc


def too_large(size: int, limit: int, what: str) -> str:
    """``is 40.0 MiB, above the 32 MiB a mesh file may have``."""
    return f"is {size / MIB:.1f} MiB, above the {limit / MIB:.0f} MiB a {what} may have"


def side_path(mesh: Path, name: str) -> Path | None:
    """The file a mesh's reader opens for the side file ``name`` the mesh names, resolved
    (symbolic links followed), or None when nothing is there.

    The name must stay in the mesh's folder as written: an absolute name, or one whose ``..``
    leave the folder, is refused even when nothing is there, because PyBullet looks for a
    texture it cannot find beside the mesh again from its working directory (a texture named
    ``../pipe`` blocked it on a FIFO there). What is there must lie in the folder once links
    are followed; a folder is returned (PyBullet aborts reading one: the caller's read refuses
    it).

    Raises:
        UnsafeFileError: an absolute name, one leading out of the folder, or a link out of it.
    """
    text = name.strip()
    if text.startswith("/") or os.path.normpath(text).split(os.sep)[0] == "..":
        how = "is an absolute path" if text.startswith("/") else "leads out of the mesh's folder"
        raise UnsafeFileError(mesh, how, _FIX_SIDE)
    folder = mesh.parent.resolve()
    try:
        resolved = (folder / text).resolve()
        resolved.stat()
    except (OSError, RuntimeError, ValueError):  # missing, a link loop, a bad name
        return None
    if not resolved.is_relative_to(folder):
        problem = f"leads to {short_path(resolved, 40)}, outside the mesh's folder"
        raise UnsafeFileError(mesh, problem, _FIX_SIDE)
    return resolved
