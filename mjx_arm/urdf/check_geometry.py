"""Validation layer 2, geometry: shapes, sizes, origins and meshes each engine can read and
collide.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjx_arm.urdf.findings import (
    MAX_SIZE_RATIO,
    SHAPES,
    SIZE_RATIO_LIMIT,
    _Findings,
    _fmt_values,
    _link,
    _numbers,
    _Tree,
)
from mjx_arm.urdf.mesh_bbox import READ_FORMATS, is_ascii_stl, mesh_box
from mjx_arm.urdf.mesh_convert import (
    INSTALL_HINT,
    MeshConvertError,
    default_cache_dir,
    mesh_bounds,
    missing_packages,
)
from mjx_arm.urdf.mesh_files import short_path
from mjx_arm.urdf.mesh_limits import mesh_problem, path_problem
from mjx_arm.urdf.mesh_side_files import texture_problem
from mjx_arm.urdf.meshes import AssetPathError, is_file, not_regular, resolve_asset
from mjx_arm.urdf.model import rpy_to_matrix
from mjx_arm.urdf.readers import UrdfReader

# --------------------------------------------------------------------------- layer 2: geometry


@dataclass(frozen=True)
class _Shape:
    """One visual or collision shape, checked; ``box`` is its local bounding box or None."""

    role: str
    kind: str
    box: np.ndarray | None


def _check_geometry(
    tree: _Tree, readers: tuple[UrdfReader, ...], package_dirs: Mapping[str, str], out: _Findings
) -> None:
    """Every link's shapes, as each of ``readers`` reads them, and its textures."""
    for name, elem in tree.links.items():
        shapes = []
        for role in ("visual", "collision"):
            for item in elem.findall(role):
                shape = _check_shape(tree.path, name, role, item, readers, package_dirs, out)
                if shape is not None:
                    shapes.append(shape)
        _check_sizes(name, shapes, out)
    _check_textures(tree, package_dirs, out)


def _check_textures(tree: _Tree, package_dirs: Mapping[str, str], out: _Findings) -> None:
    """Every ``<texture filename>`` (PyBullet loads them) stays inside its folder and, where
    it is there, is an image safe to decode (:func:`texture_problem`)."""
    owners = [(_link(n), e) for n, e in tree.links.items()]
    owners += [(f"material {m.get('name', '')[:40]!r}", m) for m in tree.root.findall("material")]
    for element, elem in owners:
        for texture in elem.iter("texture"):
            filename = texture.get("filename")
            if filename is None:
                continue
            shown = short_path(filename)
            try:
                path = resolve_asset(filename, tree.path, package_dirs)
            except AssetPathError as exc:
                out.error(2, element, f"has texture {shown!r}: it {exc.problem}", exc.fix)
                continue
            problem = texture_problem(path) if path.exists() else None
            if problem is not None:
                out.error(
                    2, element, f"has texture {shown!r}, which {problem.problem}", problem.fix
                )


def _check_shape(
    path: Path,
    link: str,
    role: str,
    item: ET.Element,
    readers: tuple[UrdfReader, ...],
    package_dirs: Mapping[str, str],
    out: _Findings,
) -> _Shape | None:
    geometry = item.find("geometry")
    shapes = [] if geometry is None else list(geometry)
    if len(shapes) != 1 or shapes[0].tag not in SHAPES:
        found = ", ".join(f"<{s.tag[:32]}>" for s in shapes[:4]) or "nothing"
        found += f" and {len(shapes) - 4} more" if len(shapes) > 4 else ""
        out.error(
            2,
            _link(link),
            f"has a <{role}> whose <geometry> holds {found}",
            f"give exactly one of {', '.join(f'<{s}>' for s in sorted(SHAPES))}",
        )
        return None
    shape = shapes[0]
    if shape.tag == "mesh":
        box = _check_mesh(path, link, role, shape, readers, package_dirs, out)
    else:
        box = _primitive_box(link, role, shape, out)
    capsules = any(r.capsules_cylinders for r in readers)
    if role == "collision" and shape.tag == "cylinder" and capsules:
        out.warning(
            2,
            _link(link),
            "has a cylinder collision shape, which MJX does not collide "
            "with boxes, spheres or meshes: the converter makes it a capsule of the same radius "
            "and length (its ends round off, one radius longer)",
            "use a capsule (or a box) for collision",
        )
    if box is not None:
        box = _placed_box(box, item.find("origin"))
    return _Shape(role, shape.tag, box)


