"""What the user gives a command: named errors for bad inputs, and the checks every command shares.

An :class:`InputError` is a file, setting or argument that cannot be used; ``mjx-arm`` prints its
message as one ``error:`` line and exits with :data:`mjx_arm.names.EXIT_INVALID` (2), in one
place (:func:`mjx_arm.cli.main`). Anything else is a bug: its traceback shows and the exit code
is 1. The named errors of the packages (arm configs, URDFs, policy files, run directories)
derive from it, and each is also the builtin error it always was (ValueError, OSError, ...).

Input files are read with :func:`open_regular` / :func:`read_bytes` (and :func:`read_text`,
:func:`read_json_object` on top): only a regular file (never a FIFO or a device), of a bounded
size, and with ``within`` never through a link out of the given folder (a run directory).

Outputs are written with :func:`write_atomic` (a temporary file in the same folder, renamed into
place), so a failing or killed command never leaves half a file where a good one was.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import stat
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from mjx_arm.zip_directory import checked_directory


class InputError(Exception):
    """An input (file, setting, argument) that cannot be used; the message names it, says what
    is wrong and how to fix it.

    Attributes:
        headline: a one-line summary for the command line when the message is a long report
            (a validation report, say); empty: the message itself is the line. ``mjx-arm``
            prints the headline and writes the whole message to an error-report file.
    """

    headline: str = ""


class ConfigError(InputError, ValueError):
    """A config value of the wrong type or out of range, or an unknown key."""


class InputFileError(InputError, OSError):
    """An input file that is not a file, or cannot be read or parsed."""


class MissingInputError(InputFileError, FileNotFoundError):
    """An input file or folder that does not exist."""


class OutputWriteError(InputError, OSError):
    """An output that could not be written (a full disk, a folder that refuses files)."""


class OutputPathError(InputError, ValueError):
    """An output path that cannot be written: a folder for a file, a file for a folder, the
    wrong suffix, no writable folder."""


def require_file(path: str | Path, what: str) -> Path:
    """``path`` as a Path, checked to be a readable file.

    Args:
        path: the file given.
        what: what it should be, for the message ("policy file").

    Raises:
        MissingInputError: it does not exist.
        InputFileError: it is a folder, or cannot be read.
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise MissingInputError(f"{what} {str(path)!r} does not exist; check the path")
    if not path.is_file():
        raise InputFileError(f"{what} {str(path)!r} is not a file; give the path of a file")
    if not os.access(path, os.R_OK):
        raise InputFileError(f"{what} {str(path)!r} cannot be read; check its permissions")
    return path


def read_text(
    path: str | Path, what: str, max_bytes: int | None = None, *, within: str | Path | None = None
) -> str:
    """The text of a readable UTF-8 regular file of at most ``max_bytes`` (default
    :data:`MAX_TEXT_BYTES`), read by :func:`read_bytes` (``within``: see there).

    Raises:
        InputFileError: missing, not a regular file, too big, unreadable, or not UTF-8 text.
    """
    data = read_bytes(path, what, MAX_TEXT_BYTES if max_bytes is None else max_bytes, within=within)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputFileError(f"{what} {str(path)!r} cannot be read as UTF-8 text: {err}") from err


def read_json_object(
    path: str | Path, what: str, max_bytes: int | None = None, *, within: str | Path | None = None
) -> dict[str, Any]:
    """A JSON file holding one object (a dict), read by :func:`read_text`.

    Raises:
        InputFileError: missing, not a regular file, too big, unreadable, not JSON, or not an
            object.
    """
    text = read_text(path, what, max_bytes, within=within)
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as err:
        raise InputFileError(f"{what} {str(path)!r} is not valid JSON: {err}") from err
    if not isinstance(data, dict):
        raise InputFileError(
            f"{what} {str(path)!r} must hold a JSON object ({{...}}), not {type(data).__name__}"
        )
    return data


# --------------------------------------------------------------------------- bounded reads

MiB = 2**20
MAX_TEXT_BYTES = 16 * MiB  # read_text's default bound: configs, arm files, run metadata


class OversizedInputError(InputFileError, ValueError):
    """An input file (or an ``.npz`` member) larger than the limit its reader sets."""


