"""A small, typed reading of a URDF: links, joints, inertials and geometry.

This is what the rest of the package needs from a URDF (kinematics, limits, the tool frame). It is
strict: it expects a URDF that already passed :func:`mjx_arm.urdf.validate`. The validator itself
reads the XML leniently so it can report every problem instead of stopping at the first.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjx_arm.urdf.inertia import inertia_tensor
from mjx_arm.urdf.safe_xml import parse_xml, read_xml


@dataclass(frozen=True)
class Origin:
    """A rigid transform given as ``xyz`` (m) and fixed-axis ``rpy`` (rad)."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """Return the 4x4 homogeneous transform, shape ``(4, 4)``."""
        t = np.eye(4)
        t[:3, :3] = rpy_to_matrix(self.rpy)
        t[:3, 3] = self.xyz
        return t


@dataclass(frozen=True)
class Geometry:
    """One visual or collision shape. ``kind`` is box, sphere, capsule, cylinder or mesh."""

    kind: str
    origin: Origin
    size: tuple[float, ...] = ()
    filename: str | None = None
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass origin and the inertia tensor (kg m^2), shape ``(3, 3)``."""

    mass: float
    origin: Origin
    inertia: np.ndarray


@dataclass(frozen=True)
class Link:
    """A URDF link."""

    name: str
    inertial: Inertial | None
    visuals: tuple[Geometry, ...] = ()
    collisions: tuple[Geometry, ...] = ()


@dataclass(frozen=True)
class Limit:
    """Joint limits: position range (rad or m), effort (N m or N) and velocity (rad/s or m/s)."""

    lower: float
    upper: float
    effort: float
    velocity: float


@dataclass(frozen=True)
class Joint:
    """A URDF joint. ``mimic`` names the joint a ``<mimic>`` joint copies, else None;
    ``mimic_multiplier`` and ``mimic_offset`` are its ``q = multiplier * q_leader + offset``."""

    name: str
    type: str
    parent: str
    child: str
    origin: Origin
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    limit: Limit | None = None
    damping: float | None = None
    friction: float | None = None
    mimic: str | None = None
    mimic_multiplier: float = 1.0
    mimic_offset: float = 0.0

    @property
    def movable(self) -> bool:
        """True for joints with a degree of freedom."""
        return self.type in ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class RobotModel:
    """A parsed URDF: ``links`` and ``joints`` by name, in file order."""

    name: str
    path: Path | None
    links: dict[str, Link] = field(default_factory=dict)
    joints: dict[str, Joint] = field(default_factory=dict)

    @property
    def root_link(self) -> str:
        """The one link that is no joint's child."""
        children = {j.child for j in self.joints.values()}
        roots = [name for name in self.links if name not in children]
        if len(roots) != 1:
            raise ValueError(f"expected one root link, found {roots}")
        return roots[0]

    @property
    def actuated_joints(self) -> list[Joint]:
        """Movable joints in kinematic order (depth first from the root)."""
        return [j for j in self.joints_in_tree_order() if j.movable]

    def joints_in_tree_order(self) -> list[Joint]:
        """All joints, parents before children, siblings in file order."""
        by_parent: dict[str, list[Joint]] = {}
        for j in self.joints.values():
            by_parent.setdefault(j.parent, []).append(j)
        return _depth_first(self.root_link, by_parent)

    def chain_to(self, link: str) -> list[Joint]:
        """Joints from the root down to ``link``, in order."""
        parent_joint = {j.child: j for j in self.joints.values()}
        chain: list[Joint] = []
        while link in parent_joint:
            j = parent_joint[link]
            chain.append(j)
            link = j.parent
        return chain[::-1]


def _depth_first(root: str, by_parent: dict[str, list[Joint]]) -> list[Joint]:
    """The joints below ``root`` in depth-first pre-order (each joint, then its subtree), with
    a stack rather than recursion, so a chain of any depth cannot exhaust Python's stack."""
    out: list[Joint] = []
    stack = list(reversed(by_parent.get(root, [])))
    seen: set[str] = set()
    while stack:
        j = stack.pop()
        if j.child in seen:  # a loop: each link is entered once
            continue
        seen.add(j.child)
        out.append(j)
        stack.extend(reversed(by_parent.get(j.child, [])))
    return out


