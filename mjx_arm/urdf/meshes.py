"""Mesh file resolution: ``package://`` URIs, relative paths, and formats each engine reads."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from mjx_arm.urdf.errors import ConversionError

# MuJoCo reads STL, OBJ and its own MSH; PyBullet reads STL and OBJ (and DAE through assimp-free
# loaders only partly). Collada (.dae) is the usual ROS format that MuJoCo cannot read.
MUJOCO_MESH_FORMATS = frozenset({".stl", ".obj", ".msh"})
PYBULLET_MESH_FORMATS = frozenset({".stl", ".obj", ".dae"})


def find_package_dir(package: str, urdf_path: Path, package_dirs: Mapping[str, str]) -> Path | None:
    """Directory of ROS package ``package``: from ``package_dirs``, else searched upwards.

    The upward search looks, from the URDF's folder to the file system root, for a folder named
    like the package, either the folder itself or a child of it.
    """
    if package in package_dirs:
        return Path(package_dirs[package]).expanduser().resolve()
    for folder in [urdf_path.parent, *urdf_path.parent.parents]:
        if folder.name == package:
            return folder
        if (folder / package).is_dir():
            return folder / package
    return None


def mesh_path(filename: str, urdf_path: Path, package_dirs: Mapping[str, str]) -> Path | None:
    """Absolute path a URDF mesh ``filename`` points to, or None for an unknown package."""
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        base = find_package_dir(package, urdf_path, package_dirs)
        return None if base is None else (base / rest).resolve()
    if filename.startswith("file://"):
        filename = filename[len("file://") :]
    path = Path(filename)
    return path if path.is_absolute() else (urdf_path.parent / path).resolve()


def resolve_mesh_filename(
    filename: str, urdf_path: Path, link: str, package_dirs: Mapping[str, str]
) -> Path:
    """Resolve a mesh for MuJoCo or raise a :class:`ConversionError` that says how to fix it."""
    path = mesh_path(filename, urdf_path, package_dirs)
    if path is None:
        package = filename[len("package://") :].split("/", 1)[0]
        raise ConversionError(
            f"{urdf_path}: link {link!r}: mesh {filename!r} names package {package!r}, which was "
            f"not found above {urdf_path.parent}; pass package_dirs={{'{package}': '/path'}} "
            f"(CLI: --package {package}=/path)"
        )
    if not path.is_file():
        raise ConversionError(f"{urdf_path}: link {link!r}: mesh file {path} does not exist")
    if path.suffix.lower() not in MUJOCO_MESH_FORMATS:
        raise ConversionError(
            f"{urdf_path}: link {link!r}: mesh {path.name} is {path.suffix} which MuJoCo cannot "
            f"read; convert it to .stl or .obj (for example with trimesh or meshlab)"
        )
    return path
