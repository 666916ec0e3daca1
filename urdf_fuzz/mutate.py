"""Seeded mutations of valid URDFs: broken and hostile inputs for the validator and converter.

:func:`mutants` turns a few valid URDFs into a reproducible stream of broken ones, one mutation
kind after the other (:data:`KINDS`). Mutant ``i`` of a stream depends only on the seed, ``i``
and the base files, so any failure can be replayed alone with :func:`mutant`.

Tree mutations edit the parsed element tree and write it back (comments and the XML
declaration are dropped); byte mutations (truncation, bad encodings, entities, padding) edit the
file's bytes.

Example::

    bases = {"ur5e": Path("assets/ur5e.urdf").read_bytes()}
    for m in mutants(bases, count=100, seed=0):
        Path(f"/tmp/{m.name}.urdf").write_bytes(m.data)
"""

from __future__ import annotations

import copy
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

_Edit = Callable[[ET.Element, np.random.Generator], str]
_ByteEdit = Callable[[bytes, np.random.Generator], tuple[bytes, str]]

# Replacement texts of the number mutations.
NON_FINITE = ("nan", "NaN", "inf", "-inf", "+Infinity", "1e999", "9" * 400)
HUGE = ("1e308", "-1e308", "1.7976931348623157e308", "3.4e38", "-3.4e38", "1e100", "1e30")
# Filenames a hostile URDF may point at, outside its folder.
OUTSIDE_FILES = (
    "/etc/passwd",
    "file:///etc/passwd",
    "../../../../../../../../etc/passwd",
    "../../../../../../../../etc/hostname.stl",
    "file:///etc/ssl/openssl.cnf.obj",
    "package://etc/passwd",
    "package://../../../../../../etc/passwd.stl",
    "package://./../../../../../../etc/group.obj",
    "/proc/self/environ",
    "/dev/zero",
    "/dev/urandom.stl",
    "~/.ssh/id_rsa",
)
MISSING_FILES = ("meshes/missing.stl", "package://no_such_package/a.obj", "", " ", "nope.dae")


@dataclass(frozen=True)
class Mutant:
    """One mutated URDF.

    Attributes:
        kind: the mutation kind, one of :data:`KINDS`.
        base: name of the valid URDF it came from.
        index: position in the seeded stream.
        description: what was changed.
        data: the file's bytes.
    """

    kind: str
    base: str
    index: int
    description: str
    data: bytes

    @property
    def name(self) -> str:
        """A file stem naming the mutant, e.g. ``0042_huge_number_ur5e``."""
        return f"{self.index:04d}_{self.kind}_{self.base}"


# --------------------------------------------------------------------------- tree helpers


def _elements(root: ET.Element) -> list[ET.Element]:
    """Every element below the root, document order."""
    return list(root.iter())[1:]


def _parents(root: ET.Element) -> dict[int, ET.Element]:
    """Parent of each element, keyed by ``id(element)``."""
    return {id(child): parent for parent in root.iter() for child in parent}


def _pick(rng: np.random.Generator, items: list | tuple):
    return items[int(rng.integers(len(items)))]


def _label(elem: ET.Element) -> str:
    name = elem.get("name")
    return f"<{elem.tag}>" + (f" {name!r}" if name else "")


def _number_slots(root: ET.Element) -> list[tuple[ET.Element, str, list[str]]]:
    """(element, attribute, its space-separated numbers) for every numeric attribute."""
    slots = []
    for elem in root.iter():
        for attr, text in elem.attrib.items():
            parts = text.split()
            if parts and all(_is_number(p) for p in parts):
                slots.append((elem, attr, parts))
    return slots


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _set_number(root: ET.Element, rng: np.random.Generator, make: Callable[[str], str]) -> str:
    """Replace one number of one numeric attribute by ``make(old)``."""
    elem, attr, parts = _pick(rng, _number_slots(root))
    i = int(rng.integers(len(parts)))
    old, parts[i] = parts[i], make(parts[i])
    elem.set(attr, " ".join(parts))
    return f"{_label(elem)} {attr}: number {i} {old!r} -> {parts[i]!r}"


