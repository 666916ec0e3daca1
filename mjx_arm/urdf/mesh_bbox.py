"""Bounding boxes of STL and OBJ mesh files, read from their bytes (no mesh library), and the
test for a text STL that neither engine reads. Reads are cached per path, modification time and
size.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np

from mjx_arm.urdf.findings import MAX_MESH_BYTES
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular

READ_FORMATS = frozenset({".stl", ".obj"})  # the formats whose bounding box is read
_STL_RECORD = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


@functools.lru_cache(maxsize=256)
def _is_ascii_stl_at(path: str, mtime_ns: int, size: int) -> bool:
    """True for a text STL (``solid ...`` and no consistent binary header)."""
    del mtime_ns
    try:
        head = read_regular(path, MAX_MESH_BYTES, head=84)
    except (OSError, UnsafeFileError):
        return False
    binary = len(head) == 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")
    return not binary and head.lstrip().startswith(b"solid")


@functools.lru_cache(maxsize=256)
def _mesh_box_at(path: str, mtime_ns: int, size: int) -> np.ndarray | None:
    """Bounding box ``(2, 3)`` of an STL or OBJ file's vertices, or None when unreadable.

    ``mtime_ns`` and ``size`` only key the cache.
    """
    del mtime_ns, size
    try:
        data = read_regular(path, MAX_MESH_BYTES)
        suffix = Path(path).suffix.lower()
        vertices = _stl_vertices(data) if suffix == ".stl" else None
        vertices = _obj_vertices(data) if suffix == ".obj" else vertices
    except (OSError, ValueError, UnsafeFileError):
        return None
    if vertices is None or len(vertices) == 0 or not np.all(np.isfinite(vertices)):
        return None
    return np.stack([vertices.min(axis=0), vertices.max(axis=0)])


def _stl_vertices(data: bytes) -> np.ndarray | None:
    """Vertices ``(n, 3)`` of a binary or ASCII STL."""
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        exact = len(data) == 84 + 50 * count
        if count and (exact or (not data.startswith(b"solid") and len(data) > 84 + 50 * count)):
            records = np.frombuffer(data, dtype=_STL_RECORD, count=count, offset=84)
            return records["v"].reshape(-1, 3).astype(float)
    found = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
    return np.array(found, dtype=float) if found else None


def _obj_vertices(data: bytes) -> np.ndarray | None:
    """Vertices ``(n, 3)`` of a Wavefront OBJ (the ``v`` lines)."""
    found = re.findall(rb"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", data, flags=re.MULTILINE)
    return np.array(found, dtype=float) if found else None


def is_ascii_stl(path: Path) -> bool:
    """True for a text STL at ``path`` (``solid ...`` and no consistent binary header)."""
    return _is_ascii_stl_at(str(path), *_stamp(path))


def mesh_box(path: Path) -> np.ndarray | None:
    """Bounding box ``(2, 3)`` of the STL or OBJ file's vertices, or None when unreadable."""
    return _mesh_box_at(str(path), *_stamp(path))


def _stamp(path: Path) -> tuple[int, int]:
    """``path``'s modification time (ns) and size (bytes): what the reads are cached on."""
    stat = path.stat()
    return stat.st_mtime_ns, stat.st_size
