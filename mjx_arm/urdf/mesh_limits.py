"""Size, triangle counts and contents of a mesh file, checked before trimesh or an engine reads it.

The limits (:data:`~mjx_arm.urdf.findings.MAX_MESH_BYTES`,
:data:`~mjx_arm.urdf.findings.MAX_MESH_FACES`, :data:`~mjx_arm.urdf.findings.MAX_MESH_VERTICES`)
live with the validator's other limits, with the measured failure points behind them. The file
is read only when it is a regular file within the size limit (:mod:`mjx_arm.urdf.mesh_files`).
A binary STL's face count is read from its header. An OBJ is read line by line: its faces and
vertices are counted, every index a face names must exist (PyBullet reads out of bounds and
crashes on a face index of 99,999,999), its line endings must be LF or CRLF, and the side files
it names must be safe (:mod:`mjx_arm.urdf.mesh_side_files`). Other formats are bounded by their
size here and by their face count once trimesh has read them.

Line endings: an OBJ with a lone CR (carriage return, the classic Mac ending) is refused, not
rewritten. MuJoCo reads it line by line, PyBullet as one line (so the mesh PyBullet loads is not
the one the file describes, and a large one takes PyBullet minutes), and a rewritten copy would
be a second file the engines read instead of the user's. The fix is one command.
"""

from __future__ import annotations

from pathlib import Path

from mjx_arm.urdf.findings import MAX_MESH_BYTES, MAX_MESH_FACES, MAX_MESH_VERTICES
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular
from mjx_arm.urdf.mesh_side_files import MeshProblem, obj_side_problem

__all__ = [
    "MeshProblem",
    "count_problem",
    "data_problem",
    "mesh_problem",
    "obj_problem",
    "path_problem",
]

_ELEMENTS = (b"f", b"l", b"p")  # the OBJ lines that name vertices by index
_FIX_LARGE = "simplify the mesh (e.g. a quadric decimation in MeshLab or Blender)"
_FIX_CR = "give the OBJ LF line endings, e.g. tr '\\r' '\\n' < FILE.obj > fixed.obj"
_FIX_EXPORT = "export the mesh again (e.g. from Blender or MeshLab)"
_KINDS = ("vertex", "texture coordinate", "normal")


def mesh_problem(path: Path) -> MeshProblem | None:
    """What makes the mesh file at ``path`` unsafe or too large to read, and its fix, or None
    when it is within the limits (a file that cannot be opened at all is left to the readers,
    which name the cause). Not cached: the side files an OBJ names can change without it."""
    try:
        data = read_regular(path, MAX_MESH_BYTES)
    except UnsafeFileError as exc:
        return MeshProblem(exc.problem, exc.fix)
    except OSError:
        return None
    return data_problem(path, data)


def data_problem(path: Path, data: bytes) -> MeshProblem | None:
    """What is wrong with the bytes ``data`` of the mesh file ``path`` (its face and vertex
    counts; for an OBJ also its indices, line endings and side files), or None."""
    suffix = path.suffix.lower()
    if suffix == ".stl":
        too_many = count_problem(_stl_faces(data), 0)
        return None if too_many is None else MeshProblem(too_many, _FIX_LARGE)
    if suffix == ".obj":
        return obj_problem(data) or obj_side_problem(path, data)
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


def obj_problem(data: bytes) -> MeshProblem | None:
    """What is wrong with the text ``data`` of an OBJ: a lone CR line ending, more faces or
    vertices than the limits, or a face (line, point) naming a vertex, texture coordinate or
    normal that the file does not have (index 0, above the count, or a negative index
    reaching before the first); None when it is fine."""
    if data.count(b"\r") != data.count(b"\r\n"):
        problem = (
            "has lone CR line endings: PyBullet reads such a file as one line and MuJoCo "
            "line by line, so the engines would not load the same mesh"
        )
        return MeshProblem(problem, _FIX_CR)
    counts, top, faces, bad = _scan_obj(data)
    if bad:
        return MeshProblem(bad, _FIX_EXPORT)
    too_many = count_problem(faces, counts[0])
    if too_many:
        return MeshProblem(too_many, _FIX_LARGE)
    for name, highest, count in zip(_KINDS, top, counts, strict=True):
        if highest > count:
            problem = (
                f"has a face naming {name} {highest:,}, but the file has {count:,} "
                "(PyBullet would read past its arrays: it crashes on such files)"
            )
            return MeshProblem(problem, _FIX_EXPORT)
    return None


def _scan_obj(data: bytes) -> tuple[list[int], list[int], int, str]:
    """One pass over an OBJ's lines: the counts of ``v``, ``vt`` and ``vn`` lines, the highest
    index of each that a face names, the ``f`` lines, and the first bad index ("" if none)."""
    counts, top, faces = [0, 0, 0], [0, 0, 0], 0
    kinds = {b"v": 0, b"vt": 1, b"vn": 2}
    for number, line in enumerate(data.split(b"\n"), 1):
        tokens = line.split(b"#", 1)[0].split() if b"#" in line else line.split()
        if not tokens:
            continue
        kind = kinds.get(tokens[0])
        if kind is not None:
            counts[kind] += 1
        elif tokens[0] in _ELEMENTS:
            faces += tokens[0] == b"f"
            bad = _check_refs(tokens[1:], counts, top)
            if bad:
                return counts, top, faces, f"has a bad index on line {number:,}: {bad}"
    return counts, top, faces, ""


def _check_refs(refs: list[bytes], counts: list[int], top: list[int]) -> str:
    """Check the ``v/vt/vn`` references of one face line against the ``counts`` read so far
    (a negative index counts back from there); raise the highest positive ones in ``top``
    (checked against the whole file's counts at the end). Returns what is wrong, or ""."""
    for ref in refs:
        for kind, text in enumerate(ref.split(b"/")[:3]):
            if not text and kind:  # "1//3": no texture coordinate
                continue
            try:
                index = int(text)
            except ValueError:
                return f"{ref[:20].decode(errors='replace')!r} is not a vertex reference"
            if index > top[kind]:
                top[kind] = index
            elif index == 0 or -index > counts[kind]:
                return f"index {index:,} names no {_KINDS[kind]}"
    return ""


def _stl_faces(data: bytes) -> int:
    """Faces of an STL: a binary STL's header count (when the file is long enough to hold
    them; a corrupt header is left to the readers), an ASCII STL's ``facet`` keywords."""
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        if len(data) >= 84 + 50 * count:
            return count
    return data.count(b"facet ") if data[:84].lstrip().startswith(b"solid") else 0
