"""Three-layer URDF validation: XML and tree, engine compatibility, physics and native loads.

Layer 1 reads the XML leniently and checks the kinematic tree. Layer 2 checks what MuJoCo (through
:mod:`mjx_arm.urdf.convert`) and PyBullet need: joint limits, damping, readable meshes and collision
shapes MJX can collide. Layer 3 checks masses and inertia tensors, then loads the file into the
engines' own loaders (skipped when an earlier check already found an error: PyBullet crashes on
some broken trees, for example a URDF with two root links).

Every problem becomes a :class:`Finding` that names the file, the element, what is wrong and how to
fix it; nothing raises on bad input. ``mjx-arm validate`` prints the report; envs call
:func:`validated`, which caches the result per file version.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import math
import os
import re
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjx_arm.urdf.errors import UrdfError, one_line
from mjx_arm.urdf.inertia import inertia_problem, inertia_tensor
from mjx_arm.urdf.meshes import (
    MUJOCO_MESH_FORMATS,
    PYBULLET_MESH_FORMATS,
    AssetPathError,
    is_file,
    resolve_asset,
)
from mjx_arm.urdf.model import rpy_to_matrix
from mjx_arm.urdf.safe_xml import XmlError, read_xml

ENGINES: dict[str, tuple[str, ...]] = {
    "mujoco": ("mujoco",),
    "pybullet": ("pybullet",),
    "all": ("mujoco", "pybullet"),
}
JOINT_TYPES = frozenset({"revolute", "continuous", "prismatic", "fixed", "floating", "planar"})
MOVABLE_TYPES = frozenset({"revolute", "continuous", "prismatic"})
LIMITED_TYPES = frozenset({"revolute", "prismatic"})
SHAPES = frozenset({"box", "sphere", "cylinder", "capsule", "mesh"})
# A collision shape whose bounding box diagonal differs from the visual's by more than this
# factor (either way) is reported.
SIZE_RATIO_LIMIT = 2.0
_AXIS_EPS = 1e-9
# Links (and joints) a URDF may have: far above any arm, low enough to keep every check and
# native load well under a second.
MAX_LINKS = 512
# Largest ratio of two sizes of one primitive shape that survives MuJoCo's MJCF writer.
MAX_SIZE_RATIO = 1e5
# Largest origin offset (m): a robot is metres across; beyond this, float rounding eats its shapes.
MAX_OFFSET = 1e4

# --------------------------------------------------------------------------- report types


@dataclass(frozen=True)
class Finding:
    """One problem in a URDF.

    Attributes:
        severity: "error" (the file cannot be used) or "warning" (it can, with a caveat).
        layer: 1 XML and tree, 2 engine compatibility, 3 physics and native loading.
        file: the URDF path.
        element: the offending element, e.g. ``joint 'elbow_joint'``, ``link 'tool_link'``.
        problem: what is wrong.
        fix: how to fix it.
    """

    severity: str
    layer: int
    file: str
    element: str
    problem: str
    fix: str

    def __str__(self) -> str:
        problem, fix = self.problem.rstrip(". "), self.fix.rstrip(". ")
        head = f"{self.severity.upper()} [{self.layer}] {self.file}: {self.element}"
        return f"{head}: {problem}. Fix: {fix}"


@dataclass(frozen=True)
class ValidationReport:
    """Everything :func:`validate` found in one URDF for one engine choice."""

    path: str
    engine: str
    findings: tuple[Finding, ...] = ()

    @property
    def errors(self) -> tuple[Finding, ...]:
        """Findings that make the file unusable."""
        return tuple(f for f in self.findings if f.severity == "error")

    @property
    def warnings(self) -> tuple[Finding, ...]:
        """Findings that leave the file usable."""
        return tuple(f for f in self.findings if f.severity == "warning")

    @property
    def ok(self) -> bool:
        """True when there is no error (warnings allowed)."""
        return not self.errors

    def format(self) -> str:
        """A header line, the errors, the warnings, and a verdict line."""
        lines = [f"Validating {self.path} (engine: {self.engine})"]
        lines += [str(f) for f in (*self.errors, *self.warnings)]
        n_err, n_warn = len(self.errors), len(self.warnings)
        if n_err:
            lines.append(f"INVALID: {n_err} errors, {n_warn} warnings")
        else:
            lines.append("valid" + (f" ({n_warn} warnings)" if n_warn else ""))
        return "\n".join(lines)


class _Findings:
    """Collects findings for one file."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.items: list[Finding] = []

    def error(self, layer: int, element: str, problem: str, fix: str) -> None:
        self._add("error", layer, element, problem, fix)

    def warning(self, layer: int, element: str, problem: str, fix: str) -> None:
        self._add("warning", layer, element, problem, fix)

    def _add(self, severity: str, layer: int, element: str, problem: str, fix: str) -> None:
        finding = Finding(severity, layer, self.file, element, problem, fix)
        if finding not in self.items:
            self.items.append(finding)

    @property
    def has_errors(self) -> bool:
        return any(f.severity == "error" for f in self.items)


