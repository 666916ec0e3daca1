"""The validator's vocabulary: findings and reports, the limits it checks against, and the lenient
parse tree every check reads.

Every limit on what a URDF may hold is here, each with the failure point it was measured
against (MuJoCo 3.x, PyBullet 3.2): the XML's size and shape, names, links, chain depth, line
length, and mesh paths, sizes and face counts.
"""

from __future__ import annotations

import dataclasses
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjx_arm.engines import engine_names
from mjx_arm.urdf.mesh_files import short_path


class _EngineChoices(Mapping[str, tuple[str, ...]]):
    """What ``validate(engine=...)`` takes, read from the registry (:mod:`mjx_arm.engines`)
    on every use: each engine whose row names a URDF reader, or "all" of them, mapped to the
    engine names checked."""

    def _now(self) -> dict[str, tuple[str, ...]]:
        names = engine_names("urdf_reader")
        return {**{name: (name,) for name in names}, "all": names}

    def __getitem__(self, key: str) -> tuple[str, ...]:
        return self._now()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._now())

    def __len__(self) -> int:
        return len(self._now())


ENGINES: Mapping[str, tuple[str, ...]] = _EngineChoices()
JOINT_TYPES = frozenset({"revolute", "continuous", "prismatic", "fixed", "floating", "planar"})
MOVABLE_TYPES = frozenset({"revolute", "continuous", "prismatic"})
LIMITED_TYPES = frozenset({"revolute", "prismatic"})
SHAPES = frozenset({"box", "sphere", "cylinder", "capsule", "mesh"})
# A collision shape whose bounding box diagonal differs from the visual's by more than this
# factor (either way) is reported.
SIZE_RATIO_LIMIT = 2.0
_AXIS_EPS = 1e-9
# Links (and joints) a URDF may have: far above any arm, low enough to keep every check and
# native load well under a second. PyBullet 3.2 loads a 5,000-joint chain without trouble.
MAX_LINKS = 512
# Links on the longest path from the root link (the depth of the kinematic chain). The MJCF
# nests one <body> per link, and MuJoCo's XML reader (MuJoCo 3.x, tinyxml2) refuses nesting
# deeper than 500 elements with "XML_ELEMENT_DEPTH_EXCEEDED: Element nesting is too deep".
# Measured on serial chains: MuJoCo's own URDF import written and read back works up to 497
# links and fails at 498; through this converter (mjx_arm.urdf.to_mjcf) 496 links convert and
# 497 fail. 256 is about half of that and far above any arm (a 6-DoF arm with a gripper is
# about 15 links deep).
MAX_CHAIN_LINKS = 256
# Bytes of one line of a URDF that PyBullet reads. PyBullet 3.2 reads a URDF in pieces of 8,191
# bytes and puts a line break between them, so a longer line is silently changed where it is
# cut: a joint name cut after 8,191 bytes of its line reads back as 'abcde\nfghij', and a cut
# inside a tag ends the load with XML_ERROR_PARSING_ATTRIBUTE. 8,000 is a round figure below
# that (a CRLF line ending counts one byte more).
MAX_LINE_BYTES = 8000
# Bytes of a mesh file's absolute path that PyBullet is given. PyBullet 3.2 crashes the process
# (SIGSEGV) loading a URDF whose mesh path has 1,032 or more bytes; 1,031 load (measured with the
# URDF in folders of 15 and 196 bytes: the same point). MuJoCo reads a mesh path of 3,915 bytes.
MAX_MESH_PATH_BYTES = 1000
# Triangles of one mesh file. MuJoCo's STL reader refuses a binary STL of more than 200,000
# faces ("number of faces should be between 1 and 200000"; 200,000 random faces load in 12 s
# on a 2-core CPU, mostly for the convex hull). Every format (OBJ, and the meshes trimesh
# converts) is held to the same count, and an OBJ to three vertices per face.
MAX_MESH_FACES = 200_000
MAX_MESH_VERTICES = 3 * MAX_MESH_FACES
# Bytes of one mesh file, checked before any reader opens it: a binary STL at MAX_MESH_FACES is
# 10,000,084 bytes; an OBJ of as many faces with 100,000 vertices, normals and texture
# coordinates, as trimesh writes it, is 19.8 MiB.
MAX_MESH_BYTES = 32 * 2**20
# Files a mesh names (mjx_arm.urdf.mesh_side_files): an OBJ's material libraries and their
# textures (PyBullet reads both), a glTF's buffers, a .zae archive's members. Each is read only
# when it is a regular file of at most MAX_MESH_BYTES, and all of one mesh's together (for a
# .zae: what its members unpack to, declared and actual) at most MAX_SIDE_BYTES.
MAX_SIDE_BYTES = MAX_MESH_BYTES
# Members of a .zae archive (a Collada file and its textures: a handful).
MAX_ZAE_MEMBERS = 256
# Pixels of a texture an OBJ's material library names. PyBullet decodes it when it loads the
# URDF, at about 6 bytes a pixel: a 187 KB PNG of 8,000 x 8,000 pixels took PyBullet's peak
# memory from 80 MB to 456 MB (PyBullet 3.2.7). 4096 x 4096 is the usual largest texture.
MAX_TEXTURE_PIXELS = 4096 * 4096
# Bytes of Collada geometry, counted once per instance of it in the scene: trimesh copies a
# geometry for every <instance_geometry>, also through nested <instance_node>s, so a 6 KB file
# that instances a box through 30 levels of two <instance_node>s each asks for 2**30 copies
# (1,024 copies took trimesh 0.8 s). A file that uses each geometry once is within it by its size.
MAX_INSTANCED_BYTES = MAX_MESH_BYTES
# Parts of one mesh file trimesh reads: a Collada file's geometries and their instances, a
# glTF's nodes, mesh primitives and accessors. trimesh takes about 0.8 ms a part (1,024 Collada
# instances: 0.8 s; 20,000 glTF nodes: 10 s and 190 MB; 200,000 nodes, a 3.5 MB file: 60 s and
# 1.1 GB). The most among the 262 Collada meshes of example-robot-data 6.0 is 269.
MAX_SCENE_PARTS = 4096
# Longest name (robot, link, joint, material, ...) a URDF may use. PyBullet 3.2 segfaults while
# loading a URDF whose joint name has 1,264 or more characters, or whose link name has 2,288
# or more (robot names crash from 42,184; material names up to 70,000 do not). 256 leaves a
# margin of about 5x below the lowest of these and is far above any real name.
MAX_NAME_CHARS = 256
# The XML itself (mjx_arm.urdf.safe_xml): a file above MAX_BYTES is not read; a tree deeper than
# MAX_DEPTH (Python's serialiser recurses per level), with more than MAX_ELEMENTS elements or an
# attribute longer than MAX_ATTRIBUTE_CHARS (a path's limit on Linux) is refused.
MAX_BYTES = 8 * 2**20
MAX_DEPTH = 64
MAX_ELEMENTS = 50_000
MAX_ATTRIBUTE_CHARS = 4096
# Largest ratio of two sizes of one primitive shape that survives MuJoCo's MJCF writer.
MAX_SIZE_RATIO = 1e5
# Largest origin offset (m): a robot is metres across; beyond this, float rounding eats its shapes.
MAX_OFFSET = 1e4
# Longest line of a finding (Finding.line): indented by two in a report, under 300 characters.
LINE_CHARS = 297

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
        return self.line(with_file=True)

    def line(self, with_file: bool = False) -> str:
        """``SEVERITY [layer] (file: )element: problem. Fix: fix`` on one line of at most
        :data:`LINE_CHARS` characters: a longer one has its paths shortened to their tails,
        then its element, fix and problem cut (each ending in ``...``)."""
        problem, fix = self.problem.rstrip(". "), self.fix.rstrip(". ")
        where = f"{short_path(self.file)}: {self.element}" if with_file else self.element
        text = f"{self.severity.upper()} [{self.layer}] {where}: {problem}. Fix: {fix}"
        if len(text) <= LINE_CHARS:
            return text
        problem, fix = _PATH.sub(_tail, problem), _cut(_PATH.sub(_tail, fix), 110)
        head = f"{self.severity.upper()} [{self.layer}] {_cut(where, 80)}: "
        tail = f". Fix: {fix}"
        return head + _cut(problem, LINE_CHARS - len(head) - len(tail)) + tail