def _primitive_box(link: str, role: str, shape: ET.Element, out: _Findings) -> np.ndarray | None:
    """Local bounding box ``(2, 3)`` of a primitive, after checking its sizes are positive."""
    attrs = {"box": ("size",), "sphere": ("radius",)}.get(shape.tag, ("radius", "length"))
    sizes = []
    for attr in attrs:
        values = _numbers(shape.get(attr), 3 if attr == "size" else 1)
        if values is None or min(values) <= 0:
            out.error(
                2,
                _link(link),
                f"has a <{role}> <{shape.tag}> with {attr}={shape.get(attr)!r}",
                f"give {attr} as positive number(s) in m",
            )
            return None
        sizes.extend(values)
    if max(sizes) > MAX_SIZE_RATIO * min(sizes):
        out.error(
            2,
            _link(link),
            f"has a <{role}> <{shape.tag}> whose sizes {_fmt_values(sizes)} differ by more than "
            f"a factor {MAX_SIZE_RATIO:.0e} (MuJoCo writes about 6 significant digits per "
            "vector, so the small one would become 0)",
            "check the units of the sizes (m)",
        )
        return None
    if shape.tag == "box":
        half = np.array(sizes) / 2
    elif shape.tag == "sphere":
        half = np.full(3, sizes[0])
    else:
        radius, length = sizes
        cap = radius if shape.tag == "capsule" else 0.0
        half = np.array([radius, radius, length / 2 + cap])
    return np.stack([-half, half])


def _check_mesh(
    path: Path,
    link: str,
    role: str,
    shape: ET.Element,
    readers: tuple[UrdfReader, ...],
    package_dirs: Mapping[str, str],
    out: _Findings,
) -> np.ndarray | None:
    """Resolve a mesh, check its format; return its scaled local bounding box or None."""
    filename = shape.get("filename", "").strip()
    if not filename:
        out.error(
            2,
            _link(link),
            f"has a <{role}> <mesh> without filename",
            "set filename to the mesh file (relative to the URDF, or package://...)",
        )
        return None
    resolved = _resolve_mesh(path, link, role, filename, package_dirs, out)
    filename = short_path(filename)  # the name in messages: its tail
    convert = _check_mesh_format(link, role, filename, readers, out)
    scale = _numbers(shape.get("scale", "1 1 1"), 3)
    if scale is None:
        out.error(
            2,
            _link(link),
            f"has a <{role}> mesh with scale={shape.get('scale')!r}",
            'give three numbers, e.g. scale="0.001 0.001 0.001"',
        )
        return None
    if resolved is None or not _mesh_file_usable(link, role, filename, resolved, readers, out):
        return None
    if convert:
        box = _converted_box(link, filename, resolved, convert, out)
    else:
        box = _file_box(link, role, filename, resolved, out)
    return None if box is None else np.sort(box * np.array(scale), axis=0)


def _mesh_file_usable(
    link: str,
    role: str,
    filename: str,
    resolved: Path,
    readers: tuple[UrdfReader, ...],
    out: _Findings,
) -> bool:
    """Whether the mesh file at ``resolved`` can be loaded: its path is short enough for
    every reader with a ``max_mesh_path_bytes`` and the file is not too large; an error where
    not."""
    for reader in readers:
        limit = reader.max_mesh_path_bytes
        too_long = None if limit is None else path_problem(resolved, limit, reader.label)
        if too_long:
            out.error(
                2,
                _link(link),
                f"has <{role}> mesh {filename!r}, which {too_long}",
                "move the meshes to a folder with a shorter path",
            )
            return False
    problem = mesh_problem(resolved)
    if problem:
        text = f"has <{role}> mesh {filename!r}, which {problem.problem}"
        out.error(2, _link(link), text, problem.fix)
        return False
    return True


def _file_box(
    link: str, role: str, filename: str, resolved: Path, out: _Findings
) -> np.ndarray | None:
    """Bounding box ``(2, 3)`` of an STL or OBJ mesh file, None for other files; an ASCII STL
    is an error."""
    if resolved.suffix.lower() == ".stl" and is_ascii_stl(resolved):
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {filename!r}, an ASCII STL: MuJoCo and PyBullet read binary "
            "STL only",
            "save the mesh as binary STL (e.g. trimesh.load(path).export(path)) or as .obj",
        )
        return None
    if resolved.suffix.lower() not in READ_FORMATS:  # only mesh files are ever opened
        return None
    return mesh_box(resolved)


def _converted_box(
    link: str, filename: str, resolved: Path, who: str, out: _Findings
) -> np.ndarray | None:
    """Read a collision mesh the converter turns into STL with trimesh for the engines ``who``.

    Reports a warning that says where the STL goes, or an error when trimesh cannot read the
    file. Returns the mesh's bounding box ``(2, 3)`` (m, before ``<mesh scale>``) or None.
    """
    cannot = f"has <collision> mesh {filename!r} in format {Path(filename).suffix.lower()}, "
    cannot += f"which {who} cannot read"
    try:
        box = mesh_bounds(resolved)
    except MeshConvertError as exc:
        problem = f"{cannot}, and trimesh cannot convert it: {exc.problem}"
        out.error(2, _link(link), problem, exc.fix)
        return None
    out.warning(
        2,
        _link(link),
        f"{cannot}: converted to STL with trimesh, cached in {default_cache_dir()} "
        "(ConvertConfig.mesh_cache_dir sets another folder)",
        "nothing needed (to skip the conversion: save the mesh as binary .stl or .obj)",
    )
    return box


