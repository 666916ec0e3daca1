"""The files a mesh names, checked before any reader opens them, and what trimesh is given.

Which reader opens which side file (measured with MuJoCo 3.x, PyBullet 3.2.7, trimesh 5.2):

- OBJ: PyBullet opens the material libraries (``mtllib``) and the textures they name
  (``map_Kd``, ...) and decodes those textures; MuJoCo opens neither. Every such file that is
  there must lie in the mesh's folder (or below it), be a regular file within
  :data:`~mjx_arm.urdf.findings.MAX_SIDE_BYTES`, and a texture must be an image of at most
  :data:`~mjx_arm.urdf.findings.MAX_TEXTURE_PIXELS`; else the mesh is an error (PyBullet would
  block on a FIFO, read ``/dev/zero`` without end or decode a small image to gigabytes). A side
  file that is not there is no error: the readers leave it out.
- glTF (``.gltf``, ``.glb``): trimesh needs its buffers; they are read here under the same
  rules and handed to trimesh, which is given nothing else (no images). Its nodes, mesh
  primitives and accessors are at most :data:`~mjx_arm.urdf.findings.MAX_SCENE_PARTS` each.
- Collada (``.dae``): trimesh is given no side file at all (the converter needs geometry, not
  textures; PyBullet's reader opens no texture either). Its scene may instance one geometry many
  times over: before trimesh reads it, its geometries and their instances are counted
  (at most ``MAX_SCENE_PARTS``) and the geometry bytes counted per instance are bounded by
  :data:`~mjx_arm.urdf.findings.MAX_INSTANCED_BYTES`.

With these bounds, what trimesh parses is at most 32 MiB and a few thousand parts, so its time
and memory are bounded too (measured in ``docs/troubleshooting.md``).
- ``.zae`` (a zipped Collada file): at most :data:`~mjx_arm.urdf.findings.MAX_ZAE_MEMBERS`
  members, whose declared sizes together stay within ``MAX_SIDE_BYTES``; only the Collada
  member is unpacked, and no more bytes than it declared are taken from it.
"""

from __future__ import annotations

import io
import json
import re
import struct
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import NamedTuple

from mjx_arm.urdf.findings import (
    MAX_INSTANCED_BYTES,
    MAX_MESH_BYTES,
    MAX_SCENE_PARTS,
    MAX_SIDE_BYTES,
    MAX_TEXTURE_PIXELS,
    MAX_ZAE_MEMBERS,
)
from mjx_arm.urdf.mesh_files import (
    MIB,
    UnsafeFileError,
    read_regular,
    short_path,
    side_path,
)

__all__ = [
    "MeshProblem",
    "obj_side_problem",
    "texture_problem",
    "trimesh_input",
]

# MTL statements that name a texture file (the name is the rest of the line, after options).
_TEXTURE_KEYS = frozenset({"bump", "disp", "decal", "refl", "norm"})
_FIX_EXPORT = "export the mesh again (e.g. from Blender or MeshLab)"
_BIG = 2**62  # a cap on sums that could otherwise grow without end (2**30 instances and more)


class MeshProblem(NamedTuple):
    """What is wrong with a mesh file, and how to fix it."""

    problem: str
    fix: str


def _together(size: int, what: str) -> str:
    """``has 40.0 MiB of buffers together, above the 32 MiB ...``."""
    return (
        f"has {size / MIB:,.1f} MiB of {what} together, above the "
        f"{MAX_SIDE_BYTES / MIB:.0f} MiB a mesh's side files may have"
    )


def _names(line: bytes) -> list[str]:
    """The file names an ``mtllib`` statement's rest of line may mean: all of it, and each
    word (PyBullet opens the words; a name with spaces is the whole line)."""
    text = line.decode("utf-8", "surrogateescape").strip()
    return list(dict.fromkeys([text, *text.split()])) if text else []