def grouped_lines(findings: tuple[Finding, ...], shown: int = 3) -> list[str]:
    """A line per finding (:meth:`Finding.line`), but one line for findings that differ only
    in their element (the same problem and fix on seven joints): it names the first ``shown``
    elements and the count, e.g. ``joints 'a', 'b', 'c' and 4 more (7)``."""
    groups: dict[tuple, list[Finding]] = {}
    for f in findings:
        groups.setdefault((f.severity, f.layer, f.file, f.problem, f.fix), []).append(f)
    lines = []
    for group in groups.values():
        if len(group) == 1:
            lines.append(group[0].line())
            continue
        kinds = {f.element.partition(" ")[0] for f in group}
        names = [f.element.partition(" ")[2] if len(kinds) == 1 else f.element for f in group]
        more = f" and {len(names) - shown} more" if len(names) > shown else ""
        kind = f"{kinds.pop()}s " if len(kinds) == 1 else ""
        element = f"{kind}{', '.join(names[:shown])}{more} ({len(names)})"
        lines.append(dataclasses.replace(group[0], element=element).line())
    return lines


@dataclass(frozen=True)
class ValidationReport:
    """Everything :func:`mjx_arm.urdf.validate.validate` found in one URDF for one engine choice."""

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
        """A header line with the path, the errors, the warnings (indented, without the
        path), and a verdict line."""
        lines = [f"Validating {self.path} (engine: {self.engine})"]
        lines += ["  " + line for line in grouped_lines((*self.errors, *self.warnings))]
        n_err, n_warn = len(self.errors), len(self.warnings)
        if n_err:
            lines.append(f"INVALID: {plural(n_err, 'error')}, {plural(n_warn, 'warning')}")
        else:
            lines.append("valid" + (f" ({plural(n_warn, 'warning')})" if n_warn else ""))
        return "\n".join(lines)

    def summary(self, chars: int = 200, first: int = 2) -> str:
        """The errors on one line of about ``chars`` characters: their count and the first
        ``first`` of them (element and problem, sharing ``chars``, each cut to its share),
        e.g. ``3 errors (joint 'a': has no <limit>; link 'b': ...; and 1 more)``."""
        parts = [f"{f.element}: {f.problem.rstrip('. ')}" for f in self.errors]
        shown = parts[:first]
        share = max(chars // max(len(shown), 1) - 2, 20)
        listed = "; ".join(_cut(part, share) for part in shown)
        listed += f"; and {len(parts) - first} more" if len(parts) > first else ""
        return f"{plural(len(parts), 'error')} ({listed})" if parts else "no errors"


def plural(n: int, noun: str) -> str:
    """``1 error``, ``2 errors``."""
    return f"{n} {noun}" + ("" if n == 1 else "s")


# An absolute path of three or more folders, shortened to its tail on a long report line. It
# starts a word: the tail of a path shortened before (``.../meshes/x.dae``) is not cut again.
_PATH = re.compile(r"(?<![^\s'\"(\[=,])(?:/[^\s'\"/;:,()\[\]]+){3,}")


def _tail(match: re.Match) -> str:
    return short_path(match.group(0), 40)


def _cut(text: str, chars: int) -> str:
    """``text`` on one line, cut to at most ``chars`` characters (ending in ``...`` when cut)."""
    text = " ".join(text.split())
    return text if len(text) <= chars else text[: chars - 3].rstrip() + "..."


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


def name_list(names: list[str], first: int = 4) -> str:
    """Names quoted and joined by commas, the first ``first`` of them and a count of the rest:
    ``'a', 'b', 'c', 'd' and 5 more``."""
    shown = ", ".join(repr(n) for n in names[:first])
    return shown + (f" and {len(names) - first} more" if len(names) > first else "")


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