def _joints(root: ET.Element) -> list[ET.Element]:
    return root.findall("joint")


def _link_names(root: ET.Element) -> list[str]:
    return [link.get("name", "") for link in root.findall("link")]


def _mesh_holder(root: ET.Element, rng: np.random.Generator) -> ET.Element:
    """A ``<mesh>`` of the tree, or a new one in a new visual of a random link."""
    meshes = list(root.iter("mesh"))
    if meshes and rng.random() < 0.7:
        return _pick(rng, meshes)
    link = _pick(rng, root.findall("link"))
    visual = ET.SubElement(link, "visual")
    return ET.SubElement(ET.SubElement(visual, "geometry"), "mesh", filename="")


def _texture_holder(root: ET.Element, rng: np.random.Generator) -> ET.Element:
    """A new ``<texture>`` in a new material of a random link's visual."""
    link = _pick(rng, root.findall("link"))
    visual = ET.SubElement(link, "visual")
    ET.SubElement(ET.SubElement(visual, "geometry"), "sphere", radius="0.01")
    material = ET.SubElement(visual, "material", name=f"m{int(rng.integers(1000))}")
    return ET.SubElement(material, "texture", filename="")


# --------------------------------------------------------------------------- tree mutations


def delete_element(root: ET.Element, rng: np.random.Generator) -> str:
    """Remove one element (and what it holds)."""
    elem = _pick(rng, _elements(root))
    _parents(root)[id(elem)].remove(elem)
    return f"deleted {_label(elem)}"


def duplicate_element(root: ET.Element, rng: np.random.Generator) -> str:
    """Insert one to three copies of one element next to it."""
    elem = _pick(rng, _elements(root))
    parent = _parents(root)[id(elem)]
    copies = int(rng.integers(1, 4))
    at = list(parent).index(elem)
    for _ in range(copies):
        parent.insert(at, copy.deepcopy(elem))
    return f"duplicated {_label(elem)} x{copies}"


def nan_number(root: ET.Element, rng: np.random.Generator) -> str:
    """One number becomes NaN or infinite (also by overflow: ``1e999``)."""
    return _set_number(root, rng, lambda old: _pick(rng, NON_FINITE))


def negative_number(root: ET.Element, rng: np.random.Generator) -> str:
    """One number becomes negative (its negated magnitude, or -1)."""
    return _set_number(
        root, rng, lambda old: _pick(rng, (f"-{old.lstrip('+-')}", "-1", "-1e-9", "-0"))
    )


def zero_number(root: ET.Element, rng: np.random.Generator) -> str:
    """One number becomes zero (or a tiny denormal)."""
    return _set_number(root, rng, lambda old: _pick(rng, ("0", "0.0", "-0.0", "1e-320")))


def huge_number(root: ET.Element, rng: np.random.Generator) -> str:
    """One number becomes huge but finite."""
    return _set_number(root, rng, lambda old: _pick(rng, HUGE))


def broken_reference(root: ET.Element, rng: np.random.Generator) -> str:
    """A joint names a missing link, a mimic a missing joint, or a mesh a missing file."""
    choice = int(rng.integers(4))
    if choice < 2:
        role = ("parent", "child")[choice]
        joint = _pick(rng, _joints(root))
        ref = joint.find(role)
        if ref is None:
            ref = ET.SubElement(joint, role)
        ref.set("link", _pick(rng, ("ghost_link", "", " ", joint.get("name", "x"))))
        return f"{_label(joint)} <{role} link={ref.get('link')!r}>"
    if choice == 2:
        joint = _pick(rng, _joints(root))
        ET.SubElement(joint, "mimic", joint=_pick(rng, ("ghost_joint", "", joint.get("name", ""))))
        return f"{_label(joint)} mimics a missing or its own joint"
    mesh = _mesh_holder(root, rng)
    mesh.set("filename", _pick(rng, MISSING_FILES))
    return f"mesh filename {mesh.get('filename')!r}"