def obj_side_problem(mesh: Path, data: bytes) -> MeshProblem | None:
    """What is wrong with the material libraries an OBJ's text ``data`` names, or with the
    textures they name (each checked where it is there), or None."""
    total = 0
    for line in re.findall(rb"^[ \t]*mtllib[ \t]+([^\n]*)", data, flags=re.MULTILINE):
        for name in _names(line):
            try:
                library = side_path(mesh, name)
                text = b"" if library is None else read_regular(library, MAX_SIDE_BYTES)
            except UnsafeFileError as exc:
                return MeshProblem(
                    f"names material library {short_path(name, 40)!r}, which {exc.problem}", exc.fix
                )
            except OSError:
                continue  # unreadable: no reader gets it either
            total += len(text)
            problem = _mtl_textures_problem(mesh, text)
            if problem is not None:
                return problem
    if total > MAX_SIDE_BYTES:
        problem = _together(total, "material libraries")
        return MeshProblem(problem, _FIX_EXPORT)
    return None


def _mtl_textures_problem(mesh: Path, text: bytes) -> MeshProblem | None:
    """What is wrong with a texture a material library's ``text`` names, or None."""
    for line in text.split(b"\n"):
        words = line.split(None, 1)
        key = words[0].decode("utf-8", "replace").lower() if words else ""
        if len(words) < 2 or not (key.startswith("map_") or key in _TEXTURE_KEYS):
            continue
        name = words[1].decode("utf-8", "surrogateescape").strip()  # PyBullet: all of it
        try:
            texture = side_path(mesh, name) if name else None
        except UnsafeFileError as exc:
            problem = MeshProblem(exc.problem, exc.fix)
        else:
            problem = None if texture is None else texture_problem(texture)
        if problem is not None:
            message = f"names texture {short_path(name, 40)!r}, which {problem.problem}"
            return MeshProblem(message, problem.fix)
    return None


def texture_problem(path: Path) -> MeshProblem | None:
    """What makes the texture at ``path`` unsafe to decode (not a regular file, above
    :data:`~mjx_arm.urdf.findings.MAX_MESH_BYTES`, more than
    :data:`~mjx_arm.urdf.findings.MAX_TEXTURE_PIXELS` pixels, not an image), or None; a file
    that cannot be opened is left to the readers."""
    try:
        data = read_regular(path, MAX_MESH_BYTES, "texture")
    except UnsafeFileError as exc:
        return MeshProblem(exc.problem, exc.fix)
    except OSError:
        return None
    pixels = _image_pixels(data)
    if pixels is None:
        problem = "is not an image whose size can be read"
        return MeshProblem(problem, "save the texture as PNG or JPEG")
    if pixels > MAX_TEXTURE_PIXELS:
        return MeshProblem(
            f"is an image of {pixels:,} pixels, more than the {MAX_TEXTURE_PIXELS:,} a texture "
            "may have (PyBullet decodes it whole)",
            "scale the texture down to at most 4096 x 4096 pixels",
        )
    return None


