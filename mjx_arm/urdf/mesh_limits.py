"""Size and triangle counts of a mesh file, checked before trimesh or MuJoCo reads it.

The limits (:data:`~mjx_arm.urdf.findings.MAX_MESH_BYTES`,
:data:`~mjx_arm.urdf.findings.MAX_MESH_FACES`, :data:`~mjx_arm.urdf.findings.MAX_MESH_VERTICES`)
live with the validator's other limits, with the measured failure points behind them. A binary
STL's face count is read from its header; an OBJ's faces and vertices are counted by their lines;
other formats are bounded by their size here and by their face count once trimesh has read them.
"""

from __future__ import annotations

import re
from pathlib import Path

from mjx_arm.urdf.findings import (
    MAX_MESH_BYTES,
    MAX_MESH_FACES,
    MAX_MESH_VERTICES,
)

__all__ = ["count_problem", "mesh_problem", "path_problem"]

_OBJ_FACE = re.compile(rb"^[ \t]*f[ \t]", re.MULTILINE)
_OBJ_VERTEX = re.compile(rb"^[ \t]*v[ \t]", re.MULTILINE)
_MIB = 2**20


def mesh_problem(path: Path) -> str | None:
    """What makes the mesh file at ``path`` too large to read, or None when it is within the
    limits (a file that cannot be read at all is left to the readers, which name the cause)."""
    try:
        size = path.stat().st_size
    except OSError:
        return None
    if size > MAX_MESH_BYTES:
        return (
            f"is {size / _MIB:.1f} MiB, above the {MAX_MESH_BYTES / _MIB:.0f} MiB a mesh file "
            "may have"
        )
    suffix = path.suffix.lower()
    try:
        if suffix == ".stl":
            return count_problem(_stl_faces(path, size), 0)
        if suffix == ".obj":
            data = path.read_bytes()
            return count_problem(len(_OBJ_FACE.findall(data)), len(_OBJ_VERTEX.findall(data)))
    except OSError:
        return None
    return None


def path_problem(path: Path, limit: int, label: str) -> str | None:
    """What makes the absolute ``path`` of a mesh longer than the ``limit`` bytes the engine
    ``label`` loads, or None (PyBullet crashes on longer ones:
    :data:`~mjx_arm.urdf.findings.MAX_MESH_PATH_BYTES`)."""
    size = len(str(path).encode("utf-8", "surrogateescape"))
    if size > limit:
        return (
            f"resolves to a path of {size:,} bytes, more than the {limit:,} "
            f"{label} reads (it crashes on longer ones)"
        )
    return None


def count_problem(faces: int, vertices: int) -> str | None:
    """What is wrong with a mesh of ``faces`` triangles and ``vertices`` vertices, or None."""
    if faces > MAX_MESH_FACES:
        return f"has {faces:,} faces, more than the {MAX_MESH_FACES:,} MuJoCo reads"
    if vertices > MAX_MESH_VERTICES:
        return f"has {vertices:,} vertices, more than the {MAX_MESH_VERTICES:,} this tool accepts"
    return None


def _stl_faces(path: Path, size: int) -> int:
    """Faces of an STL: a binary STL's header count (when the file is long enough to hold
    them; a corrupt header is left to the readers), an ASCII STL's ``facet`` keywords."""
    with open(path, "rb") as f:
        head = f.read(84)
    if len(head) == 84:
        count = int.from_bytes(head[80:84], "little")
        if size >= 84 + 50 * count:
            return count
    return path.read_bytes().count(b"facet ") if head.lstrip().startswith(b"solid") else 0
