"""Collision meshes as MuJoCo sees them, for PyBullet: each convex hull eroded by Bullet's margin.

MuJoCo and Bullet both collide a mesh through its convex hull. Bullet's URDF importer then pads
every convex hull by a collision margin of 1 mm (``gUrdfDefaultCollisionMargin``; its
``changeDynamics(collisionMargin=)`` does not reach the hulls inside a link's compound shape).
Measured on the UR10 of example-robot-data: at the same joint angles MuJoCo put the wrist mesh
8 um above the Touch box and Bullet 0.89 mm into it, so PyBullet touched the box about a
millimetre early. A UR10 Touch policy trained in MuJoCo tapped the box without settling: 0.730
success over 200 episodes in PyBullet (rigid contacts), 0.990 with the shrunk hulls
(``benchmarks/results/contact/touch_before_hulls.md``, ``calibrate_touch.md``).

The fix is geometric: PyBullet loads a copy of the arm URDF whose collision meshes are their
convex hulls shrunk by the margin (every face plane moved inward by 1 mm, the planes
intersected again). Bullet's padding puts the faces back where MuJoCo has them; only edges and
corners come out rounded with a 1 mm radius. Visual meshes are untouched (their paths made
absolute). A URDF without collision meshes (the shipped arms: primitives only) is loaded as it
is, unless its arm config repairs it: the repairs go into the same copy (:mod:`mjx_arm.urdf.repair`
says why a copy). Copies live in :func:`mjx_arm.urdf.mesh_convert.default_cache_dir`, named by
a hash of the URDF's and the meshes' bytes, of the URDF's folder and of the repairs, so an
edited or moved file gets a fresh copy (the copy names its visual meshes by absolute path).
"""

from __future__ import annotations

import contextlib
import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.mesh_convert import default_cache_dir, load_mesh, read_mesh_bytes, write_atomic
from mjx_arm.urdf.meshes import existing_mesh, resolve_asset
from mjx_arm.urdf.repair import UrdfRepairs, repair_tree
from mjx_arm.urdf.safe_xml import read_xml

BULLET_URDF_MARGIN = 0.001  # m: the padding Bullet's URDF importer gives every convex mesh
_VERSION = b"eroded-hull-v1"  # part of the cache key: bump when the output changes
NO_REPAIRS = UrdfRepairs()


def eroded_hull(vertices: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of ``vertices`` with every face moved ``margin`` inward.

    Args:
        vertices: mesh vertices (m), ``(n, 3)``.
        margin: how far each face plane moves in (m).

    Returns:
        ``(vertices (k, 3), faces (f, 3))`` of the shrunk hull. A hull thinner than twice the
        margin somewhere cannot shrink that far: it is scaled about its centre instead, to
        half its size (a sliver that Bullet's padding rounds out either way).
    """
    from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

    hull = ConvexHull(np.asarray(vertices, np.float64))
    points = hull.points[hull.vertices]
    centre = points.mean(axis=0)
    planes = hull.equations.copy()  # rows (n, d): n . x + d <= 0 inside, |n| = 1
    depth = (-(planes[:, :3] @ centre + planes[:, 3])).min()  # centre to the nearest face
    if depth <= 1.5 * margin:
        shrunk = centre + 0.5 * (points - centre)
        return _hull_mesh(ConvexHull(shrunk))
    planes[:, 3] += margin
    try:
        corners = HalfspaceIntersection(planes, centre).intersections
    except QhullError:
        return _hull_mesh(hull)
    return _hull_mesh(ConvexHull(corners))


def _hull_mesh(hull) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and outward-wound triangles of a scipy ``ConvexHull``."""
    faces = hull.simplices.copy()
    centre = hull.points[hull.vertices].mean(axis=0)
    for i, (a, b, c) in enumerate(faces):
        p = hull.points
        if np.dot(np.cross(p[b] - p[a], p[c] - p[a]), p[a] - centre) < 0:
            faces[i] = (a, c, b)
    used, faces = np.unique(faces, return_inverse=True)
    return hull.points[used], faces.reshape(-1, 3)


def bullet_urdf(
    urdf: Path, cache_dir: Path | None = None, repairs: UrdfRepairs = NO_REPAIRS
) -> Path:
    """The URDF PyBullet should load for ``urdf``: itself when it has no collision meshes and
    ``repairs`` change nothing, else a cached copy with the repaired inertias and limits
    (:mod:`mjx_arm.urdf.repair`, the text MuJoCo's conversion reads) and eroded collision hulls
    (module docstring), named by a hash of the source's bytes and of the repairs.

    Raises:
        ConversionError: a mesh that cannot be found or read (the converter's message).
    """
    root = read_xml(urdf)
    repaired = repair_tree(root, repairs)
    collisions = root.findall("./link/collision/geometry/mesh")
    if not collisions and not repaired:
        return urdf
    sources = {  # collision meshes must resolve; the rest (drawing only) where they can
        id(mesh): existing_mesh(mesh.get("filename", ""), urdf, link.get("name", "?"), {})
        for link in root.findall("./link")
        for mesh in link.findall("./collision/geometry/mesh")
    }
    key = hashlib.sha256(_VERSION + urdf.read_bytes())
    # the copy names its visual meshes by absolute path: a URDF moved elsewhere gets its own
    key.update(str(urdf.resolve().parent).encode())
    if repaired:  # (an unrepaired copy keeps its name)
        key.update(repairs.key())
    for path in sorted({str(p) for p in sources.values()}):
        key.update(read_mesh_bytes(Path(path)))
    folder = (cache_dir or default_cache_dir()).expanduser().resolve()
    target = folder / f"{urdf.stem}_bullet_{key.hexdigest()[:16]}.urdf"
    if target.is_file():
        return target
    _absolute_paths(root, urdf)  # the copy lives elsewhere: its visuals keep their files
    try:
        for mesh in collisions:
            mesh.set("filename", str(_eroded_file(mesh, sources[id(mesh)], folder)))
            mesh.attrib.pop("scale", None)
        write_atomic(ET.tostring(root, encoding="unicode").encode(), target)
    except OSError as exc:
        raise ConversionError(
            f"{urdf}: PyBullet's copy (shrunk collision hulls, repairs) cannot be written to "
            f"{folder} ({exc}); set XDG_CACHE_HOME to a writable folder"
        ) from exc
    return target


def _absolute_paths(root: ET.Element, urdf: Path) -> None:
    """Point every ``filename`` (meshes, textures) that resolves at its absolute path."""
    for element in root.iter():
        filename = element.get("filename")
        if filename:
            with contextlib.suppress(ConversionError):
                element.set("filename", str(resolve_asset(filename, urdf, {})))


def _eroded_file(mesh: ET.Element, source: Path, folder: Path) -> Path:
    """Write the eroded hull of ``source`` (scaled by the element's ``scale``) as an OBJ."""
    scale = np.array([float(v) for v in (mesh.get("scale") or "1 1 1").split()], np.float64)
    tag = hashlib.sha256(_VERSION + read_mesh_bytes(source) + scale.tobytes()).hexdigest()[:16]
    target = folder / f"{source.stem}_hull_{tag}.obj"
    if not target.is_file():
        vertices, faces = eroded_hull(load_mesh(source).vertices * scale, BULLET_URDF_MARGIN)
        lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
        write_atomic(("\n".join(lines) + "\n").encode(), target)
    return target
