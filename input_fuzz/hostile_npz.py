"""Structure-aware mutations of ``.npz`` files (policies, trajectories, a checkpoint's
``resume.npz`` and ``env_state.npz``): the zip and ``.npy`` layers are kept valid, and what they
declare is hostile.

- :func:`huge_header`: a member whose ``.npy`` header declares :data:`HUGE_ELEMENTS` float32
  elements (4 TiB) in a file of a few kB;
- :func:`zip_bomb`: an extra (or a real) member that unpacks to :data:`BOMB_BYTES` of zeros from
  about 3 MB (:func:`bomb_stream` builds the deflate stream without compressing 3 GiB);
- :func:`object_member`: a member of pickled Python objects;
- :func:`wrong_dtype`: a member cast to complex, text, float16, int64 or bool;
- :func:`extreme_values`: a whole member of 3e38, -3e38, NaN, inf or subnormals;
- :func:`misfit_shape`: a member given an extra axis, flattened, doubled or emptied.

Each is a mutation ``(good file, output path, rng) -> description`` (:mod:`input_fuzz.mutate`).
"""

from __future__ import annotations

import functools
import io
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np
from numpy.lib import format as npy

HUGE_ELEMENTS = 2**40
BOMB_BYTES = 3 * 2**30
_CHUNK = 64 * 2**20  # BOMB_BYTES is a whole number of chunks
# CRC-32 of the bomb member (its header, then BOMB_BYTES zeros): computing it reads 3 GiB, so it
# is kept here; tests/test_input_fuzz.py unpacks the whole member and checks it (slow).
BOMB_CRC = 0x54720FE7
KEPT = ("metadata", "task_config")  # the JSON members: not numbers to damage


def pick(rng: np.random.Generator, items):
    """One of ``items`` (a sequence), uniformly."""
    return items[int(rng.integers(len(items)))]


def read_members(path: Path) -> dict[str, np.ndarray]:
    """Every array of a good ``.npz``."""
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def npy_bytes(array: np.ndarray) -> bytes:
    """``array`` as the bytes of an ``.npy`` file (pickled when it holds objects)."""
    buffer = io.BytesIO()
    npy.write_array(buffer, np.asanyarray(array), allow_pickle=True)
    return buffer.getvalue()


def npy_header(shape: tuple[int, ...], dtype: str) -> bytes:
    """The bytes of an ``.npy`` header (version 1.0) declaring ``shape`` of ``dtype``."""
    buffer = io.BytesIO()
    npy.write_array_header_1_0(
        buffer, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)}
    )
    return buffer.getvalue()


def _numeric_key(arrays: dict[str, np.ndarray], rng: np.random.Generator) -> str:
    return str(pick(rng, sorted(k for k in arrays if k not in KEPT)))


def write_zip(out: Path, members: dict[str, bytes], bomb: str | None = None) -> None:
    """An ``.npz`` of ``members`` (name -> ``.npy`` bytes, stored) and, when ``bomb`` names one,
    a deflated member of that name that unpacks to :data:`BOMB_BYTES` zeros after its header."""
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for name, data in members.items():
            archive.writestr(f"{name}.npy", data)
    if bomb is not None:
        _append_deflated(out, f"{bomb}.npy", *bomb_stream())


@functools.cache
def bomb_stream() -> tuple[bytes, int, int]:
    """(deflate stream, CRC-32, unpacked size) of an ``.npy`` member: a header declaring
    :data:`BOMB_BYTES` uint8, then that many zeros. Each 64 MiB of zeros is compressed once and
    repeated: a full flush makes every chunk's compressed block the same bytes."""
    header = npy_header((BOMB_BYTES,), "|u1")
    compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
    head = compressor.compress(header) + compressor.flush(zlib.Z_FULL_FLUSH)
    zeros = bytes(_CHUNK)
    block = compressor.compress(zeros) + compressor.flush(zlib.Z_FULL_FLUSH)
    tail = compressor.flush(zlib.Z_FINISH)
    count = BOMB_BYTES // _CHUNK
    return head + block * count + tail, BOMB_CRC, len(header) + BOMB_BYTES