def rpy_to_matrix(rpy: tuple[float, float, float]) -> np.ndarray:
    """Rotation of URDF fixed-axis roll, pitch, yaw: ``Rz(y) Ry(p) Rx(r)``, shape ``(3, 3)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _floats(text: str | None, n: int, default: float = 0.0) -> tuple[float, ...]:
    if text is None:
        return (default,) * n
    values = tuple(float(v) for v in text.split())
    if len(values) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return values


def _origin(elem: ET.Element | None) -> Origin:
    if elem is None:
        return Origin()
    return Origin(_floats(elem.get("xyz"), 3), _floats(elem.get("rpy"), 3))  # type: ignore[arg-type]


def _geometry(elem: ET.Element) -> Geometry | None:
    origin = _origin(elem.find("origin"))
    geom = elem.find("geometry")
    if geom is None or len(geom) == 0:
        return None
    shape = geom[0]
    kind = shape.tag
    if kind == "box":
        return Geometry(kind, origin, _floats(shape.get("size"), 3))
    if kind == "sphere":
        return Geometry(kind, origin, (float(shape.get("radius", "nan")),))
    if kind in ("cylinder", "capsule"):
        size = (float(shape.get("radius", "nan")), float(shape.get("length", "nan")))
        return Geometry(kind, origin, size)
    if kind == "mesh":
        scale = _floats(shape.get("scale"), 3, 1.0)
        return Geometry(kind, origin, (), shape.get("filename"), scale)  # type: ignore[arg-type]
    return Geometry(kind, origin)


def _inertial(elem: ET.Element | None) -> Inertial | None:
    if elem is None:
        return None
    mass_elem = elem.find("mass")
    mass = float(mass_elem.get("value", "0")) if mass_elem is not None else 0.0
    i = elem.find("inertia")
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: float(i.get(k, "0")) if i is not None else 0.0 for k in keys}
    tensor = inertia_tensor(v)
    return Inertial(mass, _origin(elem.find("origin")), tensor)


def _link(elem: ET.Element) -> Link:
    visuals = tuple(g for g in map(_geometry, elem.findall("visual")) if g is not None)
    collisions = tuple(g for g in map(_geometry, elem.findall("collision")) if g is not None)
    return Link(elem.get("name", ""), _inertial(elem.find("inertial")), visuals, collisions)


def _joint(elem: ET.Element) -> Joint:
    lim = elem.find("limit")
    limit = None
    if lim is not None:
        limit = Limit(
            float(lim.get("lower", "0")),
            float(lim.get("upper", "0")),
            float(lim.get("effort", "0")),
            float(lim.get("velocity", "0")),
        )
    dyn = elem.find("dynamics")
    damping = friction = None
    if dyn is not None:
        damping = float(dyn.get("damping")) if dyn.get("damping") is not None else None
        friction = float(dyn.get("friction")) if dyn.get("friction") is not None else None
    axis_elem = elem.find("axis")
    axis = _floats(axis_elem.get("xyz") if axis_elem is not None else "1 0 0", 3)
    parent, child = elem.find("parent"), elem.find("child")
    mimic = elem.find("mimic")
    return Joint(
        name=elem.get("name", ""),
        type=elem.get("type", ""),
        parent=parent.get("link", "") if parent is not None else "",
        child=child.get("link", "") if child is not None else "",
        origin=_origin(elem.find("origin")),
        axis=axis,  # type: ignore[arg-type]
        limit=limit,
        damping=damping,
        friction=friction,
        mimic=mimic.get("joint") if mimic is not None else None,
        mimic_multiplier=_number(mimic, "multiplier", 1.0),
        mimic_offset=_number(mimic, "offset", 0.0),
    )


def _number(elem: ET.Element | None, name: str, default: float) -> float:
    """Attribute ``name`` of ``elem`` as a float; ``default`` where it is absent or no number
    (the validator reports a malformed ``<mimic>``)."""
    try:
        return float(elem.get(name, default)) if elem is not None else default
    except ValueError:
        return default


def parse_urdf(source: str | Path) -> RobotModel:
    """Parse a URDF file path (or XML text starting with ``<``) into a :class:`RobotModel`.

    Raises:
        mjx_arm.urdf.safe_xml.XmlError: the XML is unsafe or not well-formed.
    """
    text = str(source)
    if text.lstrip().startswith("<"):
        root, path = parse_xml(text), None
    else:
        path = Path(source).resolve()
        root = read_xml(path)
    links = {link.name: link for link in map(_link, root.findall("link"))}
    joints = {joint.name: joint for joint in map(_joint, root.findall("joint"))}
    return RobotModel(root.get("name", "robot"), path, links, joints)