def open_regular(
    path: str | Path, what: str, max_bytes: int, *, within: str | Path | None = None
) -> BinaryIO:
    """``path`` opened to read (binary) only if it is a regular file of at most ``max_bytes``:
    a FIFO, a device (``/dev/zero``), a socket or a folder is refused before a byte is read
    (opened non-blocking, then ``fstat``). The size is the one at opening (see read_bytes).

    Args:
        path: the file.
        what: what it is, for the messages ("checkpoint metadata").
        max_bytes: the largest size accepted.
        within: a folder the file must lie in (a run directory): a link whose target lies
            outside it is refused; None: links are followed wherever they go.

    Raises:
        MissingInputError: no such file.
        OversizedInputError: larger than ``max_bytes``.
        InputFileError: not a regular file, a link out of ``within``, or unreadable.
    """
    path = Path(path).expanduser()
    name = f"{what} {str(path)!r}"
    target, flags = path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if within is not None:
        target = Path(os.path.realpath(path))
        if not target.is_relative_to(os.path.realpath(within)):
            raise InputFileError(f"{name} is a link to {target}, outside {within}: refused")
        flags |= getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(target, flags)
    except FileNotFoundError:
        raise MissingInputError(f"{name} does not exist; check the path") from None
    except OSError as err:
        raise InputFileError(f"{name} cannot be opened: {err.strerror or err}") from err
    try:
        _check_regular(os.fstat(fd), name, max_bytes)
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _check_regular(info: os.stat_result, name: str, max_bytes: int) -> None:
    """Refuse an opened file that is not a regular file of at most ``max_bytes``."""
    if stat.S_ISDIR(info.st_mode):
        raise InputFileError(f"{name} is a folder, not a file; give the path of a file")
    if not stat.S_ISREG(info.st_mode):
        raise InputFileError(f"{name} is not a regular file (a FIFO, device or socket)")
    if info.st_size > max_bytes:
        raise _oversized(name, info.st_size, max_bytes)