def _image_pixels(data: bytes) -> int | None:
    """The pixels of the image file ``data`` from its header (nothing is decoded), None when
    it is no image PIL knows; PIL's own limit (about 179 million) reads as one pixel above it."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data)) as image:
                width, height = image.size
    except Image.DecompressionBombError:
        return 2 * Image.MAX_IMAGE_PIXELS + 1
    except Exception:  # PIL raises many kinds on files that are not images
        return None
    return width * height


# --------------------------------------------------------------------------- what trimesh reads


def trimesh_input(source: Path, data: bytes) -> tuple[bytes, str, dict[str, bytes]]:
    """What trimesh is given for the mesh file ``source`` of bytes ``data``: the bytes it
    parses, their file type, and the side files it may read (name -> bytes).

    Raises:
        UnsafeFileError: a side file or archive member that is not read (see the module).
    """
    suffix = source.suffix.lower()
    if suffix == ".zae":
        data, suffix = _zae_collada(source, data), ".dae"
    if suffix == ".dae":
        _check_instances(source, data)
    files = _gltf_buffers(source, data) if suffix in (".gltf", ".glb") else {}
    return data, suffix[1:], files


def _gltf_buffers(source: Path, data: bytes) -> dict[str, bytes]:
    """The external buffers of a glTF (``.gltf`` text or ``.glb``), each read with
    :func:`read_regular`, all together within ``MAX_SIDE_BYTES``, after its nodes, mesh
    primitives and accessors are checked against MAX_SCENE_PARTS."""
    header = _gltf_header(data)
    for key in ("nodes", "accessors"):
        _check_parts(source, len(_items(header, key)), key)
    primitives = [_items(mesh, "primitives") for mesh in _items(header, "meshes")]
    _check_parts(source, sum(map(len, primitives)), "mesh primitives")
    uris = [b.get("uri") for b in _items(header, "buffers")]
    files: dict[str, bytes] = {}
    for uri in [u for u in uris if isinstance(u, str) and u and not u.startswith("data:")]:
        try:
            path = side_path(source, uri)
            if path is None:
                continue  # trimesh names the missing buffer
            files[uri] = read_regular(path, MAX_SIDE_BYTES, "glTF buffer")
        except UnsafeFileError as exc:
            problem = f"names buffer {short_path(uri, 40)!r}, which {exc.problem}"
            raise UnsafeFileError(source, problem, exc.fix) from exc
        except OSError:
            continue  # unreadable: trimesh names it
        total = sum(len(b) for b in files.values())
        if total > MAX_SIDE_BYTES:
            raise UnsafeFileError(source, _together(total, "buffers"), _FIX_EXPORT)
    return files


def _gltf_header(data: bytes) -> dict:
    """The JSON of a glTF (``.gltf`` text, or a ``.glb``'s JSON chunk); {} when it cannot be
    read (trimesh then names what is wrong)."""
    text = data
    if data[:4] == b"glTF" and len(data) >= 20:  # binary glTF: header, then the JSON chunk
        length, kind = struct.unpack_from("<I4s", data, 12)
        text = data[20 : 20 + length] if kind == b"JSON" else b""
    try:
        header = json.loads(text)
    except (ValueError, RecursionError):
        return {}
    return header if isinstance(header, dict) else {}


def _items(parent: object, key: str) -> list[dict]:
    """The objects of the list ``parent[key]`` (a glTF's nodes, ...); [] where there is none."""
    items = parent.get(key) if isinstance(parent, dict) else None
    return [item for item in items if isinstance(item, dict)] if isinstance(items, list) else []


def _zae_collada(source: Path, data: bytes) -> bytes:
    """The Collada member of a ``.zae`` archive, unpacked within the limits (module text)."""
    _check_member_count(source, data)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            infos = archive.infolist()
            declared = sum(info.file_size for info in infos)
            if declared > MAX_SIDE_BYTES:
                problem = _together(declared, "files unpacked (as its directory declares)")
                raise UnsafeFileError(source, problem, _FIX_EXPORT)
            member = next((i for i in infos if i.filename.lower().endswith(".dae")), None)
            if member is None:
                raise UnsafeFileError(source, "holds no .dae file", _FIX_EXPORT)
            with archive.open(member) as stream:
                dae = stream.read(member.file_size + 1)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError) as exc:
        problem = f"cannot be unpacked ({type(exc).__name__}: {exc})"
        raise UnsafeFileError(source, problem, _FIX_EXPORT) from exc
    if len(dae) > member.file_size:
        problem = f"unpacks to more than the {member.file_size:,} bytes its .dae declares"
        raise UnsafeFileError(source, problem, _FIX_EXPORT)
    return dae


def _check_member_count(source: Path, data: bytes) -> None:
    """At most MAX_ZAE_MEMBERS members, read from the end record before the directory is."""
    end = data.rfind(b"PK\x05\x06", max(0, len(data) - 65_557))
    count = int.from_bytes(data[end + 10 : end + 12], "little") if end >= 0 else 0
    if count > MAX_ZAE_MEMBERS:
        problem = f"holds {count:,} files, more than the {MAX_ZAE_MEMBERS} a .zae may have"
        raise UnsafeFileError(source, problem, _FIX_EXPORT)


_TAG = re.compile(
    rb"<(/?)(node|instance_node|instance_geometry|geometry|visual_scene)\b([^>]*?)(/?)>"
)
_ATTR = re.compile(rb"""\b(id|url)\s*=\s*["']#?([^"']*)["']""")


def _check_instances(source: Path, data: bytes) -> None:
    """Refuse a Collada file with more than MAX_SCENE_PARTS geometries or instances of them,
    or whose geometry counted once per instance (through nested nodes and
    ``<instance_node>``s) exceeds MAX_INSTANCED_BYTES, before trimesh reads it."""
    sizes, children, roots = _collada_graph(data)
    _check_parts(source, len(sizes), "geometries")
    weights: dict[str, tuple[int, int]] = {}

    def weight(node: str, depth: int) -> tuple[int, int]:
        """Bytes and instances of geometry under ``node`` (each capped just above its limit)."""
        if node in weights:
            return weights[node]
        if depth > 64:  # a cycle, or nesting no reader follows
            raise UnsafeFileError(source, "nests its nodes in a cycle or too deep", _FIX_EXPORT)
        size = count = 0
        for kind, target in children.get(node, ()):
            more = (sizes.get(target, 0), 1) if kind == b"g" else weight(target, depth + 1)
            size, count = min(size + more[0], _BIG), min(count + more[1], _BIG)
        weights[node] = size, count
        return size, count

    found = [weight(root, 0) for root in roots]
    _check_parts(source, sum(count for _, count in found), "geometry instances")
    if sum(size for size, _ in found) > MAX_INSTANCED_BYTES:
        problem = (
            f"instances its geometry to more than {MAX_INSTANCED_BYTES / MIB:.0f} MiB "
            "(each <instance_geometry> and <instance_node> copies it)"
        )
        raise UnsafeFileError(source, problem, "instance each geometry a few times at most")


def _check_parts(source: Path, count: int, what: str) -> None:
    """At most MAX_SCENE_PARTS ``what`` (nodes, geometries) in one mesh file."""
    if count > MAX_SCENE_PARTS:
        problem = f"holds {count:,} {what}, more than the {MAX_SCENE_PARTS:,} a mesh may have"
        raise UnsafeFileError(source, problem, "merge the parts into one mesh")


def _collada_graph(data: bytes) -> tuple[dict[str, int], dict[str, list], list[str]]:
    """A Collada file's geometry sizes (id -> bytes), each node's children (node id ->
    ``(b"g", geometry id)`` or ``(b"n", node id)``, an inline child node under a made-up
    id), and the nodes of its visual scenes, read from its tags (no XML parse)."""
    sizes: dict[str, int] = {}
    children: dict[str, list] = {}
    roots: list[str] = []
    stack: list[tuple[bytes, str, int]] = []  # open elements: tag, id, start offset
    for n, match in enumerate(_TAG.finditer(data)):
        closing, tag, attrs, empty = match.groups()
        attr = dict(_ATTR.findall(attrs))
        ident = attr.get(b"id", f"#{n}".encode()).decode("utf-8", "replace")
        parent = stack[-1] if stack else None
        if closing:
            if stack and stack[-1][0] == tag:
                _, ident, start = stack.pop()
                if tag == b"geometry":
                    sizes[ident] = match.end() - start
            continue
        target = attr.get(b"url", b"").decode("utf-8", "replace")
        if tag == b"instance_geometry" and parent and parent[0] == b"node":
            children.setdefault(parent[1], []).append((b"g", target))
        elif tag == b"instance_node" and parent and parent[0] == b"node":
            children.setdefault(parent[1], []).append((b"n", target))
        elif tag == b"node" and parent and parent[0] == b"node":
            children.setdefault(parent[1], []).append((b"n", ident))
        elif tag == b"node" and parent and parent[0] == b"visual_scene":
            roots.append(ident)
        if not empty and tag in (b"node", b"geometry", b"visual_scene"):
            stack.append((tag, ident, match.start()))
    return sizes, children, roots
