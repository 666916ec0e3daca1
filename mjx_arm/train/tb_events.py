"""TensorBoard scalars written as an event file, with nothing but the standard library.

A run logs a few dozen scalars per evaluation. TensorBoard reads them from files of
length-delimited records (the TFRecord framing: length, its checksum, the bytes, their
checksum; CRC-32C masked as TensorFlow masks it) that hold ``Event`` protocol buffers. Both
are small enough to write by hand, which keeps a training run from importing a TensorBoard
library at its first evaluation: tensorboardX imports torch wherever torch is installed,
seconds of a run's start-up.

The messages written (field numbers of TensorFlow's ``event.proto`` and ``summary.proto``):
``Event{1: wall_time (double), 2: step (int64), 3: file_version (string), 5: summary}``,
``Summary{1: value (repeated)}``, ``Summary.Value{1: tag (string), 2: simple_value (float)}``.
"""

from __future__ import annotations

import socket
import struct
import time
from typing import BinaryIO

from mjx_arm.protobuf_wire import length_delimited, varint

FILE_VERSION = "brain.Event:2"
_CRC32C_POLY = 0x82F63B78  # Castagnoli, bit-reversed
_MASK_DELTA = 0xA282EAD8


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ _CRC32C_POLY if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_TABLE = _crc_table()


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli) of ``data``; ``crc32c(b"123456789") == 0xE3069283``."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc = _TABLE[(crc ^ byte) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def masked_crc32c(data: bytes) -> int:
    """The checksum as a TFRecord stores it (rotated right by 15 bits, plus a constant)."""
    crc = crc32c(data)
    return (((crc >> 15) | (crc << 17)) + _MASK_DELTA) & 0xFFFFFFFF


def record(data: bytes) -> bytes:
    """``data`` framed as one TFRecord."""
    length = struct.pack("<Q", len(data))
    return b"".join(
        (length, struct.pack("<I", masked_crc32c(length)), data,
         struct.pack("<I", masked_crc32c(data)))
    )  # fmt: skip


def event(wall_time: float, step: int = 0, *, version: str = "", scalars=None) -> bytes:
    """An ``Event`` message: the file's version record, or ``scalars`` ({tag: value}) at
    ``step``."""
    out = varint(1 << 3 | 1) + struct.pack("<d", wall_time)
    if step:
        out += varint(2 << 3) + varint(int(step))
    if version:
        out += length_delimited(3, version.encode())
    if scalars:
        values = b"".join(
            length_delimited(1, length_delimited(1, tag.encode()) + b"\x15" + struct.pack("<f", v))
            for tag, v in scalars.items()
        )
        out += length_delimited(5, values)
    return out


def event_file_name(wall_time: float | None = None) -> str:
    """A name TensorBoard takes for an event file (it looks for ``tfevents``)."""
    wall_time = time.time() if wall_time is None else wall_time
    return f"events.out.tfevents.{int(wall_time):010d}.{socket.gethostname()}"


class ScalarWriter:
    """Scalars appended to one event file (``stream``, opened for appending in binary)."""

    def __init__(self, stream: BinaryIO) -> None:
        self._stream = stream
        self._stream.write(record(event(time.time(), version=FILE_VERSION)))
        self._stream.flush()

    def add_scalars(self, step: int, scalars: dict[str, float]) -> None:
        """One event holding every scalar of ``step``, flushed to the file."""
        self._stream.write(record(event(time.time(), step, scalars=scalars)))
        self._stream.flush()

    def close(self) -> None:
        self._stream.close()
