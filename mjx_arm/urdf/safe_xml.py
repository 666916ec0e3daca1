"""Reading URDF XML safely: size, DOCTYPE, nesting and element-count limits.

Every URDF the package reads goes through :func:`read_xml` or :func:`parse_xml`. On this
Python, ``xml.etree`` (expat 2.4 or newer) already stops "billion laughs" entity expansion and
refuses external entities in attributes, but it silently accepts a DOCTYPE that names an
external DTD or declares entities. A URDF needs no DTD, so any DOCTYPE that declares an entity
or names an external DTD is refused before the document is parsed, with a named error. A bare
``<!DOCTYPE robot>`` is accepted.

The limits keep every later step fast and safe: a file above :data:`MAX_BYTES` is not read, and a
tree deeper than :data:`MAX_DEPTH` (Python's serialiser recurses per level), with more than
:data:`MAX_ELEMENTS` elements or with an attribute longer than :data:`MAX_ATTRIBUTE_CHARS`
characters is refused. Names are bounded much lower by the tree checks
(:data:`mjx_arm.urdf.findings.MAX_NAME_CHARS`): PyBullet's loader crashes on a joint name of
1,264 characters.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from xml.parsers import expat

from mjx_arm.urdf.errors import UrdfError

# The limits live with the validator's others (names have a lower limit, MAX_NAME_CHARS).
from mjx_arm.urdf.findings import MAX_ATTRIBUTE_CHARS, MAX_BYTES, MAX_DEPTH, MAX_ELEMENTS
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular

__all__ = [
    "MAX_ATTRIBUTE_CHARS",
    "MAX_BYTES",
    "MAX_DEPTH",
    "MAX_ELEMENTS",
    "XmlError",
    "parse_xml",
    "read_xml",
]


class XmlError(UrdfError):
    """A URDF file that cannot be read as safe XML.

    Attributes:
        element: what is wrong, e.g. ``file``, ``DOCTYPE``, ``XML at line 3, column 7``.
        problem: what is wrong with it.
        fix: how to fix it.
    """

    def __init__(self, element: str, problem: str, fix: str) -> None:
        super().__init__(f"{element}: {problem}. Fix: {fix}")
        self.element, self.problem, self.fix = element, problem, fix


class _Refused(Exception):
    """Raised inside expat handlers: the DOCTYPE holds a declaration a URDF must not have."""


class _PrologEnd(Exception):
    """Raised at the root element's start tag: the DOCTYPE, if any, has been seen."""


def read_xml(path: str | Path) -> ET.Element:
    """The root element of an XML file, read within the limits.

    Args:
        path: the file.

    Raises:
        XmlError: the file is missing, unreadable, too large, not well-formed, carries a DOCTYPE
            with entity declarations or an external DTD, or is nested too deeply.
    """
    path = Path(path)
    if not path.is_file():
        what = "is a directory" if path.is_dir() else "does not exist"
        raise XmlError("file", f"{path} {what}", "pass the path of a URDF file")
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise XmlError("file", _too_large(size), "remove what the URDF does not need")
        data = read_regular(path, MAX_BYTES, "URDF")  # no FIFO, no file grown since the stat
    except UnsafeFileError as exc:
        raise XmlError("file", exc.problem, exc.fix) from exc
    except OSError as exc:
        raise XmlError(
            "file", f"cannot be read: {exc.strerror or exc}", "check the permissions"
        ) from exc
    return parse_xml(data)


def parse_xml(data: bytes | str) -> ET.Element:
    """The root element of an XML document, parsed within the limits.

    Args:
        data: the document (bytes, or text).

    Raises:
        XmlError: as :func:`read_xml`, except for the file checks.
    """
    size = len(data.encode("utf-8", errors="replace")) if isinstance(data, str) else len(data)
    if size > MAX_BYTES:
        raise XmlError("file", _too_large(size), "remove what the URDF does not need")
    _check_doctype(data)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        line, col = getattr(exc, "position", (0, 0))
        reason = str(exc).split(": line ")[0]
        raise XmlError(
            f"XML at line {line}, column {col}",
            f"is not well-formed XML: {reason}",
            f"correct the XML syntax at line {line}, column {col}",
        ) from exc
    except (LookupError, ValueError) as exc:  # an unknown encoding in the XML declaration
        raise XmlError(
            "XML declaration",
            f"cannot be decoded: {exc}",
            'save the file as UTF-8 with <?xml version="1.0" encoding="utf-8"?>',
        ) from exc
    _check_size(root)
    return root


def _too_large(size: int) -> str:
    return f"is {size / 2**20:.1f} MiB, above the {MAX_BYTES / 2**20:.0f} MiB a URDF may have"


def _check_doctype(data: bytes | str) -> None:
    """Refuse a DOCTYPE that declares entities or names an external DTD.

    Expat reads the prolog only: the parse stops at the root element's start tag, before any
    entity could be expanded. Syntax errors are left to the tree parser, which reports them
    with their position.
    """
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.StartDoctypeDeclHandler = _on_doctype
    parser.EntityDeclHandler = _on_entity
    parser.StartElementHandler = _on_start
    try:
        parser.Parse(data, True)
    except _Refused as exc:
        raise XmlError(
            "DOCTYPE",
            str(exc),
            "remove the <!DOCTYPE ...> declaration: a URDF needs no DTD or entities "
            "(they enable entity-expansion and external-file attacks, so they are refused)",
        ) from None
    except (_PrologEnd, expat.ExpatError, LookupError, ValueError):
        return


def _on_doctype(name: str, system_id: str | None, public_id: str | None, internal: int) -> None:
    if system_id or public_id:
        shown = system_id or public_id
        raise _Refused(f"<!DOCTYPE {name}> names an external DTD {shown!r}")


def _on_entity(name: str, is_parameter: int, value, base, system_id, public_id, notation) -> None:
    kind = "parameter entity" if is_parameter else "entity"
    source = f"external file {system_id!r}" if system_id else "text"
    raise _Refused(f"the DOCTYPE declares {kind} {name!r} ({source})")


def _on_start(name: str, attributes: dict) -> None:
    raise _PrologEnd


def _check_size(root: ET.Element) -> None:
    """Refuse a tree nested deeper than MAX_DEPTH, with more than MAX_ELEMENTS elements or with
    an attribute longer than MAX_ATTRIBUTE_CHARS."""
    level, depth, count = [root], 0, 0
    while level:
        depth += 1
        count += len(level)
        if depth > MAX_DEPTH:
            raise XmlError(
                "XML tree",
                f"is nested more than {MAX_DEPTH} elements deep",
                "a URDF nests a few levels (robot/link/visual/geometry/mesh): remove the "
                "extra nesting",
            )
        if count > MAX_ELEMENTS:
            raise XmlError(
                "XML tree",
                f"has more than {MAX_ELEMENTS} elements",
                "remove what the URDF does not need (or split the robot)",
            )
        for elem in level:
            _check_attributes(elem)
        level = [child for parent in level for child in parent]


def _check_attributes(elem: ET.Element) -> None:
    for attr, value in elem.attrib.items():
        if len(value) > MAX_ATTRIBUTE_CHARS:
            raise XmlError(
                f"<{elem.tag[:40]}> attribute {attr[:40]!r}",
                f"is {len(value)} characters long, more than the {MAX_ATTRIBUTE_CHARS} allowed",
                "shorten it (names and paths are far shorter)",
            )
