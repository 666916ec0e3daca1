"""Meshes in formats MuJoCo cannot read (Collada ``.dae``, PLY, glTF, ...) converted to binary
STL with trimesh (pycollada reads Collada for it).

A converted mesh is written once to a cache folder and named by a hash of the source file's
bytes, so converting the same file again returns the same path without rewriting it. A scene of
several geometries becomes one mesh with each geometry's transform applied, and a Collada file's
``<unit meter>`` is applied, so the STL is in metres like the rest of the URDF. Collada's
``<up_axis>`` is ignored, as ROS tools (RViz, Gazebo) ignore it.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import io
import logging
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import write_atomic
from mjx_arm.urdf.errors import ConversionError, one_line
from mjx_arm.urdf.findings import MAX_MESH_BYTES, MAX_MESH_FACES
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular, short_path
from mjx_arm.urdf.mesh_limits import count_problem, data_problem
from mjx_arm.urdf.mesh_side_files import trimesh_input

# Mesh formats trimesh reads, with the modules each needs (import name -> pip name).
CONVERTIBLE_FORMATS = frozenset({".dae", ".zae", ".ply", ".off", ".glb", ".gltf"})
_TRIMESH = {"trimesh": "trimesh"}
_COLLADA = {**_TRIMESH, "collada": "pycollada"}
_NEEDED = {".dae": _COLLADA, ".zae": _COLLADA}
INSTALL_HINT = "pip install trimesh pycollada"
# Folder of converted meshes beside a written MJCF file (see :func:`cache_dir_for`).
CACHE_FOLDER = "meshes_converted"
# Part of every hash: a change in how meshes are converted gives new file names.
_HASH_SALT = b"mjx_arm.mesh_convert 1\0"
_FIX = (
    "re-export the mesh as binary .stl or .obj (e.g. with Blender or MeshLab) and point the "
    "URDF's filename at it"
)
_FIX_LARGE = "simplify the mesh (e.g. a quadric decimation in MeshLab or Blender)"
# Loaders of trimesh that take ``skip_materials`` (Collada's reads no texture given no file).
_SKIPS_MATERIALS = frozenset({"obj", "ply", "gltf", "glb"})


class MeshConvertError(ConversionError):
    """A mesh that cannot be converted, with what is wrong and how to fix it.

    Attributes:
        problem: what is wrong, without the file name.
        fix: how to fix it.
    """

    def __init__(self, path: Path, problem: str, fix: str) -> None:
        super().__init__(f"{short_path(path)}: {problem}; {fix}")
        self.problem, self.fix = problem, fix


def missing_packages(suffix: str) -> list[str]:
    """Pip names of the packages that converting a ``suffix`` mesh needs and that are missing.

    Args:
        suffix: the file suffix with its dot, any case (``.DAE``).

    Returns:
        e.g. ``["pycollada"]``; empty when everything is installed.
    """
    needed = _NEEDED.get(suffix.lower(), _TRIMESH)
    return [pip for module, pip in needed.items() if not _importable(module)]


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def default_cache_dir() -> Path:
    """The per-user cache of converted meshes: ``$XDG_CACHE_HOME/mjx_arm/meshes`` (by default
    ``~/.cache/mjx_arm/meshes``)."""
    base = os.environ.get("XDG_CACHE_HOME") or "~/.cache"
    return Path(base).expanduser() / "mjx_arm" / "meshes"


def cache_dir_for(output: str | Path | None) -> Path:
    """Where meshes converted for ``output`` go: ``meshes_converted/`` beside that MJCF file, or
    :func:`default_cache_dir` when there is no output file."""
    if output is None:
        return default_cache_dir()
    return Path(output).expanduser().resolve().parent / CACHE_FOLDER


def convert_mesh(path: str | Path, cache_dir: str | Path | None = None) -> Path:
    """Convert one mesh file to binary STL in ``cache_dir``, or return the earlier conversion.

    Args:
        path: the source mesh (``.dae``, ``.ply``, ... any of :data:`CONVERTIBLE_FORMATS`).
        cache_dir: folder of converted meshes, created when missing; None uses
            :func:`default_cache_dir`.

    Returns:
        The path of ``<stem>_<hash>.stl`` in ``cache_dir``; the hash is of the source's bytes.

    Raises:
        MeshConvertError: a package is missing, the file cannot be read or holds no triangles,
            or the cache folder cannot be written.
    """
    source = Path(path)
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    folder = folder.expanduser().resolve()  # the MJCF names the STL by its absolute path
    target = folder / f"{_safe_stem(source)}_{_content_hash(source)}.stl"
    if target.is_file():
        return target
    mesh = load_mesh(source)
    _write_atomic(mesh, target)
    return target


def mesh_bounds(path: str | Path) -> np.ndarray:
    """Bounding box ``(2, 3)`` (min, max; m) of a mesh file as :func:`convert_mesh` converts it.

    Cached per file version (path, modification time, size).

    Raises:
        MeshConvertError: as :func:`load_mesh`.
    """
    source = Path(path)
    stat = _stat(source)
    return _bounds_cached(str(source.resolve()), stat.st_mtime_ns, stat.st_size).copy()


@functools.lru_cache(maxsize=256)
def _bounds_cached(path: str, mtime_ns: int, size: int) -> np.ndarray:
    del mtime_ns, size  # part of the cache key only
    return np.asarray(load_mesh(Path(path)).bounds, dtype=float)


def load_mesh(path: str | Path) -> Any:
    """Read a mesh file into one ``trimesh.Trimesh`` in metres.

    Args:
        path: the mesh file.

    Returns:
        A ``trimesh.Trimesh`` with ``(n, 3)`` vertices and ``(m, 3)`` faces, ``m > 0``.

    Raises:
        MeshConvertError: a package is missing, or the file cannot be read or holds no
            finite triangles.
    """
    source = Path(path)
    data = read_mesh_bytes(source)
    problem = data_problem(source, data)
    if problem:
        raise MeshConvertError(source, f"the file {problem.problem}", problem.fix)
    missing = missing_packages(source.suffix)
    if missing:
        raise MeshConvertError(
            source,
            f"converting a {source.suffix} mesh needs {' and '.join(missing)}, not installed",
            f"{INSTALL_HINT}, or convert the mesh to .stl or .obj yourself",
        )
    loaded = _read(source, data)
    mesh = _concatenate(loaded, source)
    scale = _unit_scale(getattr(loaded, "units", None), source)
    if scale != 1.0:
        mesh.apply_scale(scale)
    if len(mesh.faces) == 0:
        raise MeshConvertError(source, "the mesh holds no triangles", _FIX)
    too_many = count_problem(len(mesh.faces), len(mesh.vertices))
    if too_many:
        raise MeshConvertError(source, f"the mesh {too_many}", _FIX_LARGE)
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshConvertError(source, "the mesh has non-finite vertex coordinates", _FIX)
    return mesh


def _read(source: Path, data: bytes) -> Any:
    """``trimesh.load`` of the bytes ``data`` of ``source``, quietly (trimesh's log records and
    pycollada's warnings are not shown), given only the side files it needs for the geometry
    (:func:`~mjx_arm.urdf.mesh_side_files.trimesh_input`): no materials, no textures."""
    import trimesh

    try:
        data, file_type, files = trimesh_input(source, data)
    except UnsafeFileError as exc:
        raise MeshConvertError(source, f"the file {exc.problem}", exc.fix) from exc
    logger = logging.getLogger("trimesh")
    if not logger.handlers:  # a library's logger: no output unless the application asks for it
        logger.addHandler(logging.NullHandler())
    options = {"skip_materials": True} if file_type in _SKIPS_MATERIALS else {}
    resolver = trimesh.resolvers.ZipResolver(files)  # serves these files, and nothing else
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return trimesh.load(io.BytesIO(data), file_type, resolver=resolver, **options)
    except Exception as exc:  # trimesh and pycollada raise many kinds on broken files
        problem = f"trimesh cannot read it ({type(exc).__name__}: {one_line(exc)[:120]})"
        raise MeshConvertError(source, problem, _FIX) from exc


def _concatenate(loaded: Any, source: Path) -> Any:
    """One ``trimesh.Trimesh`` from a mesh or a scene: each instance of a geometry moved by its
    transform, geometry only (no visuals: a texture is never decoded). A scene whose
    instances hold more than MAX_MESH_FACES faces is refused before they are copied."""
    import trimesh

    if isinstance(loaded, trimesh.Trimesh):
        return loaded
    if not isinstance(loaded, trimesh.Scene):
        kind = type(loaded).__name__
        raise MeshConvertError(source, f"the file holds a {kind}, not a triangle mesh", _FIX)
    parts, faces = [], 0
    for node in loaded.graph.nodes_geometry:
        transform, name = loaded.graph[node]
        geometry = loaded.geometry.get(name)
        if isinstance(geometry, trimesh.Trimesh):
            faces += len(geometry.faces)
            if faces > MAX_MESH_FACES:
                problem = f"the scene instances more than the {MAX_MESH_FACES:,} faces MuJoCo reads"
                raise MeshConvertError(source, problem, _FIX_LARGE)
            parts.append((transform, geometry))
    if not parts:
        raise MeshConvertError(source, "the file holds no triangle mesh", _FIX)
    meshes = [
        trimesh.Trimesh(vertices=g.vertices, faces=g.faces, process=False).apply_transform(t)
        for t, g in parts
    ]
    return trimesh.util.concatenate(meshes)


def _unit_scale(units: str | None, source: Path) -> float:
    """Factor from the file's units (Collada's ``<unit meter>``) to metres; 1 when unstated."""
    if not units or units in ("meters", "meter", "m"):
        return 1.0
    import trimesh

    try:
        return float(trimesh.units.unit_conversion(units, "meters"))
    except (ValueError, KeyError, TypeError) as exc:
        problem = f"its unit {units!r} cannot be converted to metres ({one_line(exc)})"
        raise MeshConvertError(source, problem, "give the file's <unit> in metres") from exc


def _write_atomic(mesh: Any, target: Path) -> None:
    """Write ``mesh`` as binary STL to ``target`` (:func:`write_atomic`)."""
    try:
        write_atomic(mesh.export(file_type="stl"), target)
    except OSError as exc:
        raise MeshConvertError(
            target,
            f"the converted mesh cannot be written ({one_line(exc)})",
            "set ConvertConfig.mesh_cache_dir to a writable folder",
        ) from exc


def _content_hash(source: Path) -> str:
    return hashlib.sha256(_HASH_SALT + read_mesh_bytes(source)).hexdigest()[:20]


def read_mesh_bytes(source: Path) -> bytes:
    """The bytes of the mesh file ``source``: a regular file of at most MAX_MESH_BYTES
    (:func:`~mjx_arm.urdf.mesh_files.read_regular`).

    Raises:
        MeshConvertError: not a regular file, too large, or unreadable.
    """
    try:
        return read_regular(source, MAX_MESH_BYTES)
    except UnsafeFileError as exc:
        raise MeshConvertError(source, f"the file {exc.problem}", exc.fix) from exc
    except OSError as exc:
        raise MeshConvertError(source, f"the file cannot be read ({one_line(exc)})", _FIX) from exc


def _stat(source: Path) -> os.stat_result:
    try:
        return source.stat()
    except OSError as exc:
        raise MeshConvertError(source, f"the file cannot be read ({one_line(exc)})", _FIX) from exc


def _safe_stem(source: Path) -> str:
    """The file's stem in characters safe for a file and a MuJoCo mesh name."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", source.stem)[:64] or "mesh"
