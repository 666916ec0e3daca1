"""URDFs with meshes, good and hostile, and the mesh side files they lead to.

Each writes a URDF at the output path (the shipped arm with a mesh visual on its last link) and
its mesh files in a folder beside it (``<stem>_meshes/``): one of OBJ (with a material library
and a PNG texture), binary STL, Collada (``.dae``, naming an image), glTF (``.gltf`` and its
``.bin`` buffer) or zipped Collada (``.zae``). The hostile ones:

- :func:`side_special`: a side file (an OBJ's ``mtllib``, its texture, a Collada image, a glTF
  buffer ``uri``) a FIFO, a device, a socket, a folder or a link (:mod:`input_fuzz.special`), or
  a name that leads out of the mesh's folder (``../../../dev/zero``, ``/dev/zero``,
  ``../../../etc/passwd``);
- :func:`zae_bomb`: a ``.zae`` whose Collada member unpacks to 3 GiB (from about 3 MB), declares
  3 GiB and holds a few bytes, declares a few bytes and holds 3 GiB, or that holds thousands of
  members, or members named ``../../evil.dae``, ``/tmp/evil.dae``;
- :func:`obj_damage`: an OBJ with CR-only line endings, a face index of 99999999 (or -99999999,
  0), ``mtllib ../../../dev/zero``;
- :func:`long_mesh_path`: a mesh named ``file:///etc/passwd``, ``package://`` URIs, or by a
  path of 4,000 characters (for the length of an error line);
- :func:`texture_bomb`: a PNG texture whose header declares 100,000 x 100,000 pixels.

:func:`mesh_special` makes the mesh file itself special. Each public function is a mutation
``(good URDF, output path, rng) -> description`` (:mod:`input_fuzz.mutate`).
"""

from __future__ import annotations

import json
import re
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import BOMB_BYTES, bomb_stream, pick
from input_fuzz.special import SPECIALS, make_special

FORMATS = ("obj", "stl", "dae", "gltf", "zae")
_POINTS = np.float32([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0, 0, 0.05]])
_FACES = ((0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3))  # a tetrahedron, outward faces


# --------------------------------------------------------------------------- good files


