"""Validation layer 1: the XML reads safely and describes one kinematic tree."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from mjx_arm.urdf.findings import (
    JOINT_TYPES,
    MAX_BYTES,
    MAX_CHAIN_LINKS,
    MAX_LINKS,
    MAX_NAME_CHARS,
    MAX_OFFSET,
    _Findings,
    _Joint,
    _joint,
    _link,
    _numbers,
    _Tree,
    name_list,
)
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular
from mjx_arm.urdf.safe_xml import XmlError, read_xml

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
    if not _check_counts(root, out) or not _check_name_lengths(root, out):
        return None
    tree = _Tree(path, root)
    _collect_links(tree, out)
    _collect_joints(tree, out)
    _check_parents(tree, out)
    _check_roots(tree, out)
    _check_cycles(tree, out)
    _check_depth(tree, out)
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


# Attributes that hold a name or refer to one, per element tag (None: any tag).
_NAME_ATTRS: tuple[tuple[str | None, str], ...] = (
    (None, "name"),
    ("parent", "link"),
    ("child", "link"),
    ("mimic", "joint"),
)


def _check_name_lengths(root: ET.Element, out: _Findings) -> bool:
    """No name (or reference to one) is longer than MAX_NAME_CHARS: PyBullet's loader crashes
    the process on long link and joint names, so they must be refused before it reads the file.
    Each long name is reported once, where it first occurs, showing its start only."""
    seen: set[str] = set()
    for elem in root.iter():
        for tag, attr in _NAME_ATTRS:
            value = elem.get(attr) if tag in (None, elem.tag) else None
            if value is not None and len(value) > MAX_NAME_CHARS and value not in seen:
                seen.add(value)
                out.error(
                    1,
                    f"<{elem.tag} {attr}={value[:32] + '...'!r}>",
                    f"has a {attr} of {len(value)} characters, more than the "
                    f"{MAX_NAME_CHARS} this tool accepts",
                    f"use a {attr} of at most {MAX_NAME_CHARS} characters",
                )
    return not seen


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
            problem = f"has {len(joints)} parents: it is the child of joints {name_list(joints)}"
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
        out.error(
            1,
            "robot",
            f"has {len(roots)} root links ({name_list(roots)}); a URDF has exactly one",
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
            shown = links if len(links) <= 6 else [*links[:4], f"... ({len(links)} links)"]
            loop = " -> ".join([*shown, links[0]])
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


def chain_depth(tree: _Tree) -> tuple[int, str]:
    """Links on the longest path down from a root link, and the last link of that path (a
    link reached twice, through a loop or a second parent, is counted once)."""
    children: dict[str, list[str]] = {}
    for j in tree.joints.values():
        if j.parent in tree.links and j.child in tree.links:
            children.setdefault(j.parent, []).append(j.child)
    has_parent = {j.child for j in tree.joints.values()}
    level = [name for name in tree.links if name not in has_parent]
    seen, depth, last = set(level), 0, ""
    while level:
        depth, last = depth + 1, level[0]
        level = [c for link in level for c in children.get(link, []) if c not in seen]
        seen.update(level)
    return depth, last


def _check_depth(tree: _Tree, out: _Findings) -> None:
    """At most MAX_CHAIN_LINKS links from the root to the deepest link: the MJCF nests one
    body per link, and MuJoCo's XML reader refuses deep nesting."""
    depth, last = chain_depth(tree)
    if depth > MAX_CHAIN_LINKS:
        out.error(
            1,
            _link(last),
            f"is {depth} links down from the root link, more than the {MAX_CHAIN_LINKS} this "
            "tool accepts (MuJoCo cannot read an MJCF nested that deep)",
            f"shorten the kinematic chain to at most {MAX_CHAIN_LINKS} links, e.g. by merging "
            "links joined by fixed joints",
        )


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


def _check_line_lengths(path: Path, limit: int, label: str, out: _Findings) -> None:
    """No line of the file is longer than ``limit`` bytes, the most the engine ``label`` reads
    whole (PyBullet cuts longer lines into pieces and silently changes names and values where
    it cuts: :data:`~mjx_arm.urdf.findings.MAX_LINE_BYTES`)."""
    try:
        lines = read_regular(path, MAX_BYTES, "URDF").split(b"\n")
    except (OSError, UnsafeFileError):
        return  # layer 1 already reported an unreadable file
    long = [(i + 1, len(line)) for i, line in enumerate(lines) if len(line) > limit]
    if long:
        number, size = long[0]
        more = f" (and {len(long) - 1} more lines)" if len(long) > 1 else ""
        out.error(
            2,
            f"line {number}",
            f"has {size:,} bytes{more}, more than the {limit:,} {label} reads whole "
            "(it cuts longer lines, changing names and values where it cuts)",
            "break the file into shorter lines, one element per line (e.g. xmllint --format)",
        )