# --------------------------------------------------------------------------- lenient tree


@dataclass
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    elem: ET.Element


@dataclass
class _Tree:
    """What layers 2 and 3 need from layer 1: elements by name and the joint graph."""

    path: Path
    root: ET.Element
    links: dict[str, ET.Element] = field(default_factory=dict)
    joints: dict[str, _Joint] = field(default_factory=dict)

    def child_joints(self, link: str) -> list[_Joint]:
        return [j for j in self.joints.values() if j.parent == link]

    def moving_links(self) -> dict[str, bool]:
        """Links below a non-fixed joint: name -> True when such a joint is its parent joint."""
        out: dict[str, bool] = {}
        for joint in self.joints.values():
            if joint.type != "fixed" and joint.child in self.links:
                out[joint.child] = True
        stack = list(out)
        while stack:
            for joint in self.child_joints(stack.pop()):
                if joint.child in self.links and joint.child not in out:
                    out[joint.child] = False
                    stack.append(joint.child)
        return out


def _link(name: str) -> str:
    return f"link {name!r}"


def _joint(name: str) -> str:
    return f"joint {name!r}"


def _numbers(text: str | None, n: int) -> tuple[float, ...] | None:
    """``n`` finite floats from a space-separated attribute, or None when malformed."""
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        return None
    if len(values) != n or not all(np.isfinite(values)):
        return None
    return values


