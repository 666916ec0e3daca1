"""A gripper's fitted pads in PyBullet's copy of the URDF: the boxes and cut meshes MuJoCo gets.

Where a pad's collision is a mesh, :mod:`mjx_arm.urdf.pad_fit` fits a box to it (and, for a
one-jaw gripper's hand, cuts the fixed jaw off the hand's meshes); the converter puts those
shapes in the MuJoCo model (:func:`mjx_arm.urdf.collision_fit.fit_pads`). PyBullet loads a URDF,
so the same shapes go into a copy of the copy it loads (:func:`pybullet_ref.hulls.bullet_urdf`):
each fitted link's collision meshes are replaced by a ``<box>`` (Bullet keeps a box's faces
where the URDF puts them) and by the kept parts of cut meshes, written as their convex hulls
eroded by Bullet's 1 mm margin as every other collision mesh (:mod:`pybullet_ref.hulls`). Copies
are cached by a hash of the input copy and of the fitted shapes.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from mjx_arm.arm.facts import ArmInfo
from mjx_arm.urdf.mesh_convert import write_atomic
from mjx_arm.urdf.pad_fit import FittedPads, PadBox
from mjx_arm.urdf.repair import UrdfRepairs
from mjx_arm.urdf.safe_xml import read_xml
from pybullet_ref.hulls import BULLET_URDF_MARGIN, bullet_urdf, eroded_hull

_VERSION = b"fitted-pads-v1"  # part of the cache key: bump when the output changes


def bullet_arm_urdf(arm: ArmInfo) -> Path:
    """The URDF PyBullet loads for ``arm``: :func:`pybullet_ref.hulls.bullet_urdf` (eroded
    hulls, the config's repairs) with its gripper's fitted pads (:func:`pad_urdf`)."""
    urdf = bullet_urdf(arm.urdf, repairs=UrdfRepairs.of(arm.config))
    return urdf if arm.gripper is None else pad_urdf(urdf, arm.gripper.fitted)


def pad_urdf(urdf: Path, pads: FittedPads) -> Path:
    """The copy of ``urdf`` (PyBullet's copy, its paths absolute) with ``pads`` in place of its
    pad links' collision meshes (module doc), written next to it; ``urdf`` where no link is
    fitted."""
    if not pads.replaced:
        return urdf
    key = hashlib.sha256(_VERSION + Path(urdf).read_bytes())
    for box in pads.boxes:
        numbers = np.concatenate([box.centre, box.rotation.ravel(), box.half])
        key.update(box.link.encode() + numbers.tobytes())
    for link, vertices in pads.rests:
        key.update(link.encode() + np.asarray(vertices, float).tobytes())
    target = Path(urdf).parent / f"{Path(urdf).stem}_pads_{key.hexdigest()[:16]}.urdf"
    if target.is_file():
        return target
    root = read_xml(urdf)
    for link in root.findall("./link"):
        name = link.get("name", "")
        if name in pads.replaced:
            _replace(link, name, pads, target)
    write_atomic(ET.tostring(root, encoding="unicode").encode(), target)
    return target


def _replace(link: ET.Element, name: str, pads: FittedPads, target: Path) -> None:
    """Swap ``link``'s collision meshes for its fitted box and kept hulls."""
    for collision in link.findall("./collision"):
        if collision.find("./geometry/mesh") is not None:
            link.remove(collision)
    box = pads.box(name)
    if box is not None:
        link.append(_box_collision(box))
    rests = [vertices for link_name, vertices in pads.rests if link_name == name]
    for i, vertices in enumerate(rests):
        hull = target.parent / f"{target.stem}_{name}_rest{i}.obj"
        _write_hull(vertices, hull)
        collision = ET.SubElement(link, "collision")
        ET.SubElement(collision, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(ET.SubElement(collision, "geometry"), "mesh", filename=str(hull))


def _box_collision(box: PadBox) -> ET.Element:
    """A ``<collision>`` with ``box`` as a URDF ``<box>`` (full sizes, roll-pitch-yaw)."""
    collision = ET.Element("collision")
    xyz = " ".join(f"{v:.9g}" for v in box.centre)
    rpy = " ".join(f"{v:.9g}" for v in _rpy(box.rotation))
    ET.SubElement(collision, "origin", xyz=xyz, rpy=rpy)
    size = " ".join(f"{2.0 * v:.9g}" for v in box.half)
    ET.SubElement(ET.SubElement(collision, "geometry"), "box", size=size)
    return collision


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw (rad) of a rotation ``(3, 3)`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    pitch = float(np.arcsin(np.clip(-rotation[2, 0], -1.0, 1.0)))
    if abs(np.cos(pitch)) < 1e-9:  # gimbal lock: the yaw carries the whole turn about z
        return 0.0, pitch, float(np.arctan2(-rotation[0, 1], rotation[1, 1]))
    roll = float(np.arctan2(rotation[2, 1], rotation[2, 2]))
    return roll, pitch, float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def _write_hull(vertices: np.ndarray, path: Path) -> None:
    """The convex hull of ``vertices (n, 3)`` eroded by Bullet's margin, as an OBJ."""
    if path.is_file():
        return
    points, faces = eroded_hull(np.asarray(vertices, float), BULLET_URDF_MARGIN)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    write_atomic(("\n".join(lines) + "\n").encode(), path)