def outside_reference(root: ET.Element, rng: np.random.Generator) -> str:
    """A mesh or texture points outside the URDF's folder (system files, devices, home)."""
    holder = _mesh_holder(root, rng) if rng.random() < 0.7 else _texture_holder(root, rng)
    holder.set("filename", _pick(rng, OUTSIDE_FILES))
    return f"<{holder.tag}> filename {holder.get('filename')!r}"


def cycle(root: ET.Element, rng: np.random.Generator) -> str:
    """Close a kinematic loop: a joint's parent becomes one of its descendants (or its child)."""
    joints = _joints(root)
    joint = _pick(rng, joints)
    child = joint.find("child")
    parent = joint.find("parent")
    if child is None or parent is None:
        return delete_element(root, rng)
    below = _descendants(joints, child.get("link", ""))
    target = _pick(rng, sorted(below)) if below else child.get("link", "")
    parent.set("link", target)
    return f"{_label(joint)} re-parented to its descendant {target!r}"


def _descendants(joints: list[ET.Element], link: str) -> set[str]:
    """Links below ``link`` in the joint graph (``link`` included)."""
    children: dict[str, list[str]] = {}
    for j in joints:
        p, c = j.find("parent"), j.find("child")
        if p is not None and c is not None:
            children.setdefault(p.get("link", ""), []).append(c.get("link", ""))
    seen, stack = {link}, [link]
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in seen:
                seen.add(c)
                stack.append(c)
    return seen


def wrong_type(root: ET.Element, rng: np.random.Generator) -> str:
    """A value of the wrong type: a word for a number, a wrong count, a bad joint type, a tag."""
    choice = int(rng.integers(4))
    if choice == 0:
        joint = _pick(rng, _joints(root))
        joint.set("type", _pick(rng, ("hinge", "", "REVOLUTE", "1", "revolute ", "ball")))
        return f"{_label(joint)} type={joint.get('type')!r}"
    if choice == 1:
        elem, attr, _ = _pick(rng, _number_slots(root))
        elem.set(attr, _pick(rng, ("abc", "1 2", "1,2,3", "0x10", "", "1 2 3 4", "true")))
        return f"{_label(elem)} {attr}={elem.get(attr)!r}"
    if choice == 2:
        elem = _pick(rng, _elements(root))
        old, elem.tag = elem.tag, _pick(rng, ("link", "joint", "robot", "visual", "box", "x"))
        return f"<{old}> renamed <{elem.tag}>"
    elem = _pick(rng, _elements(root))
    elem.text = _pick(rng, ("1 2 3", "text", "<![CDATA[x]]>"))
    return f"{_label(elem)} got text {elem.text!r}"


TREE_KINDS: dict[str, _Edit] = {
    "delete_element": delete_element,
    "duplicate_element": duplicate_element,
    "nan_number": nan_number,
    "negative_number": negative_number,
    "zero_number": zero_number,
    "huge_number": huge_number,
    "broken_reference": broken_reference,
    "outside_reference": outside_reference,
    "cycle": cycle,
    "wrong_type": wrong_type,
}

# --------------------------------------------------------------------------- byte mutations