def _append_deflated(out: Path, name: str, stream: bytes, crc: int, size: int) -> None:
    """Add a deflated member to the zip ``out`` from its ready compressed ``stream``: rewrite
    the central directory after the new local entry (sizes under 4 GiB: no zip64)."""
    data = out.read_bytes()
    end = data.rindex(b"PK\x05\x06")
    entries, _, directory_size, directory_at = struct.unpack("<4x2x2xHHII", data[end : end + 20])
    body, directory = data[:directory_at], data[directory_at : directory_at + directory_size]
    raw = name.encode()
    fixed = struct.pack("<HHHHHIII", 20, 0, 8, 0, 0x21, crc, len(stream), size)
    local = b"PK\x03\x04" + fixed + struct.pack("<HH", len(raw), 0) + raw
    central = (
        b"PK\x01\x02"
        + struct.pack("<H", 20)
        + fixed
        + struct.pack("<HHHHHII", len(raw), 0, 0, 0, 0, 0o644 << 16, len(body))
        + raw
    )
    new_directory = directory + central
    tail = struct.pack(
        "<4sHHHHIIH",
        b"PK\x05\x06",
        0,
        0,
        entries + 1,
        entries + 1,
        len(new_directory),
        len(body) + len(local) + len(stream),
        0,
    )
    out.write_bytes(body + local + stream + new_directory + tail)


def _members(good: Path) -> dict[str, bytes]:
    return {k: npy_bytes(v) for k, v in read_members(good).items()}


def huge_header(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A member's header declares 2^40 float32 elements; its bytes stay a few kB."""
    arrays = read_members(good)
    key = _numeric_key(arrays, rng)
    shape = pick(rng, ((HUGE_ELEMENTS,), (2**20, 2**20), (2**40, 1)))
    members = {k: npy_bytes(v) for k, v in arrays.items()}
    members[key] = npy_header(shape, "<f4") + np.asarray(arrays[key], np.float32).tobytes()
    write_zip(out, members)
    return f"{key} declares shape {shape} float32"


def zip_bomb(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A member of 3 GiB of zeros compressed to about 3 MB: an extra unused one, or in place
    of a real one."""
    members = _members(good)
    key = pick(rng, ("unused", "unused", _numeric_key(read_members(good), rng)))
    members.pop(key, None)
    write_zip(out, members, bomb=key)
    return f"{key} unpacks to {BOMB_BYTES / 2**30:.0f} GiB of zeros"


def object_member(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A member of pickled Python objects."""
    members = _members(good)
    key = pick(rng, (*sorted(members), "extra"))
    payload = np.empty(2, dtype=object)
    payload[:] = [{"a": 1}, [1.0, 2.0]]
    members[key] = npy_bytes(payload)
    write_zip(out, members)
    return f"{key} holds pickled objects"


DTYPES = ("complex64", "complex128", "<U8", "float16", "int64", "int8", "bool", "uint64")


def wrong_dtype(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A member cast to another dtype (its values kept where the dtype can hold them)."""
    arrays = read_members(good)
    key = _numeric_key(arrays, rng)
    dtype = pick(rng, DTYPES)
    with np.errstate(all="ignore"):
        arrays[key] = np.asarray(arrays[key]).astype(dtype)
    write_zip(out, {k: npy_bytes(v) for k, v in arrays.items()})
    return f"{key} as {dtype}"


EXTREMES = (3e38, -3e38, np.nan, np.inf, -np.inf, 1e-45)


def extreme_values(good: Path, out: Path, rng: np.random.Generator) -> str:
    """Every entry of a member set to 3e38, NaN, inf or a subnormal (float32 kept)."""
    arrays = read_members(good)
    key = _numeric_key(arrays, rng)
    value = pick(rng, EXTREMES)
    arrays[key] = np.full(np.shape(arrays[key]), value, np.float32)
    write_zip(out, {k: npy_bytes(v) for k, v in arrays.items()})
    return f"{key} all {value!r}"


def misfit_shape(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A member with an extra axis, flattened, doubled along its first axis, or emptied."""
    arrays = read_members(good)
    key = _numeric_key(arrays, rng)
    value = np.asarray(arrays[key])
    op = pick(rng, ("axis", "flat", "double", "empty"))
    changed = {
        "axis": lambda: value[None],
        "flat": lambda: value.reshape(-1) if value.ndim > 1 else value[:, None],
        "double": lambda: np.concatenate([value, value]) if value.ndim else value[None],
        "empty": lambda: value[:0] if value.ndim else np.zeros(0, value.dtype),
    }[op]()
    arrays[key] = changed
    write_zip(out, {k: npy_bytes(v) for k, v in arrays.items()})
    return f"{key} shape {value.shape} -> {changed.shape}"


NPZ_MUTATIONS = (huge_header, zip_bomb, object_member, wrong_dtype, extreme_values, misfit_shape)
