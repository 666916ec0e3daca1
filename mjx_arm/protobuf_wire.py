"""The two pieces of protocol buffers' wire format that files written by hand need: a varint
and a length-delimited field (a string, bytes or an embedded message)."""

from __future__ import annotations


def varint(value: int) -> bytes:
    """``value`` as a base-128 varint; a negative one as protobuf encodes an int64 (ten bytes)."""
    out = bytearray()
    value &= (1 << 64) - 1
    while True:
        low, value = value & 0x7F, value >> 7
        out.append(low | (0x80 if value else 0))
        if not value:
            return bytes(out)


def length_delimited(number: int, payload: bytes) -> bytes:
    """Field ``number`` holding ``payload`` (wire type 2)."""
    return varint(number << 3 | 2) + varint(len(payload)) + payload