def truncated(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """Cut the file at a random byte."""
    at = int(rng.integers(len(data)))
    return data[:at], f"truncated at byte {at} of {len(data)}"


def non_utf8(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """Bytes that are not UTF-8, a lying or unknown encoding declaration, a BOM, NUL bytes."""
    body = data.split(b"?>", 1)[1] if data.startswith(b"<?xml") else data
    choice = int(rng.integers(5))
    if choice == 0:
        at = _attribute_position(body, rng)
        junk = bytes(rng.integers(0x80, 0x100, int(rng.integers(1, 5)), dtype=np.uint8))
        return body[:at] + junk + body[at:], f"bytes {junk!r} inside an attribute"
    if choice == 1:
        encoding = _pick(rng, ("utf-16", "ascii", "latin-1", "no-such-codec", "utf-32", "cp1252"))
        head = f'<?xml version="1.0" encoding="{encoding}"?>'.encode()
        return head + body.replace(b'name="', b'name="\xe9\xff', 1), f"declared {encoding}"
    if choice == 2:
        bom = _pick(rng, (b"\xff\xfe", b"\xfe\xff", b"\xef\xbb\xbf\xef\xbb\xbf"))
        return bom + body, f"byte order mark {bom!r}"
    if choice == 3:
        at = _attribute_position(body, rng)
        return body[:at] + b"\x00" + body[at:], "a NUL byte"
    return body.decode("utf-8").encode("utf-16-le"), "UTF-16 without a byte order mark"


def _attribute_position(body: bytes, rng: np.random.Generator) -> int:
    """Offset just inside a random attribute value (after its opening quote)."""
    starts = [m.end() for m in re.finditer(rb'="', body)]
    return _pick(rng, starts) if starts else len(body) // 2


def large_file(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """A very large file: padding, thousands of links, one huge attribute, many shapes."""
    choice = int(rng.integers(5))
    close = data.rindex(b"</robot>")
    if choice == 0:
        mib = int(_pick(rng, (2, 9)))
        pad = b"<!--" + b"x" * (mib * 2**20) + b"-->"
        return data[:close] + pad + data[close:], f"{mib} MiB comment"
    if choice == 1:
        n = int(_pick(rng, (300, 600, 20_000)))
        first = ET.fromstring(data).find("link")
        anchor = "" if first is None else first.get("name", "")
        return data[:close] + _chain(anchor, n) + data[close:], f"{n} extra links in a chain"
    if choice == 2:
        size = int(_pick(rng, (10**5, 10**6, 5 * 10**6)))
        return data.replace(b'name="', b'name="' + b"n" * size, 1), f"a {size}-character name"
    if choice == 3:
        n = int(_pick(rng, (1_000, 5_000, 40_000)))
        shapes = b'<visual><geometry><box size="0.01 0.01 0.01"/></geometry></visual>' * n
        first = data.index(b"<link") + data[data.index(b"<link") :].index(b">") + 1
        return data[:first] + shapes + data[first:], f"{n} visuals on the first link"
    return data.replace(b"<link", b"\n" * 2**20 + b"<link", 1), "1 MiB of blank lines"


def _chain(anchor: str, n: int) -> bytes:
    """``n`` massless links in a chain of fixed joints hung from link ``anchor``."""
    parts = []
    for i in range(n):
        parent = f"pad_{i - 1}" if i else anchor
        parts.append(
            f'<link name="pad_{i}"/><joint name="pad_j{i}" type="fixed">'
            f'<parent link="{parent}"/><child link="pad_{i}"/></joint>'.encode()
        )
    return b"".join(parts)


def entity_expansion(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """Internal entities: "billion laughs", quadratic blow-up, or one harmless-looking entity."""
    choice = int(rng.integers(3))
    if choice == 0:
        levels = [b'<!ENTITY e0 "lol">']
        levels += [f'<!ENTITY e{i} "{f"&e{i - 1};" * 10}">'.encode() for i in range(1, 10)]
        doctype, ref, what = b"".join(levels), b"&e9;", "billion laughs"
    elif choice == 1:
        doctype = b'<!ENTITY big "' + b"x" * 50_000 + b'">'
        ref, what = b"&big;" * 5_000, "quadratic blow-up"
    else:
        doctype, ref, what = b'<!ENTITY arm "arm">', b"&arm;", "one internal entity"
    return _with_doctype(data, b"[" + doctype + b"]", ref), what


def external_entity(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """External entities and DTDs: ``SYSTEM "file:///etc/passwd"`` and friends."""
    target = _pick(rng, ("file:///etc/passwd", "/etc/hostname", "http://127.0.0.1:1/x.dtd"))
    choice = int(rng.integers(4))
    if choice == 0:
        subset, ref = f'[<!ENTITY xxe SYSTEM "{target}">]'.encode(), b"&xxe;"
    elif choice == 1:
        subset, ref = f'[<!ENTITY % p SYSTEM "{target}"> %p;]'.encode(), b""
    elif choice == 2:
        subset, ref = f'SYSTEM "{target}"'.encode(), b""
    else:
        subset, ref = f'PUBLIC "-//x//y" "{target}"'.encode(), b""
    return _with_doctype(data, subset, ref), f"external reference {target!r} ({choice})"


def _with_doctype(data: bytes, subset: bytes, ref: bytes) -> bytes:
    """Put ``<!DOCTYPE robot ...>`` before the root and ``ref`` into the robot's name."""
    start = data.index(b"<robot")
    body = data[start:]
    if ref:
        body = body.replace(b'name="', b'name="' + ref, 1)
    return b"<!DOCTYPE robot " + subset + b">\n" + body


def deep_nesting(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """Nest elements many levels deep inside a link (as bytes: too deep to serialise a tree)."""
    depth = int(_pick(rng, (20, 60, 100, 1_000, 100_000)))
    tag = _pick(rng, (b"link", b"visual", b"geometry", b"x"))
    nest = (b"<" + tag + b">") * depth + (b"</" + tag + b">") * depth
    ends = [m.start() for m in re.finditer(rb"</link>", data)]
    at = _pick(rng, ends) if ends else data.rindex(b"</robot>")
    return data[:at] + nest + data[at:], f"{depth} nested <{tag.decode()}> elements"


BYTE_KINDS: dict[str, _ByteEdit] = {
    "deep_nesting": deep_nesting,
    "truncated": truncated,
    "non_utf8": non_utf8,
    "large_file": large_file,
    "entity_expansion": entity_expansion,
    "external_entity": external_entity,
}
KINDS: tuple[str, ...] = (*TREE_KINDS, *BYTE_KINDS)

# --------------------------------------------------------------------------- streams


def mutate(base: bytes, kind: str, rng: np.random.Generator) -> tuple[bytes, str]:
    """Apply one mutation of ``kind`` to the URDF ``base``; return (bytes, description).

    Raises:
        ValueError: an unknown kind.
    """
    if kind in BYTE_KINDS:
        return BYTE_KINDS[kind](base, rng)
    if kind not in TREE_KINDS:
        raise ValueError(f"unknown mutation kind {kind!r}; choose one of {KINDS}")
    root = ET.fromstring(base)
    description = TREE_KINDS[kind](root, rng)
    return ET.tostring(root, encoding="utf-8"), description


def mutant(bases: Mapping[str, bytes], index: int, seed: int = 0) -> Mutant:
    """Mutant ``index`` of the stream of :func:`mutants` (the same bytes, computed alone)."""
    names = sorted(bases)
    kind = KINDS[index % len(KINDS)]
    base = names[(index // len(KINDS)) % len(names)]
    rng = np.random.default_rng([seed, index])
    data, description = mutate(bases[base], kind, rng)
    return Mutant(kind, base, index, description, data)


def mutants(bases: Mapping[str, bytes], count: int, seed: int = 0) -> Iterator[Mutant]:
    """``count`` mutants: the kinds in turn, each round on the next base (sorted by name).

    Args:
        bases: name -> bytes of a valid URDF.
        count: how many mutants.
        seed: the stream's seed; mutant ``i`` draws from ``default_rng([seed, i])``.
    """
    for index in range(count):
        yield mutant(bases, index, seed)
