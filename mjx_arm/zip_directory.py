"""The central directory of a zip file (an ``.npz``), bounded before :mod:`zipfile` reads it.

When it opens a zip, ``zipfile.ZipFile`` reads the whole central directory and makes an object of
each entry (about 550 bytes): a zip of a million empty members, 88 MB on disk, took 545 MB of
memory and 10 s to open before any member was looked at. The end-of-central-directory record at
the end of the file states the entry count and the directory's size; :func:`checked_directory`
reads them (and those of the zip64 record, which ``zipfile`` uses where there is one) and
refuses a file of more than :data:`MAX_ENTRIES` entries or :data:`MAX_DIRECTORY_BYTES` bytes
of directory. The files mjx_arm reads hold a few to a few hundred arrays (a policy about 10, a
trajectory 8, a resume state about a hundred).
"""

from __future__ import annotations

import os
import struct
from typing import BinaryIO

MAX_ENTRIES = 16_384
MAX_DIRECTORY_BYTES = 2**20  # 1 MiB: a member named in 46 bytes or more, 22,795 at most
_END = struct.Struct("<4s4H2LH")  # end of central directory
_LOCATOR = struct.Struct("<4sLQL")  # zip64 end-of-directory locator
_END64 = struct.Struct("<4sQ2H2L4Q")  # zip64 end of central directory
_MAX_COMMENT = 2**16 - 1


def _directory(stream: BinaryIO) -> tuple[int, int] | None:
    """``(entries, directory bytes)`` the end records state (the larger of the classic and
    the zip64 record's); None where there is no end record (``zipfile`` reports that)."""
    size = stream.seek(0, os.SEEK_END)
    tail_start = max(0, size - _END.size - _MAX_COMMENT)
    stream.seek(tail_start)
    tail = stream.read(size - tail_start)
    at = tail.rfind(b"PK\x05\x06")
    if at < 0 or len(tail) - at < _END.size:
        return None
    fields = _END.unpack_from(tail, at)
    entries, directory = fields[4], fields[5]
    locator = tail_start + at - _LOCATOR.size
    if locator - _END64.size >= 0:
        stream.seek(locator - _END64.size)
        record = stream.read(_END64.size + _LOCATOR.size)
        if record[_END64.size : _END64.size + 4] == b"PK\x06\x07" and record[:4] == b"PK\x06\x06":
            zip64 = _END64.unpack_from(record)
            entries, directory = max(entries, zip64[7]), max(directory, zip64[8])
    return entries, directory


def checked_directory(stream: BinaryIO) -> BinaryIO:
    """``stream`` (a zip opened for reading, seekable), back at its start, once its central
    directory is within :data:`MAX_ENTRIES` and :data:`MAX_DIRECTORY_BYTES`.

    Raises:
        ValueError: a directory over a limit, with the counts it states.
    """
    stated = _directory(stream)
    stream.seek(0)
    if stated is not None:
        entries, directory = stated
        if entries > MAX_ENTRIES or directory > MAX_DIRECTORY_BYTES:
            raise ValueError(
                f"its zip directory lists {entries:,} members in {directory:,} bytes, over the "
                f"limits of {MAX_ENTRIES:,} and {MAX_DIRECTORY_BYTES:,}: not a file mjx_arm wrote"
            )
    return stream