def png(width: int = 4, height: int = 4) -> bytes:
    """A grey PNG of ``width`` x ``height`` (a header claiming that size, and its pixels when
    they are few; a huge one carries a small stream: the header is the bomb)."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = struct.pack(">I", zlib.crc32(kind + body))
        return struct.pack(">I", len(body)) + kind + body + crc

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    rows, row = (height, width) if width * height <= 2**20 else (1, 4096)
    pixels = zlib.compress((b"\0" + b"\x80" * row) * rows)
    body = chunk(b"IHDR", header) + chunk(b"IDAT", pixels) + chunk(b"IEND", b"")
    return b"\x89PNG\r\n\x1a\n" + body


def obj_text(mtllib: str = "part.mtl") -> str:
    points = "".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in _POINTS)
    faces = "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in _FACES)
    return f"mtllib {mtllib}\n{points}usemtl grey\n{faces}"


def mtl_text(texture: str = "tex.png") -> str:
    return f"newmtl grey\nKd 0.5 0.5 0.5\nmap_Kd {texture}\n"


def stl_bytes() -> bytes:
    out = [b"fuzz".ljust(80, b"\0"), struct.pack("<I", len(_FACES))]
    for face in _FACES:
        out.append(struct.pack("<3f", 0, 0, 0) + _POINTS[list(face)].tobytes() + b"\0\0")
    return b"".join(out)


def dae_text(image: str = "tex.png") -> str:
    points = " ".join(f"{v:g}" for v in _POINTS.ravel())
    faces = " ".join(str(i) for face in _FACES for i in face)
    return (
        '<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" '
        'version="1.4.1"><asset><unit meter="1"/><up_axis>Z_UP</up_axis></asset>'
        f'<library_images><image id="tex"><init_from>{image}</init_from></image>'
        '</library_images><library_geometries><geometry id="g"><mesh>'
        f'<source id="p"><float_array id="pa" count="12">{points}</float_array>'
        '<technique_common><accessor source="#pa" count="4" stride="3">'
        '<param name="X" type="float"/><param name="Y" type="float"/>'
        '<param name="Z" type="float"/></accessor></technique_common></source>'
        '<vertices id="v"><input semantic="POSITION" source="#p"/></vertices>'
        f'<triangles count="4"><input semantic="VERTEX" source="#v" offset="0"/><p>{faces}</p>'
        "</triangles></mesh></geometry></library_geometries><library_visual_scenes>"
        '<visual_scene id="s"><node id="n"><instance_geometry url="#g"/></node></visual_scene>'
        '</library_visual_scenes><scene><instance_visual_scene url="#s"/></scene></COLLADA>'
    )


def gltf_files(uri: str = "part.bin") -> tuple[str, bytes]:
    """(the glTF JSON naming its buffer ``uri``, the buffer's bytes)."""
    points = _POINTS.tobytes()
    indices = np.uint16(_FACES).tobytes()
    low, high = _POINTS.min(0).tolist(), _POINTS.max(0).tolist()
    gltf: dict = {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": uri, "byteLength": len(points) + len(indices)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(points)},
            {"buffer": 0, "byteOffset": len(points), "byteLength": len(indices)},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    gltf["accessors"][0].update(min=low, max=high)
    return json.dumps(gltf), points + indices


def zae_bytes(dae: str) -> bytes:
    import io

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("part.dae", dae)
    return buffer.getvalue()


def _write(folder: Path, name: str, data: str | bytes) -> Path:
    path = folder / name
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def write_mesh_set(folder: Path, fmt: str) -> Path:
    """Good mesh files of ``fmt`` (:data:`FORMATS`) in ``folder``; the mesh's path."""
    folder.mkdir(parents=True, exist_ok=True)
    _write(folder, "tex.png", png())
    if fmt == "obj":
        _write(folder, "part.mtl", mtl_text())
        return _write(folder, "part.obj", obj_text())
    if fmt == "stl":
        return _write(folder, "part.stl", stl_bytes())
    if fmt == "dae":
        return _write(folder, "part.dae", dae_text())
    if fmt == "gltf":
        text, buffer = gltf_files()
        _write(folder, "part.bin", buffer)
        return _write(folder, "part.gltf", text)
    return _write(folder, "part.zae", zae_bytes(dae_text()))


MESH_VISUAL = '<visual><geometry><mesh filename="{}"/></geometry></visual>'
_LINK = '<link name="wrist_3_link">'


def urdf_text(base: str, reference: str) -> str:
    """The URDF ``base`` (the shipped arm, or a mesh URDF made by this module) with its mesh
    named ``reference`` (relative to the URDF's folder, or any text)."""
    base = re.sub(re.escape(MESH_VISUAL.split("{}")[0]) + r'[^"]*"/></geometry></visual>', "", base)
    visual = MESH_VISUAL.format(reference.replace("&", "&amp;").replace('"', "&quot;"))
    return base.replace(_LINK, _LINK + visual, 1)


def meshes_of(out: Path) -> Path:
    """The folder of the mesh files of the URDF at ``out``."""
    return out.with_name(out.stem + "_meshes")


def write_urdf(good: Path, out: Path, fmt: str) -> Path:
    """A URDF at ``out`` with a good mesh of ``fmt``; the mesh's path."""
    mesh = write_mesh_set(meshes_of(out), fmt)
    out.write_text(urdf_text(good.read_text(), f"{mesh.parent.name}/{mesh.name}"))
    return mesh


def good_mesh(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A URDF with a good mesh of a random format."""
    fmt = pick(rng, FORMATS)
    write_urdf(good, out, fmt)
    return f"{fmt}: a good {fmt} mesh"


# --------------------------------------------------------------------------- hostile


def _side_reference(mesh: Path, name: str) -> None:
    """Point the side file ``mesh`` names (its material library's texture, for an OBJ's
    second level; a Collada image; a glTF buffer) at ``name``."""
    folder = mesh.parent
    if mesh.suffix == ".obj":
        (folder / "part.mtl").unlink()
        mesh.write_text(obj_text(name))
    elif mesh.suffix == ".dae":
        mesh.write_text(dae_text(name))
    elif mesh.suffix == ".gltf":
        mesh.write_text(gltf_files(name)[0])


SIDE_NAMES = ("../../../dev/zero", "/dev/zero", "../../../../etc/passwd", "../" * 12 + "dev/random")


def side_special(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A side file of an OBJ (its ``mtllib``, or the texture its library names), a Collada
    image or a glTF buffer made special, or named out of the mesh's folder."""
    fmt = pick(rng, ("obj", "obj", "dae", "gltf"))
    mesh = write_urdf(good, out, fmt)
    folder = mesh.parent
    if rng.random() < 0.25:
        name = pick(rng, SIDE_NAMES)
        _side_reference(mesh, name)
        return f"{fmt} side={name[-16:]}"
    side = {"obj": pick(rng, ("part.mtl", "tex.png")), "dae": "tex.png", "gltf": "part.bin"}[fmt]
    how = pick(rng, SPECIALS)
    make_special(folder / side, how, rng, outside=good)
    return f"{fmt} {side}={how}"


def mesh_special(good: Path, out: Path, rng: np.random.Generator) -> str:
    """The mesh file itself special (a FIFO, a device, a link, ...)."""
    fmt = pick(rng, FORMATS)
    mesh = write_urdf(good, out, fmt)
    how = pick(rng, SPECIALS)
    make_special(mesh, how, rng, outside=good)
    return f"{fmt} mesh={how}"


def _zip_with(out: Path, members: dict[str, bytes]) -> None:
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)


def _declare_size(path: Path, member: str, size: int) -> None:
    """Rewrite the uncompressed size a zip's local header and directory give ``member``."""
    data = bytearray(path.read_bytes())
    raw = member.encode()
    for signature, offset in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        at = data.find(signature)
        while at >= 0:
            name_at = at + (30 if signature == b"PK\x03\x04" else 46)
            if data[name_at : name_at + len(raw)] == raw:
                data[at + offset : at + offset + 4] = struct.pack("<I", size)
            at = data.find(signature, at + 4)
    path.write_bytes(bytes(data))


ZAE_OPS = ("bomb", "declares_big", "declares_small", "many", "traversal")


def zae_bomb(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A hostile ``.zae`` (see the module docstring)."""
    mesh = write_urdf(good, out, "zae")
    op = pick(rng, ZAE_OPS)
    dae = dae_text().encode()
    if op == "bomb":
        from input_fuzz.hostile_npz import _append_deflated

        _zip_with(mesh, {"readme.txt": b"x"})
        stream, crc, size = bomb_stream()
        _append_deflated(mesh, "part.dae", stream, crc, size)
        return f"zae bomb: part.dae unpacks to {BOMB_BYTES / 2**30:.0f} GiB"
    if op == "declares_big":
        _zip_with(mesh, {"part.dae": dae})
        _declare_size(mesh, "part.dae", 3 * 2**30)
        return "zae declares_big: part.dae declares 3 GiB"
    if op == "declares_small":
        _zip_with(mesh, {"part.dae": dae + b" " * (64 * 2**20)})
        _declare_size(mesh, "part.dae", len(dae))
        return "zae declares_small: part.dae declares its dae's bytes, holds 64 MiB more"
    if op == "many":
        count = int(pick(rng, (255, 256, 257, 5000, 65_535)))
        members = {f"m{i}.txt": b"" for i in range(count - 1)}
        _zip_with(mesh, {**members, "part.dae": dae})
        return f"zae many: {count} members"
    name = pick(rng, ("../../evil.dae", "/tmp/evil.dae", "..\\..\\evil.dae", "a/../../../evil.dae"))
    _zip_with(mesh, {name: dae})
    return f"zae traversal: {name}"


def obj_damage(good: Path, out: Path, rng: np.random.Generator) -> str:
    """An OBJ with CR-only line endings, a face index far out of range, or ``mtllib`` leading
    to ``/dev/zero``."""
    mesh = write_urdf(good, out, "obj")
    op = pick(rng, ("cr", "index", "index", "mtllib"))
    text = mesh.read_text()
    if op == "cr":
        mesh.write_bytes(text.replace("\n", "\r").encode())
        return "obj cr: CR-only line endings"
    if op == "index":
        index = pick(rng, ("99999999", "-99999999", "0", "5", "2147483648"))
        mesh.write_text(text + f"f 1 2 {index}\n")
        return f"obj index: a face names vertex {index}"
    mesh.write_text(text.replace("mtllib part.mtl", "mtllib ../../../dev/zero"))
    return "obj mtllib: ../../../dev/zero"


def long_mesh_path(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A mesh named by a URI outside the folder or a path of 4,000 characters."""
    op = pick(rng, ("file", "package", "long", "long_dirs"))
    if op == "file":
        reference = pick(rng, ("file:///etc/passwd", "file:///dev/zero", "file://" + "/x" * 2000))
    elif op == "package":
        reference = "package://" + "p" * int(pick(rng, (10, 4000))) + "/meshes/part.stl"
    elif op == "long":
        reference = "m" * 4000 + ".stl"
    else:
        reference = "/".join(["d" * 200] * 20)[:3995] + ".obj"
    out.write_text(urdf_text(good.read_text(), reference))
    return f"long_path {op}: {len(reference)} characters"


def texture_bomb(good: Path, out: Path, rng: np.random.Generator) -> str:
    """An OBJ whose texture (a PNG) declares 100,000 x 100,000 pixels (or 4097 x 4096)."""
    mesh = write_urdf(good, out, "obj")
    width, height = pick(rng, ((100_000, 100_000), (4097, 4096), (2**31 - 1, 1)))
    (mesh.parent / "tex.png").write_bytes(png(width, height))
    return f"texture {width} x {height} pixels"


MESH_MUTATIONS = (side_special, side_special, zae_bomb, zae_bomb, obj_damage, obj_damage,
                  long_mesh_path, texture_bomb)  # fmt: skip


def mutated_mesh(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A good mesh set with one of its files (mesh or side file) damaged by a byte mutation."""
    from input_fuzz.mutate import BYTE_MUTATIONS

    fmt = pick(rng, FORMATS)
    mesh = write_urdf(good, out, fmt)
    files = sorted(p for p in mesh.parent.iterdir() if p.is_file())
    target = pick(rng, files)
    mutation = pick(rng, BYTE_MUTATIONS)
    source = target.with_name(target.name + ".good")
    target.rename(source)
    what = mutation(source, target, rng)
    source.unlink()
    return f"{fmt} {target.name}: {what}"


def special_mesh(good: Path, out: Path, rng: np.random.Generator) -> tuple[Path, str]:
    """A URDF with a mesh where the URDF itself, its mesh, or a side file of the mesh is
    special; its path (a device for the URDF, at times) and ``part=how``."""
    from input_fuzz.special import special_file

    op = pick(rng, ("urdf", "mesh", "mesh", "side", "side"))
    if op == "urdf":
        write_urdf(good, out, pick(rng, FORMATS))
        return special_file(good, out, rng)
    what = mesh_special(good, out, rng) if op == "mesh" else side_special(good, out, rng)
    return out, what.replace(" ", ":", 1)
