"""Mesh and texture file resolution: ``package://`` URIs, relative paths, formats each engine reads.

A URDF may only point at files inside its own folder tree, inside a folder given in
``package_dirs``, or inside the folder of the ``package://`` package it names. A path that
leaves those folders (``../../etc/passwd``, an absolute path elsewhere, a symbolic link out) is
refused with a :class:`AssetPathError` before anything opens it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.mesh_files import file_kind, short_path

# MuJoCo reads STL, OBJ and its own MSH. Collada (.dae) is the usual ROS format that MuJoCo
# cannot read (the converter turns it into STL: mjx_arm.urdf.mesh_convert).
MUJOCO_MESH_FORMATS = frozenset({".stl", ".obj", ".msh"})
PACKAGE_PREFIX = "package://"
FILE_PREFIX = "file://"
# An unnamed package is searched for in the URDF's folder and this many folders above it (a ROS
# package holds its URDF one or two levels down; a workspace keeps packages side by side).
PACKAGE_SEARCH_LEVELS = 3
_PACKAGE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*\Z")


class AssetPathError(ConversionError):
    """A mesh or texture filename that names an unknown package or points outside its folders.

    Attributes:
        problem: what is wrong with the filename.
        fix: how to fix it.
    """

    def __init__(self, problem: str, fix: str) -> None:
        super().__init__(f"{problem}; {fix}")
        self.problem, self.fix = problem, fix


def find_package_dir(package: str, urdf_path: Path, package_dirs: Mapping[str, str]) -> Path | None:
    """Directory of ROS package ``package``: from ``package_dirs``, then the ``ROS_PACKAGE_PATH``
    variable (folders, ``:``-separated, holding packages or being one), else searched upwards.

    The upward search looks, from the URDF's folder up :data:`PACKAGE_SEARCH_LEVELS` folders
    (never at the file system root), for a folder named like the package, either the folder
    itself or a child of it. A name that is not a plain folder name (``..``, ``a/b``) is never
    searched for.
    """
    if package in package_dirs:
        return Path(package_dirs[package]).expanduser().resolve()
    if not _PACKAGE_NAME.match(package) or set(package) == {"."}:
        return None
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        root = Path(entry).expanduser().resolve()
        if root.name == package and _is_dir(root):
            return root
        if _is_dir(root / package):
            return root / package
    folders = [urdf_path.parent, *urdf_path.parent.parents][: PACKAGE_SEARCH_LEVELS + 1]
    for folder in folders:
        if folder.parent == folder:  # the file system root
            break
        if folder.name == package:
            return folder
        if _is_dir(folder / package):
            return folder / package
    return None


def resolve_asset(filename: str, urdf_path: Path, package_dirs: Mapping[str, str]) -> Path:
    """Absolute path of a mesh or texture ``filename``, checked to lie inside its folder.

    A ``package://NAME/...`` path must stay inside the package's folder; any other path (relative,
    absolute or ``file://``) inside the URDF's folder or a folder of ``package_dirs``. Symbolic
    links are followed before the check.

    Raises:
        AssetPathError: an unknown package, or a path outside those folders.
    """
    if filename.startswith(PACKAGE_PREFIX):
        package, _, rest = filename[len(PACKAGE_PREFIX) :].partition("/")
        base = find_package_dir(package, urdf_path, package_dirs)
        if base is None:
            name = package if len(package) <= 40 else package[:37] + "..."
            raise AssetPathError(
                f"names package {name!r}, which was not found above "
                f"{short_path(urdf_path.parent, 50)}",
                f"pass package_dirs={{'{name}': '/path'}} (CLI: --package {name}=/path)",
            )
        return _inside(base / rest, [base])
    local = filename[len(FILE_PREFIX) :] if filename.startswith(FILE_PREFIX) else filename
    path = Path(local)
    roots = [urdf_path.parent, *(Path(d).expanduser().resolve() for d in package_dirs.values())]
    return _inside(path if path.is_absolute() else urdf_path.parent / path, roots)


def _inside(path: Path, roots: list[Path]) -> Path:
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError, ValueError) as exc:  # a symbolic link loop, a bad name
        problem = f"cannot be resolved: {type(exc).__name__}"
        raise AssetPathError(problem, "give a plain file path") from exc
    if any(resolved.is_relative_to(root) for root in roots):
        return resolved
    folders = " or ".join(short_path(root, 50) for root in roots[:2])
    folders += f" or {len(roots) - 2} more" if len(roots) > 2 else ""
    raise AssetPathError(
        f"points to {short_path(resolved, 50)}, outside {folders}",
        "keep meshes and textures in the URDF's folder, or in a package folder given as "
        "package_dirs (CLI: --package NAME=DIR) and named package://NAME/...",
    )


def is_file(path: Path) -> bool:
    """``path.is_file()``, False instead of an error for names the OS refuses (too long)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def not_regular(path: Path) -> str:
    """What ``path`` is when it is there but not a regular file ("a FIFO (named pipe)", "a
    folder"), else "" (a regular file, or nothing there)."""
    try:
        mode = path.stat().st_mode
    except (OSError, ValueError):
        return ""
    kind = file_kind(mode)
    return "" if kind == "a regular file" else kind


def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


def existing_mesh(
    filename: str, urdf_path: Path, link: str, package_dirs: Mapping[str, str]
) -> Path:
    """The mesh file of ``filename``, resolved and present, in any format; else a
    :class:`ConversionError` that says how to fix it."""
    try:
        path = resolve_asset(filename, urdf_path, package_dirs)
    except AssetPathError as exc:
        raise ConversionError(
            f"{short_path(urdf_path)}: link {link!r}: mesh {short_path(filename)!r} "
            f"{exc.problem}; {exc.fix}"
        ) from exc
    kind = not_regular(path)
    if kind or not is_file(path):
        what = f"is {kind}, not a regular file" if kind else "does not exist"
        raise ConversionError(
            f"{short_path(urdf_path)}: link {link!r}: mesh file {short_path(path)} {what}"
        )
    return path


def resolve_mesh_filename(
    filename: str, urdf_path: Path, link: str, package_dirs: Mapping[str, str]
) -> Path:
    """Resolve a mesh for MuJoCo or raise a :class:`ConversionError` that says how to fix it."""
    path = existing_mesh(filename, urdf_path, link, package_dirs)
    if path.suffix.lower() not in MUJOCO_MESH_FORMATS:
        raise ConversionError(
            f"{short_path(urdf_path)}: link {link!r}: mesh {short_path(path.name, 40)} is "
            f"{path.suffix[:16]} which MuJoCo cannot "
            f"read; convert it to .stl or .obj (for example with trimesh or meshlab)"
        )
    return path