def read_bytes(
    path: str | Path, what: str, max_bytes: int, *, within: str | Path | None = None
) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``, opened by :func:`open_regular`
    (same arguments and errors); a file that grows past the bound while read is refused too."""
    with open_regular(path, what, max_bytes, within=within) as f:
        try:  # the size at opening first: read(n) allocates n bytes however short the file
            size = os.fstat(f.fileno()).st_size
            data = f.read(size + 1)
            if len(data) > size:  # it grew since: on, up to the bound
                data += f.read(max(0, max_bytes + 1 - len(data)))
        except OSError as err:
            raise InputFileError(f"{what} {str(path)!r} cannot be read: {err.strerror}") from err
    if len(data) > max_bytes:
        raise _oversized(f"{what} {str(path)!r}", len(data), max_bytes)
    return data


def _oversized(name: str, size: int, limit: int) -> OversizedInputError:
    return OversizedInputError(
        f"{name} holds {size:,} bytes or more, over the limit of {limit:,} bytes: not a file "
        "mjx_arm wrote, or a damaged one"
    )


def check_output(path: str | Path, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """An output path, checked before any work: not a folder, the right suffix, and a folder
    that exists or can be created.

    Raises:
        OutputPathError: the path is a folder, has the wrong suffix, or its folder is a file.
    """
    path = Path(path).expanduser()
    if suffixes and path.suffix not in suffixes:
        raise OutputPathError(f"{what} {str(path)!r} must end in one of {', '.join(suffixes)}")
    if path.is_dir():
        raise OutputPathError(f"{what} {str(path)!r} is a folder; give a file name")
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise OutputPathError(f"{what} {str(path)!r}: {parent} is not a writable folder")
    return path


def check_folder(path: str | Path, what: str) -> Path:
    """An output folder, checked before any work: not a file, and it exists or can be created
    (its nearest existing parent is a writable folder).

    Raises:
        OutputPathError: the path is a file, or no writable folder holds it.
    """
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{what} {str(path)!r} is a file; give a folder")
    parent = path
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise OutputPathError(f"{what} {str(path)!r}: {parent} is not a writable folder")
    return path


def write_atomic(data: bytes, target: Path) -> None:
    """Write ``data`` to ``target`` through a temporary file in the same folder (created if
    missing), so a reader (or a second process writing the same file) never sees half a file,
    and a failure (a full disk, a kill) leaves the old file whole.

    Raises:
        OutputWriteError: the folder or the file cannot be written (an OSError).
    """
    target = Path(target)
    temporary = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        # named from the target's first 200 bytes: a name may have 255 (a long one is valid)
        start = target.name.encode("utf-8", "surrogateescape")[:200].decode("utf-8", "ignore")
        handle, temporary = tempfile.mkstemp(suffix=".tmp", prefix=f".{start}.", dir=target.parent)
        with os.fdopen(handle, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(temporary, 0o644)
        os.replace(temporary, target)
    except OSError as err:
        raise OutputWriteError(
            f"cannot write {target}: {err.strerror or err}; any file already there is untouched"
        ) from err
    finally:
        if temporary is not None and os.path.exists(temporary):
            os.unlink(temporary)


# --------------------------------------------------------------------------- .npz files


def read_npz_members(
    path: str | Path,
    what: str,
    wanted: Callable[[str], bool] | None = None,
    *,
    max_member_bytes: int,
    max_total_bytes: int,
    error: type[Exception] = InputFileError,
    max_member_elements: int | None = None,
    within: str | Path | None = None,
) -> dict[str, Any]:
    """The arrays of an ``.npz`` (opened by :func:`open_regular`, ``within`` as there), read
    without trust: the members ``wanted`` accepts (None: all), each checked before allocation
    (zip size, ``.npy`` header) against ``max_member_bytes`` and ``max_member_elements`` (None:
    none; for readers that widen uint8), all against ``max_total_bytes``; no pickles.

    Raises:
        OversizedInputError: a member or the total over its limit (with its declared size).
        ``error``: a file that is not a readable ``.npz`` (not a zip, truncated, a pickle).
    """
    import zipfile
    import zlib

    path = Path(path)
    try:
        stream = open_regular(path, what, sys.maxsize, within=within)
        with stream, zipfile.ZipFile(checked_directory(stream)) as archive:
            infos = [i for i in archive.infolist() if i.filename.endswith(".npy")]
            infos = [i for i in infos if wanted is None or wanted(i.filename[:-4])]
            _check_sizes(path, what, infos, max_member_bytes, max_total_bytes)
            return {
                i.filename[:-4]: _read_member(
                    archive, i, path, what, max_member_bytes, error, max_member_elements
                )
                for i in infos
            }
    except (OversizedInputError, error):
        raise
    except InputFileError as err:  # missing, or not a regular file: as open_regular names it
        raise error(str(err)) from err
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as err:
        raise error(
            f"cannot read {path} as a {what} .npz (truncated or not such a file?): "
            f"{type(err).__name__}: {err}"
        ) from err


def _too_big(path: Path, what: str, subject: str, size: int, limit: int) -> OversizedInputError:
    return OversizedInputError(
        f"{path}: {subject} would unpack to {size / MiB:,.1f} MiB, over the limit of "
        f"{limit / MiB:,.0f} MiB for a {what}: a damaged or hostile file, not one mjx_arm wrote"
    )


def _check_sizes(path: Path, what: str, infos: list, member_limit: int, total_limit: int) -> None:
    """The unpacked sizes the zip directory states, before any member is unpacked."""
    for info in infos:
        if info.file_size > member_limit:
            raise _too_big(path, what, f"member {info.filename!r}", info.file_size, member_limit)
    total = sum(info.file_size for info in infos)
    if total > total_limit:
        raise _too_big(path, what, "the members it reads, together,", total, total_limit)


def _read_member(
    archive: Any,
    info: Any,
    path: Path,
    what: str,
    limit: int,
    error: type[Exception],
    max_elements: int | None = None,
) -> Any:
    """One ``.npy`` member, allocated only once its header's shape and dtype fit the bytes the
    zip directory states (already checked against the limits) and its element count
    ``max_elements``; pickled objects are refused."""
    import numpy as np
    from numpy.lib import format as npy

    member = f"member {info.filename!r}"
    with archive.open(info) as stream:
        version = npy.read_magic(stream)
        read_header = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
        shape, fortran, dtype = read_header(stream)
        if dtype.hasobject:
            raise error(f"{path}: {member} holds pickled Python objects, refused")
        declared = math.prod(shape) * dtype.itemsize
        if max_elements is not None and math.prod(shape) > max_elements:
            raise OversizedInputError(
                f"{path}: {member} (shape {shape}, {dtype}) holds {math.prod(shape):,} elements, "
                f"over the limit of {max_elements:,} for a {what}: a damaged or hostile file"
            )
        if declared > limit:
            raise _too_big(path, what, f"{member} (shape {shape}, {dtype})", declared, limit)
        if declared > info.file_size:
            raise error(
                f"{path}: {member} declares shape {shape} ({dtype}), {declared:,} bytes, more "
                f"than the {info.file_size:,} bytes it holds: a damaged {what}"
            )
        array = np.empty(shape[::-1] if fortran else shape, dtype=dtype)
        view, got = memoryview(array.reshape(-1).view(np.uint8)), 0
        while got < declared:  # in chunks: no second copy of the member in memory
            n = stream.readinto(view[got : got + 4 * MiB])
            if not n:
                raise error(f"{path}: {member} is truncated: a damaged {what}")
            got += n
    return array.T if fortran else array


# --------------------------------------------------------------------------- argparse types

MAX_SEED = 2**32 - 1  # JAX's and NumPy's seeds: an unsigned 32-bit integer


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


def int_in(low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[low, high]`` (no upper bound: ``high`` None)."""

    def parse(text: str) -> int:
        value = _integer(text)
        if value < low or (high is not None and value > high):
            span = f">= {low}" if high is None else f"in [{low}, {high}]"
            raise argparse.ArgumentTypeError(f"must be an integer {span}, got {value}")
        return value

    parse.__name__ = "integer"  # argparse names the type in some messages
    return parse


def float_in(low: float, high: float | None = None) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in ``[low, high]``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not math.isfinite(value) or value < low or (high is not None and value > high):
            span = f">= {low:g}" if high is None else f"in [{low:g}, {high:g}]"
            raise argparse.ArgumentTypeError(f"must be a finite number {span}, got {text}")
        return value

    parse.__name__ = "number"
    return parse


nonnegative_int = int_in(0)
seed_int = int_in(0, MAX_SEED)
pixels = int_in(16, 4096)  # video and plot sizes
positive_int = int_in(1)