def _fmt_values(values: list[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


def _number(elem: ET.Element | None, attr: str) -> float | str | None:
    """A float attribute: the value, None when absent, or the raw text when it is no number."""
    if elem is None or elem.get(attr) is None:
        return None
    raw = elem.get(attr, "")
    values = _numbers(raw, 1)
    return raw if values is None else values[0]


# --------------------------------------------------------------------------- layer 1


def _read_xml(path: Path, out: _Findings) -> ET.Element | None:
    """Parse the file safely (:mod:`mjx_arm.urdf.safe_xml`); any refusal becomes a finding."""
    try:
        return read_xml(path)
    except XmlError as exc:
        out.error(1, exc.element, exc.problem, exc.fix)
        return None


def _check_tree(path: Path, root: ET.Element, out: _Findings) -> _Tree | None:
    """Layer 1: the root element, names, the joint graph and the joint types."""
    if root.tag != "robot":
        out.error(
            1,
            f"root element <{root.tag}>",
            "is not <robot>",
            'a URDF\'s top element must be <robot name="...">',
        )
        return None
    if not root.get("name", "").strip():
        out.error(
            1,
            "robot",
            "has no name (PyBullet refuses the file)",
            'give the root element a name: <robot name="my_arm">',
        )
    if not _check_counts(root, out):
        return None
    tree = _Tree(path, root)
    _collect_links(tree, out)
    _collect_joints(tree, out)
    _check_parents(tree, out)
    _check_roots(tree, out)
    _check_cycles(tree, out)
    _check_joint_types(tree, out)
    _check_origins(tree, out)
    return tree


def _check_counts(root: ET.Element, out: _Findings) -> bool:
    """At most MAX_LINKS links and joints (the later checks and loaders scale with them)."""
    fine = True
    for tag in ("link", "joint"):
        n = len(root.findall(tag))
        if n > MAX_LINKS:
            out.error(
                1,
                "robot",
                f"has {n} <{tag}> elements, more than the {MAX_LINKS} this tool accepts",
                f"remove <{tag}> elements the robot does not need",
            )
            fine = False
    return fine


def _collect_links(tree: _Tree, out: _Findings) -> None:
    counts: dict[str, int] = {}
    for i, elem in enumerate(tree.root.findall("link")):
        name = elem.get("name", "").strip()
        if not name:
            out.error(1, f"link #{i + 1}", "has no name", "give every <link> a unique name")
            continue
        counts[name] = counts.get(name, 0) + 1
        tree.links.setdefault(name, elem)
    for name, n in counts.items():
        if n > 1:
            out.error(1, _link(name), f"is defined {n} times", "rename or remove the duplicates")
    if not counts:
        out.error(1, "robot", "has no <link>", "a URDF needs at least one named <link>")


def _collect_joints(tree: _Tree, out: _Findings) -> None:
    counts: dict[str, int] = {}
    for i, elem in enumerate(tree.root.findall("joint")):
        name = elem.get("name", "").strip()
        if not name:
            out.error(1, f"joint #{i + 1}", "has no name", "give every <joint> a unique name")
            continue
        counts[name] = counts.get(name, 0) + 1
        if name not in tree.joints:
            tree.joints[name] = _Joint(
                name, elem.get("type", ""), _ref(elem, "parent"), _ref(elem, "child"), elem
            )
    for name, n in counts.items():
        if n > 1:
            out.error(1, _joint(name), f"is defined {n} times", "rename or remove the duplicates")


def _ref(elem: ET.Element, tag: str) -> str:
    sub = elem.find(tag)
    return "" if sub is None else sub.get("link", "").strip()


def _check_parents(tree: _Tree, out: _Findings) -> None:
    """Every joint names an existing parent and child; no link has two parents."""
    parents: dict[str, list[str]] = {}
    for j in tree.joints.values():
        for role, link in (("parent", j.parent), ("child", j.child)):
            if not link:
                out.error(
                    1,
                    _joint(j.name),
                    f'has no <{role} link="...">',
                    f'add <{role} link="NAME"/> naming an existing link',
                )
            elif link not in tree.links:
                out.error(
                    1,
                    _joint(j.name),
                    f"names {role} link {link!r}, which does not exist",
                    f"add <link name={link!r}> or correct the <{role}> reference",
                )
        if j.parent and j.parent == j.child:
            out.error(
                1,
                _joint(j.name),
                f"joins link {j.child!r} to itself",
                "a joint connects two different links",
            )
        if j.child:
            parents.setdefault(j.child, []).append(j.name)
    for link, joints in parents.items():
        if len(joints) > 1 and link in tree.links:
            names = ", ".join(repr(n) for n in joints)
            problem = f"has {len(joints)} parents: it is the child of joints {names}"
            out.error(
                1,
                _link(link),
                problem,
                "a URDF is a tree: keep one parent joint per link (closed loops cannot be "
                "expressed in URDF)",
            )


def _check_roots(tree: _Tree, out: _Findings) -> None:
    children = {j.child for j in tree.joints.values()}
    roots = [name for name in tree.links if name not in children]
    if len(roots) > 1:
        names = ", ".join(repr(r) for r in roots)
        out.error(
            1,
            "robot",
            f"has {len(roots)} root links ({names}); a URDF has exactly one",
            "connect every extra root link to the tree with a joint, or remove it",
        )
    elif not roots and tree.links:
        out.error(
            1,
            "robot",
            "has no root link: every link is the child of some joint",
            "remove the joint that closes the loop back to the base link",
        )


def _check_cycles(tree: _Tree, out: _Findings) -> None:
    """Report each closed loop of joints once, at the joint that closes it."""
    for links, closing in _find_cycles(tree):
        if len(links) > 1:  # a joint from a link to itself is reported by _check_parents
            loop = " -> ".join([*links, links[0]])
            out.error(
                1,
                _joint(closing),
                f"closes a kinematic loop {loop}",
                "a URDF is a tree: remove or re-parent one joint of the loop",
            )


def _find_cycles(tree: _Tree) -> list[tuple[list[str], str]]:
    """Depth-first search of the joint graph: (links of each loop, the joint closing it)."""
    children: dict[str, list[_Joint]] = {}
    for j in tree.joints.values():
        if j.parent in tree.links and j.child in tree.links:
            children.setdefault(j.parent, []).append(j)
    state: dict[str, int] = {}  # 1 on the current path, 2 finished
    cycles: list[tuple[list[str], str]] = []
    for start in tree.links:
        if state.get(start):
            continue
        path, stack = [start], [iter(children.get(start, []))]
        state[start] = 1
        while stack:
            joint = next(stack[-1], None)
            if joint is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(joint.child) == 1:
                cycles.append((path[path.index(joint.child) :], joint.name))
            elif not state.get(joint.child):
                state[joint.child] = 1
                path.append(joint.child)
                stack.append(iter(children.get(joint.child, [])))
    return cycles


def _check_joint_types(tree: _Tree, out: _Findings) -> None:
    for j in tree.joints.values():
        if j.type not in JOINT_TYPES:
            out.error(
                1,
                _joint(j.name),
                f"has unknown type {j.type!r}",
                f"use one of {', '.join(sorted(JOINT_TYPES))}",
            )
        mimic = j.elem.find("mimic")
        if mimic is not None and mimic.get("joint") == j.name:
            out.error(
                1,
                _joint(j.name),
                "mimics itself",
                "name another joint in <mimic joint=...> or remove <mimic>",
            )
        elif mimic is not None and mimic.get("joint") not in tree.joints:
            target = mimic.get("joint")
            out.error(
                1,
                _joint(j.name),
                f"mimics joint {target!r}, which does not exist",
                "name an existing joint in <mimic joint=...> or remove <mimic>",
            )
    if tree.joints and not any(j.type in ("revolute", "continuous") for j in tree.joints.values()):
        out.error(1, "robot", "has no revolute joint", "an arm needs at least one revolute joint")
    elif not tree.joints:
        out.error(1, "robot", "has no joint", "an arm needs at least one revolute joint")


def _check_origins(tree: _Tree, out: _Findings) -> None:
    """Every <origin xyz rpy> of a link or joint holds three finite numbers; xyz within
    MAX_OFFSET metres (larger offsets lose the link's geometry to float rounding)."""
    owners = [(_link(n), e) for n, e in tree.links.items()]
    owners += [(_joint(n), j.elem) for n, j in tree.joints.items()]
    for element, elem in owners:
        for origin in elem.iter("origin"):
            for attr in ("xyz", "rpy"):
                text = origin.get(attr)
                values = _numbers(text, 3)
                if text is not None and values is None:
                    out.error(
                        1,
                        element,
                        f"has a malformed <origin {attr}={text!r}>",
                        f'give three numbers, e.g. {attr}="0 0 0"',
                    )
                elif attr == "xyz" and values and max(map(abs, values)) > MAX_OFFSET:
                    out.error(
                        1,
                        element,
                        f"has <origin xyz={text!r}>, more than {MAX_OFFSET:g} m from its frame",
                        "give the offset in metres",
                    )


# --------------------------------------------------------------------------- layer 2: joints


def _check_joints(
    tree: _Tree, engines: tuple[str, ...], min_damping: float, out: _Findings
) -> None:
    for j in tree.joints.values():
        if j.type in ("floating", "planar"):
            _check_free_joint(j, engines, out)
        if j.type not in MOVABLE_TYPES:
            continue
        _check_axis(j, out)
        if j.type in LIMITED_TYPES:
            _check_limit(j, out)
        elif "mujoco" in engines:
            _check_effort_velocity(j, j.elem.find("limit"), out, for_converter=True)
        _check_damping(j, engines, min_damping, out)


def _check_free_joint(j: _Joint, engines: tuple[str, ...], out: _Findings) -> None:
    """Floating and planar joints: MuJoCo rejects a free joint below the root; none is actuated."""
    fix = "use revolute, continuous, prismatic or fixed joints for an arm"
    if j.type == "floating" and "mujoco" in engines:
        out.error(
            2,
            _joint(j.name),
            "is floating: MuJoCo allows a free joint only on a body attached to the world",
            fix,
        )
    else:
        out.warning(2, _joint(j.name), f"is {j.type}: the converter gives it no actuator", fix)


def _check_axis(j: _Joint, out: _Findings) -> None:
    axis_elem = j.elem.find("axis")
    if axis_elem is None:
        return  # URDF default (1, 0, 0)
    axis = _numbers(axis_elem.get("xyz"), 3)
    if axis is None:
        out.error(
            2,
            _joint(j.name),
            f"has a malformed <axis xyz={axis_elem.get('xyz')!r}>",
            'give three numbers, e.g. xyz="0 0 1"',
        )
    elif float(np.linalg.norm(axis)) < _AXIS_EPS:
        out.error(
            2,
            _joint(j.name),
            "has a zero <axis> (MuJoCo refuses it: axis too small)",
            'give the unit vector of the joint axis, e.g. xyz="0 0 1"',
        )


def _check_limit(j: _Joint, out: _Findings) -> None:
    """Revolute and prismatic joints: <limit> with lower < upper, effort > 0, velocity > 0."""
    limit = j.elem.find("limit")
    if limit is None:
        out.error(
            2,
            _joint(j.name),
            f"is {j.type} but has no <limit> (MuJoCo silently makes it "
            "unlimited and has no velocity limit of its own)",
            "add <limit lower=... upper=... effort=... velocity=.../>",
        )
        return
    lower, upper = _number(limit, "lower"), _number(limit, "upper")
    if isinstance(lower, str) or isinstance(upper, str):
        out.error(
            2,
            _joint(j.name),
            f"has a non-numeric <limit> bound ({lower!r}, {upper!r})",
            "give numbers in rad (revolute) or m (prismatic)",
        )
    elif lower is None or upper is None:
        out.error(
            2,
            _joint(j.name),
            "has a <limit> without lower and upper (URDF reads them as 0)",
            "give both lower and upper, with lower < upper",
        )
    elif not lower < upper:
        out.error(
            2,
            _joint(j.name),
            f"has limit lower={lower:g} >= upper={upper:g}",
            "set lower < upper (swap them if they are reversed)",
        )
    _check_effort_velocity(j, limit, out, for_converter=False)


def _check_effort_velocity(
    j: _Joint, limit: ET.Element | None, out: _Findings, for_converter: bool
) -> None:
    why = " (the converter sizes the joint's velocity actuator from them)" if for_converter else ""
    if limit is None:
        out.error(
            2,
            _joint(j.name),
            f"has no <limit effort velocity>{why}",
            "add <limit effort=... velocity=.../> with positive values",
        )
        return
    for attr, unit in (("effort", "N m or N"), ("velocity", "rad/s or m/s")):
        value = _number(limit, attr)
        if value is None or isinstance(value, str) or value <= 0:
            shown = "missing" if value is None else f"{value}"
            out.error(
                2,
                _joint(j.name),
                f"has <limit {attr}> {shown}, not > 0{why}",
                f"set {attr} to the joint's positive maximum ({unit})",
            )


def _check_damping(j: _Joint, engines: tuple[str, ...], min_damping: float, out: _Findings) -> None:
    value = _number(j.elem.find("dynamics"), "damping")
    if isinstance(value, str) or (value is not None and value < 0):
        out.error(
            2,
            _joint(j.name),
            f"has invalid <dynamics damping={value!r}>",
            "give a damping >= 0 (N m s/rad or N s/m)",
        )
        return
    if not value:
        engines_text = []
        if "mujoco" in engines:
            engines_text.append("the converter injects its default damping for MuJoCo")
        if "pybullet" in engines:
            engines_text.append("PyBullet runs it undamped, which jitters")
        out.warning(
            2,
            _joint(j.name),
            "has no <dynamics damping>: " + "; ".join(engines_text),
            'add <dynamics damping="..."/> with the joint\'s real damping',
        )
    elif "pybullet" in engines and value < min_damping:
        out.warning(
            2,
            _joint(j.name),
            f"has damping {value:g} < {min_damping:g}: PyBullet jitters with so little damping",
            f"raise <dynamics damping> to at least {min_damping:g}",
        )


# --------------------------------------------------------------------------- layer 2: geometry


@dataclass(frozen=True)
class _Shape:
    """One visual or collision shape, checked; ``box`` is its local bounding box or None."""

    role: str
    kind: str
    box: np.ndarray | None


def _check_geometry(
    tree: _Tree, engines: tuple[str, ...], package_dirs: Mapping[str, str], out: _Findings
) -> None:
    for name, elem in tree.links.items():
        shapes = []
        for role in ("visual", "collision"):
            for item in elem.findall(role):
                shape = _check_shape(tree.path, name, role, item, engines, package_dirs, out)
                if shape is not None:
                    shapes.append(shape)
        _check_sizes(name, shapes, out)
    _check_textures(tree, package_dirs, out)


def _check_textures(tree: _Tree, package_dirs: Mapping[str, str], out: _Findings) -> None:
    """Every ``<texture filename>`` (PyBullet loads them) stays inside its folder."""
    owners = [(_link(n), e) for n, e in tree.links.items()]
    owners += [(f"material {m.get('name', '')!r}", m) for m in tree.root.findall("material")]
    for element, elem in owners:
        for texture in elem.iter("texture"):
            filename = texture.get("filename")
            if filename is None:
                continue
            try:
                resolve_asset(filename, tree.path, package_dirs)
            except AssetPathError as exc:
                out.error(2, element, f"has texture {filename!r}: it {exc.problem}", exc.fix)


def _check_shape(
    path: Path,
    link: str,
    role: str,
    item: ET.Element,
    engines: tuple[str, ...],
    package_dirs: Mapping[str, str],
    out: _Findings,
) -> _Shape | None:
    geometry = item.find("geometry")
    shapes = [] if geometry is None else list(geometry)
    if len(shapes) != 1 or shapes[0].tag not in SHAPES:
        found = ", ".join(f"<{s.tag}>" for s in shapes) or "nothing"
        out.error(
            2,
            _link(link),
            f"has a <{role}> whose <geometry> holds {found}",
            f"give exactly one of {', '.join(f'<{s}>' for s in sorted(SHAPES))}",
        )
        return None
    shape = shapes[0]
    if shape.tag == "mesh":
        box = _check_mesh(path, link, role, shape, engines, package_dirs, out)
    else:
        box = _primitive_box(link, role, shape, out)
    if role == "collision" and shape.tag == "cylinder" and "mujoco" in engines:
        out.warning(
            2,
            _link(link),
            "has a cylinder collision shape, which MJX does not collide "
            "with boxes, spheres or meshes",
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
    engines: tuple[str, ...],
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
    _check_mesh_format(link, role, filename, engines, out)
    resolved = _resolve_mesh(path, link, role, filename, package_dirs, out)
    scale = _numbers(shape.get("scale", "1 1 1"), 3)
    if scale is None:
        out.error(
            2,
            _link(link),
            f"has a <{role}> mesh with scale={shape.get('scale')!r}",
            'give three numbers, e.g. scale="0.001 0.001 0.001"',
        )
        return None
    if resolved is None:
        return None
    if resolved.suffix.lower() == ".stl" and _is_ascii_stl(str(resolved), *_stamp(resolved)):
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {filename!r}, an ASCII STL: MuJoCo and PyBullet read binary "
            "STL only",
            "save the mesh as binary STL (e.g. trimesh.load(path).export(path)) or as .obj",
        )
        return None
    if resolved.suffix.lower() not in _READ_FORMATS:  # only mesh files are ever opened
        return None
    box = _mesh_box(str(resolved), *_stamp(resolved))
    return None if box is None else np.sort(box * np.array(scale), axis=0)


def _check_mesh_format(
    link: str, role: str, filename: str, engines: tuple[str, ...], out: _Findings
) -> None:
    suffix = Path(filename).suffix.lower()
    readable = {"mujoco": MUJOCO_MESH_FORMATS, "pybullet": PYBULLET_MESH_FORMATS}
    blind = [e for e in engines if suffix not in readable[e]]
    if blind:
        who = " and ".join({"mujoco": "MuJoCo", "pybullet": "PyBullet"}[e] for e in blind)
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {filename!r} in format "
            f"{suffix or '(none)'}, which {who} cannot read",
            "convert the mesh to .stl or .obj (for example with trimesh or meshlab) and "
            "point filename at it",
        )


def _resolve_mesh(
    path: Path, link: str, role: str, filename: str, package_dirs: Mapping[str, str], out: _Findings
) -> Path | None:
    try:
        resolved = resolve_asset(filename, path, package_dirs)
    except AssetPathError as exc:
        out.error(2, _link(link), f"has <{role}> mesh {filename!r}: it {exc.problem}", exc.fix)
        return None
    if not is_file(resolved):
        out.error(
            2,
            _link(link),
            f"has <{role}> mesh {filename!r}: file {resolved} does not exist",
            "correct the filename or add the mesh file",
        )
        return None
    return resolved


def _stamp(path: Path) -> tuple[int, int]:
    stat = path.stat()
    return stat.st_mtime_ns, stat.st_size


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


# --------------------------------------------------------------------------- mesh reading

_READ_FORMATS = frozenset({".stl", ".obj"})  # the formats whose bounding box is read
_STL_RECORD = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


@functools.lru_cache(maxsize=256)
def _is_ascii_stl(path: str, mtime_ns: int, size: int) -> bool:
    """True for a text STL (``solid ...`` and no consistent binary header)."""
    del mtime_ns
    try:
        with open(path, "rb") as f:
            head = f.read(84)
    except OSError:
        return False
    binary = len(head) == 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")
    return not binary and head.lstrip().startswith(b"solid")


@functools.lru_cache(maxsize=256)
def _mesh_box(path: str, mtime_ns: int, size: int) -> np.ndarray | None:
    """Bounding box ``(2, 3)`` of an STL or OBJ file's vertices, or None when unreadable.

    ``mtime_ns`` and ``size`` only key the cache.
    """
    del mtime_ns, size
    try:
        data = Path(path).read_bytes()
        suffix = Path(path).suffix.lower()
        vertices = _stl_vertices(data) if suffix == ".stl" else None
        vertices = _obj_vertices(data) if suffix == ".obj" else vertices
    except (OSError, ValueError):
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


# --------------------------------------------------------------------------- layer 3: physics


def _check_inertials(tree: _Tree, engines: tuple[str, ...], repair: bool, out: _Findings) -> None:
    """Masses and inertia tensors: every moving link has mass, every used tensor is physical."""
    moving = tree.moving_links()
    for name, elem in tree.links.items():
        inertial = elem.find("inertial")
        mass = _number(inertial.find("mass") if inertial is not None else None, "value")
        if isinstance(mass, str):
            out.error(3, _link(name), f"has a non-numeric mass {mass!r}", "give the mass in kg")
            continue
        if mass is not None and mass < 0:
            out.error(3, _link(name), f"has negative mass {mass:g}", "give the mass in kg, > 0")
            continue
        if name in moving:
            _check_moving_mass(name, elem, mass or 0.0, moving[name], out)
        if inertial is None:
            continue
        # The converter checks every <inertia>; PyBullet uses those of massive or moving links.
        if (mass or 0.0) > 0 or name in moving or "mujoco" in engines:
            _check_tensor(name, inertial, engines, repair, needed=(mass or 0.0) > 0, out=out)


def _check_moving_mass(
    name: str, elem: ET.Element, mass: float, direct: bool, out: _Findings
) -> None:
    """A moving link needs mass; a massless frame without collision geometry is allowed."""
    if mass > 0 or not (direct or elem.find("collision") is not None):
        return
    how = "is moved by a non-fixed joint" if direct else "moves and has collision geometry"
    if elem.find("inertial") is None:
        what = "has no <inertial> (PyBullet then invents 1 kg and unit inertia)"
    else:
        what = "has mass 0"
    out.error(
        3,
        _link(name),
        f"{how} but {what}",
        "add <inertial> with the link's mass (kg > 0), centre of mass and inertia tensor",
    )


def _check_tensor(
    name: str,
    inertial: ET.Element,
    engines: tuple[str, ...],
    repair: bool,
    needed: bool,
    out: _Findings,
) -> None:
    inertia = inertial.find("inertia")
    if inertia is None:
        if needed:
            out.error(
                3,
                _link(name),
                "has a mass but no <inertia>",
                "add <inertia ixx iyy izz ixy ixz iyz> about the centre of mass (kg m^2)",
            )
        return
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    values = {k: _number(inertia, k) for k in keys}
    bad = [k for k, v in values.items() if isinstance(v, str)]
    if bad:
        out.error(3, _link(name), f"has non-numeric inertia {', '.join(bad)}", "give numbers")
        return
    v = {k: float(values[k] or 0.0) for k in keys}  # type: ignore[arg-type]
    tensor = inertia_tensor(v)
    problem = inertia_problem(tensor)
    if problem is None:
        return
    if repair and engines == ("mujoco",):
        out.warning(
            3,
            _link(name),
            f"inertia {problem}; the converter will repair it",
            "correct the <inertia> values to keep the link's real dynamics",
        )
    else:
        note = "; PyBullet loads it as written and zeroes it" if "pybullet" in engines else ""
        out.error(
            3,
            _link(name),
            f"inertia {problem}{note}",
            "correct the <inertia> values (for MuJoCo alone, convert with repair_inertia="
            "True / --repair-inertia to use the nearest valid tensor)",
        )


# --------------------------------------------------------------------------- layer 3: native


def _native_element(tree: _Tree, text: str) -> str:
    """The link or joint an engine's message names, else ``robot``."""
    named = re.search(r"(link|joint) '([^']+)'", text)
    if named:
        return f"{named.group(1)} {named.group(2)!r}"
    element = re.search(r"Element name '([^']+)'", text)
    candidates = [element.group(1)] if element else []
    candidates += re.findall(r"[\w.-]+", text)
    for word in candidates:
        if word in tree.joints:
            return _joint(word)
        if word in tree.links:
            return _link(word)
        link = _link_of_mesh(tree, word)
        if link:
            return _link(link)
    return "robot"


def _link_of_mesh(tree: _Tree, stem: str) -> str | None:
    for name, elem in tree.links.items():
        for mesh in elem.iter("mesh"):
            filename = Path(mesh.get("filename", ""))
            if stem in (filename.stem, filename.name):
                return name
    return None


def _load_mujoco(
    tree: _Tree, package_dirs: Mapping[str, str], repair: bool, out: _Findings
) -> None:
    """Convert with :func:`mjx_arm.urdf.convert.build_checked_spec`, compile and write the MJCF
    (:func:`~mjx_arm.urdf.convert.mjcf_text`); report any failure.

    MuJoCo's own warnings (e.g. an OBJ's texture coordinates discarded) are dropped: they concern
    rendering, and MuJoCo's asset cache prints them only on the first load in a process, which
    would make the report depend on what ran before.
    """
    from mjx_arm.urdf.convert import ConvertConfig, build_checked_spec, mjcf_text

    config = ConvertConfig(package_dirs=dict(package_dirs), repair_inertia=repair)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            mjcf_text(build_checked_spec(tree.path, config), tree.path)
        except Exception as exc:
            text = one_line(exc)
            out.error(
                3,
                _native_element(tree, text),
                f"MuJoCo cannot load the model: {text}",
                "correct the element MuJoCo names (see the message)",
            )


@contextlib.contextmanager
def _captured_fds() -> Iterator[list[str]]:
    """Send C-level stdout and stderr to a temporary file; the yielded list gets the text.

    This swaps the process's file descriptors 1 and 2, so it is not safe to use from two threads
    at once.
    """
    captured: list[str] = []
    _flush_all()
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(1), os.dup(2)
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            yield captured
        finally:
            _flush_all()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            tmp.seek(0)
            captured.append(tmp.read().decode("utf-8", errors="replace"))


def _flush_all() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


def _absolute_mesh_copy(tree: _Tree, package_dirs: Mapping[str, str], folder: str) -> Path:
    """Write the URDF with absolute mesh and texture paths (PyBullet knows no package_dirs).

    A filename that does not resolve inside its folder loses its ``filename`` (PyBullet then
    opens nothing for it); the static checks report such meshes and textures before this runs.
    """
    root = ET.fromstring(ET.tostring(tree.root))
    for elem in [*root.iter("mesh"), *root.iter("texture")]:
        filename = elem.get("filename")
        if filename is None:
            continue
        try:
            elem.set("filename", str(resolve_asset(filename, tree.path, package_dirs)))
        except AssetPathError:
            del elem.attrib["filename"]
    copy = Path(folder) / tree.path.name
    copy.write_bytes(ET.tostring(root, encoding="utf-8"))
    return copy


def _load_pybullet(tree: _Tree, package_dirs: Mapping[str, str], out: _Findings) -> None:
    """Load into a private DIRECT PyBullet client with its C output captured; report problems.

    PyBullet runs in this process (it segfaults on some broken trees, which is why this layer only
    runs after the static checks passed). Its ``b3Warning`` messages become warnings.
    """
    with tempfile.TemporaryDirectory() as folder:
        copy = _absolute_mesh_copy(tree, package_dirs, folder)
        failure = None
        with _captured_fds() as captured:
            failure = _pybullet_load_file(str(copy))
        text = captured[0].replace(str(copy), str(tree.path)).replace(folder, str(tree.path.parent))
    messages = _attach_names(_bullet_messages(text), tree)
    if failure is not None:
        detail = one_line(" ".join([failure, *messages]))
        out.error(
            3,
            _native_element(tree, detail),
            f"PyBullet cannot load the file: {detail}",
            "correct the element PyBullet names (see the message)",
        )
        return
    for message in messages:
        out.warning(
            3,
            _native_element(tree, message),
            f"PyBullet warns: {message}",
            "check the element PyBullet names",
        )


def _pybullet_load_file(path: str) -> str | None:
    """Load ``path`` in a fresh DIRECT client (always disconnected); return error text or None."""
    client = None
    try:
        import pybullet
        from pybullet_utils import bullet_client

        client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        client.loadURDF(path, flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        return None
    except Exception as exc:
        return str(exc) or type(exc).__name__
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                client.disconnect()


def _bullet_messages(text: str) -> list[str]:
    """The b3Warning / b3Error messages of PyBullet's output, deduplicated, in order."""
    parts = re.findall(
        r"b3(?:Warning|Error)\[[^\]]*\]:\s*(.*?)(?=b3\w+\[|pybullet build time|"
        r"argv\[0\]|\Z)",
        text,
        flags=re.DOTALL,
    )
    messages: list[str] = []
    for part in parts:
        message = " ".join(part.split())
        if message and message not in messages:
            messages.append(message)
    return messages


def _attach_names(messages: list[str], tree: _Tree) -> list[str]:
    """PyBullet prints some link names as a message of their own: join them to the one before."""
    out: list[str] = []
    for message in messages:
        if out and (message in tree.links or message in tree.joints):
            out[-1] = f"{out[-1]}: {message!r}"
        else:
            out.append(message)
    return out


# --------------------------------------------------------------------------- entry points


def validate(
    path: str | Path,
    engine: str = "all",
    package_dirs: Mapping[str, str] | None = None,
    native: bool = True,
    repair_inertia: bool = False,
    min_damping_pybullet: float = 0.01,
) -> ValidationReport:
    """Validate a URDF in three layers and return every finding; never raises on bad input.

    Args:
        path: the URDF file.
        engine: "mujoco", "pybullet" or "all": the engine(s) the file must work in.
        package_dirs: ``package://NAME`` -> directory, for meshes outside the URDF's folder tree.
        native: run the engines' own loaders (layer 3) when the static checks find no error.
        repair_inertia: report invalid inertia tensors as warnings, since the converter repairs
            them (MuJoCo only; PyBullet loads the file as written).
        min_damping_pybullet: joint damping below which PyBullet is expected to jitter.

    Raises:
        ValueError: ``engine`` is not one of the three names.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {sorted(ENGINES)}, got {engine!r}")
    engines, dirs = ENGINES[engine], dict(package_dirs or {})
    out = _Findings(str(path))
    tree = _guarded(out, 1, lambda: _layer1(Path(path), out))
    if tree is not None:
        _guarded(out, 2, lambda: _check_joints(tree, engines, min_damping_pybullet, out))
        _guarded(out, 2, lambda: _check_geometry(tree, engines, dirs, out))
        _guarded(out, 3, lambda: _check_inertials(tree, engines, repair_inertia, out))
        if native and not out.has_errors:
            _native(tree, engines, dirs, repair_inertia, out)
    return ValidationReport(str(path), engine, tuple(out.items))


def _layer1(path: Path, out: _Findings) -> _Tree | None:
    resolved = path.expanduser().resolve()
    root = _read_xml(resolved, out)
    return None if root is None else _check_tree(resolved, root, out)


def _native(
    tree: _Tree, engines: tuple[str, ...], dirs: Mapping[str, str], repair: bool, out: _Findings
) -> None:
    if "mujoco" in engines:
        _guarded(out, 3, lambda: _load_mujoco(tree, dirs, repair, out))
    if "pybullet" in engines:
        _guarded(out, 3, lambda: _load_pybullet(tree, dirs, out))


def _guarded(out: _Findings, layer: int, check: Callable[[], _Tree | None]) -> _Tree | None:
    """Run one check; an unexpected exception becomes an error finding instead of a traceback."""
    try:
        return check()
    except Exception as exc:
        out.error(
            layer,
            "robot",
            f"the validator failed unexpectedly: {type(exc).__name__}: {one_line(exc)}",
            "report this as a bug in mjx_arm.urdf.validate",
        )
        return None


def require_valid(path: str | Path, engine: str = "all", **kw) -> ValidationReport:
    """Validate and return the report; raise :class:`UrdfError` with the report when not ok."""
    report = validate(path, engine=engine, **kw)
    if not report.ok:
        raise UrdfError(report.format())
    return report


def validated(
    path: str | Path, engine: str = "all", package_dirs: Mapping[str, str] | None = None
) -> ValidationReport:
    """:func:`require_valid`, cached per (resolved path, modification time, engine).

    Envs call this whenever they are constructed; a file is validated again only after it
    changes.

    Raises:
        UrdfError: the URDF has errors (not cached: every call validates again).
    """
    resolved = Path(path).expanduser().resolve()
    try:
        mtime = resolved.stat().st_mtime_ns
    except OSError:
        mtime = -1
    dirs = tuple(sorted((package_dirs or {}).items()))
    return _validated_cached(str(resolved), mtime, engine, dirs)


@functools.lru_cache(maxsize=64)
def _validated_cached(
    path: str, mtime_ns: int, engine: str, package_dirs: tuple[tuple[str, str], ...]
) -> ValidationReport:
    del mtime_ns  # part of the cache key only
    return require_valid(path, engine, package_dirs=dict(package_dirs))