def _check_mesh_format(
    link: str, role: str, filename: str, readers: tuple[UrdfReader, ...], out: _Findings
) -> str:
    """Report a mesh format an engine cannot read.

    Returns:
        For a collision mesh a converter turns into STL (trimesh and the packages it needs
        are installed): the labels of the engines it is converted for, which
        :func:`_converted_box` reports once it is read; else "".
    """
    suffix = Path(filename).suffix.lower()
    blind = [r for r in readers if not r.reads(suffix)]
    for reader in [r for r in blind if role == "visual" and r.drops_unreadable_visuals]:
        out.warning(
            2,
            _link(link),
            f"has <visual> mesh {filename!r} in format {suffix[:16] or '(none)'}, which "
            f"{reader.label} cannot read: the converter leaves this visual out (it only draws)",
            f"convert the mesh to .stl or .obj to see it in {reader.label}'s renderer",
        )
        blind.remove(reader)
    converted = [r for r in blind if suffix in r.converts_formats]
    blind = [r for r in blind if r not in converted]
    who = _labels(converted)
    convert = bool(converted) and _converter_installed(link, filename, suffix, who, out)
    if blind:
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {filename!r} in format "
            f"{suffix[:16] or '(none)'}, which {_labels(blind)} cannot read",
            "convert the mesh to .stl or .obj (for example with trimesh or meshlab) and "
            "point filename at it",
        )
    return who if convert else ""


def _labels(readers: list[UrdfReader]) -> str:
    """The readers' labels joined with "and" ("MuJoCo and PyBullet")."""
    return " and ".join(r.label for r in readers)


def _converter_installed(link: str, filename: str, suffix: str, who: str, out: _Findings) -> bool:
    """True when trimesh (and pycollada for Collada) can be imported, else an error; ``who``
    names the engines that cannot read the mesh as it is."""
    missing = missing_packages(suffix)
    if missing:
        out.error(
            2,
            _link(link),
            f"has <collision> mesh {filename!r} in format {suffix}, which {who} cannot read, "
            f"and {' and '.join(missing)}, which the converter needs to convert it to STL, "
            f"{'is' if len(missing) == 1 else 'are'} not installed",
            f"{INSTALL_HINT}, or convert the mesh to .stl or .obj and point filename at it",
        )
    return not missing


def _resolve_mesh(
    path: Path, link: str, role: str, filename: str, package_dirs: Mapping[str, str], out: _Findings
) -> Path | None:
    shown = short_path(filename)
    try:
        resolved = resolve_asset(filename, path, package_dirs)
    except AssetPathError as exc:
        out.error(2, _link(link), f"has <{role}> mesh {shown!r}: it {exc.problem}", exc.fix)
        return None
    kind = not_regular(resolved)
    if kind:
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {shown!r}: {short_path(resolved)} is {kind}, not a regular file",
            "point filename at a regular mesh file (a FIFO, device or socket is never read)",
        )
        return None
    if not is_file(resolved):
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {shown!r}: file {short_path(resolved)} does not exist",
            "correct the filename or add the mesh file",
        )
        return None
    return resolved


def _placed_box(box: np.ndarray, origin: ET.Element | None) -> np.ndarray:
    """Axis-aligned box ``(2, 3)`` in the link frame of a local box placed at ``origin``."""
    xyz = _numbers(origin.get("xyz"), 3) if origin is not None else None
    rpy = _numbers(origin.get("rpy"), 3) if origin is not None else None
    corners = np.array(
        [[box[i, 0], box[j, 1], box[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    corners = corners @ rpy_to_matrix(rpy or (0.0, 0.0, 0.0)).T + np.array(xyz or (0.0, 0.0, 0.0))
    return np.stack([corners.min(axis=0), corners.max(axis=0)])


def _check_sizes(link: str, shapes: list[_Shape], out: _Findings) -> None:
    """Warn when a link's collision geometry is much larger or smaller than its visual."""
    sizes = {}
    for role in ("visual", "collision"):
        boxes = [s.box for s in shapes if s.role == role]
        if not boxes or any(b is None for b in boxes):
            return  # nothing to compare, or a shape whose extent is unknown
        low = np.min([b[0] for b in boxes], axis=0)
        high = np.max([b[1] for b in boxes], axis=0)
        sizes[role] = float(np.linalg.norm(high - low))
    if not all(math.isfinite(v) and v > 0 for v in sizes.values()):
        return  # a degenerate or overflowing extent: nothing sensible to compare
    ratio = sizes["collision"] / sizes["visual"]
    if ratio > SIZE_RATIO_LIMIT or ratio < 1 / SIZE_RATIO_LIMIT:
        word = "larger" if ratio > 1 else "smaller"
        out.warning(
            2,
            _link(link),
            f"has collision geometry {max(ratio, 1 / ratio):.1f}x {word} "
            f"than its visual (bounding box diagonals {sizes['collision']:.3g} m vs "
            f"{sizes['visual']:.3g} m)",
            "check the mesh units and <mesh scale> (mm vs m) and the collision mesh file",
        )
