"""Mesh files and the files they name (:mod:`mjx_arm.urdf.mesh_files`,
:mod:`mjx_arm.urdf.mesh_side_files`, :mod:`mjx_arm.urdf.mesh_limits`): only regular files are
read, each within a size bound; an OBJ's indices and line endings are checked before an engine
reads it; a Collada scene's instances and a ``.zae`` archive's members are bounded before trimesh
unpacks them; every report line stays under 300 characters.

What could hang (a FIFO where a side file belongs) or crash (a face index past the vertices)
runs in a child process with a timeout, so a regression fails the test instead of stalling or
killing the suite."""

from __future__ import annotations

import json
import os
import socket
import struct
import subprocess
import sys
import threading
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image
from test_urdf_limits import mesh_urdf

from mjx_arm.cli import main
from mjx_arm.urdf.findings import (
    MAX_INSTANCED_BYTES,
    MAX_SCENE_PARTS,
    MAX_SIDE_BYTES,
    MAX_TEXTURE_PIXELS,
)
from mjx_arm.urdf.mesh_convert import MeshConvertError, load_mesh
from mjx_arm.urdf.mesh_files import UnsafeFileError, read_regular, short_path
from mjx_arm.urdf.mesh_limits import mesh_problem, obj_problem
from mjx_arm.urdf.validate import validate

TETRA = b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
# A child validating URDFs one by one with the CLI, each result a JSON line as soon as it is in.
CHILD = """
import contextlib, io, json, sys
from mjx_arm.cli import main
for path in sys.argv[2:]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = main(["validate", "--engine", sys.argv[1], path])
        except SystemExit as exc:
            code = exc.code
    print(json.dumps([path, code, out.getvalue()]), flush=True)
"""
CHILD_SECONDS = 120  # all cases together; each takes 1-3 s on a 2-core CPU


def validate_in_child(paths: list[Path], tmp_path: Path, engine: str = "all") -> dict:
    """``mjx-arm validate --engine ENGINE`` of each path in one child process, killed after
    :data:`CHILD_SECONDS`: path name -> (exit code, output). A hang or a crash fails the test
    with the cases that finished."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    env["XDG_STATE_HOME"] = str(tmp_path / "state")
    argv = [sys.executable, "-c", CHILD, engine, *map(str, paths)]
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=CHILD_SECONDS, env=env)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"validate hung; finished before the kill: {exc.stdout!r}")
    results = {Path(p).name: (c, o) for p, c, o in map(json.loads, done.stdout.splitlines())}
    assert done.returncode == 0 and len(results) == len(paths), (done.returncode, done.stderr)
    return results


def robot(folder: Path, mesh: str, role: str = "collision", name: str = "robot") -> Path:
    """A two-link URDF in ``folder`` whose moving link has a ``role`` mesh ``mesh`` (a visual
    one collides through a box)."""
    folder.mkdir(parents=True, exist_ok=True)
    if role == "collision":
        return mesh_urdf(folder / f"{name}.urdf", mesh)
    path = mesh_urdf(folder / f"{name}.urdf", "box.stl")  # replaced below
    shape = f'<visual><geometry><mesh filename="{mesh}"/></geometry></visual>'
    box = '<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision>'
    old = '<collision><geometry><mesh filename="box.stl"/></geometry></collision>'
    path.write_text(path.read_text().replace(old, shape + box))
    return path


def collada_with_texture(path: Path, texture: str) -> Path:
    """A Collada box whose material maps the image file ``texture``."""
    text = trimesh.exchange.dae.export_collada(trimesh.creation.box(extents=(0.1, 0.1, 0.1)))
    text = text.decode() if isinstance(text, bytes) else text
    image = f'<library_images><image id="img0"><init_from>{texture}</init_from></image>'
    text = text.replace("<library_materials>", image + "</library_images><library_materials>")
    start, end = text.index("<diffuse>"), text.index("</diffuse>") + len("</diffuse>")
    text = text[:start] + '<diffuse><texture texture="img0" texcoord="UV"/></diffuse>' + text[end:]
    path.write_text(text)
    return path


def gltf_box(folder: Path, name: str = "box.gltf") -> tuple[Path, list[Path]]:
    """A glTF box with its buffers in files beside it: (the .gltf, the buffers)."""
    files = trimesh.exchange.gltf.export_gltf(trimesh.creation.box(extents=(0.1, 0.2, 0.3)))
    buffers = []
    for key, data in files.items():
        target = folder / (name if key == "model.gltf" else key)
        target.write_bytes(data)
        buffers += [] if key == "model.gltf" else [target]
    return folder / name, buffers


def png_header(path: Path, width: int, height: int) -> Path:
    """The signature and header chunk of a PNG of ``width`` x ``height`` (no pixels: enough
    for its size to be read, never decoded)."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    header = chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + header + chunk(b"IDAT", b"") + chunk(b"IEND", b""))
    return path


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


# --------------------------------------------------------------------------- no hang, no crash


@pytest.fixture(scope="module")
def child_results(tmp_path_factory) -> dict:
    """Every URDF that hung or crashed ``mjx-arm validate`` (engines: all), validated in one
    child process."""
    root = tmp_path_factory.mktemp("hostile")
    cases = {}
    folder = root / "mtllib"
    folder.mkdir()
    (folder / "tetra.obj").write_bytes(b"mtllib side.mtl\n" + TETRA)
    _fifo(folder / "side.mtl")
    cases["mtllib"] = robot(folder, "tetra.obj", name="mtllib")
    folder = root / "map_kd"
    folder.mkdir()
    (folder / "tetra.mtl").write_bytes(b"newmtl a\nKd 1 1 1\nmap_Kd skin.png\n")
    (folder / "tetra.obj").write_bytes(b"mtllib tetra.mtl\nusemtl a\n" + TETRA)
    _fifo(folder / "skin.png")
    cases["map_kd"] = robot(folder, "tetra.obj", role="visual", name="map_kd")
    folder = root / "gltf"
    folder.mkdir()
    _, buffers = gltf_box(folder)
    buffers[0].unlink()
    _fifo(buffers[0])
    cases["gltf"] = robot(folder, "box.gltf", name="gltf")
    folder = root / "dae"
    folder.mkdir()
    collada_with_texture(folder / "box.dae", "skin.png")
    _fifo(folder / "skin.png")
    cases["dae"] = robot(folder, "box.dae", name="dae")
    folder = root / "mesh"
    folder.mkdir()
    _fifo(folder / "tetra.obj")
    cases["mesh"] = robot(folder, "tetra.obj", name="mesh")
    folder = root / "texture"
    cases["texture"] = robot(folder, "tetra.obj", name="texture")
    (folder / "tetra.obj").write_bytes(TETRA)
    _fifo(folder / "skin.png")
    material = '<material name="x"><texture filename="skin.png"/></material>'
    text = cases["texture"].read_text()
    cases["texture"].write_text(text.replace('<robot name="m">', '<robot name="m">' + material))
    cases.update(_crashes_and_cr(root))
    results = validate_in_child(list(cases.values()), root)
    return {key: results[path.name] for key, path in cases.items()}


def _crashes_and_cr(root: Path) -> dict[str, Path]:
    """The face index that crashed PyBullet, and a lone-CR OBJ of 400,000 faces (PyBullet
    reads it as one line: on 200,000 vertices it crashed)."""
    folder = root / "crash"
    folder.mkdir()
    (folder / "bad.obj").write_bytes(b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 99999999\n")
    cases = {"index": robot(folder, "bad.obj", name="index")}
    lines = [b"v 0 0 0", b"v 0.1 0 0", b"v 0 0.1 0", b"v 0 0 0.1", *[b"f 1 2 3"] * 400_000]
    (folder / "cr.obj").write_bytes(b"\r".join(lines) + b"\r")
    cases["cr"] = robot(folder, "cr.obj", name="cr")
    return cases


EXPECTED = {
    "mtllib": "names material library 'side.mtl', which is a FIFO (named pipe), not a regular",
    "map_kd": "names texture 'skin.png', which is a FIFO (named pipe), not a regular file",
    "gltf": "names buffer 'gltf_buffer_0.bin', which is a FIFO (named pipe), not a regular",
    "mesh": "is a FIFO (named pipe), not a regular file",
    "texture": "has texture 'skin.png', which is a FIFO (named pipe), not a regular file",
    "index": "has a face naming vertex 99,999,999, but the file has 3",
    "cr": "has lone CR line endings",
}


@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_a_hostile_mesh_or_side_file_is_a_named_error_not_a_hang_or_crash(child_results, case):
    code, output = child_results[case]
    assert code == 2, output
    assert EXPECTED[case] in " ".join(output.split()), output
    assert output.splitlines()[-1].startswith("error: ")
    assert all(len(line) < 300 for line in output.splitlines()), output


def test_a_collada_texture_that_is_a_fifo_is_never_opened(child_results):
    """The converter reads a Collada file's geometry only; PyBullet opens no Collada texture."""
    code, output = child_results["dae"]
    assert code == 0, output


# --------------------------------------------------------------------------- bounded reads


def test_read_regular_refuses_a_fifo_and_a_device_without_reading(tmp_path):
    fifo = _fifo(tmp_path / "pipe")
    outcome: list[BaseException] = []

    def read() -> None:
        try:
            read_regular(fifo, 100)
        except UnsafeFileError as exc:
            outcome.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout=10)  # a blocking open would wait for a writer forever
    assert not reader.is_alive() and "is a FIFO (named pipe), not a regular file" in str(outcome)
    with pytest.raises(UnsafeFileError, match="is a character device, not a regular file"):
        read_regular("/dev/zero", 100)
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(tmp_path / "sock"))  # a socket cannot even be opened: still named
    with pytest.raises(UnsafeFileError, match="is a socket, not a regular file"):
        read_regular(tmp_path / "sock", 100)
    server.close()


def test_read_regular_reads_up_to_the_limit_and_no_further(tmp_path):
    path = tmp_path / "mesh.stl"
    path.write_bytes(b"x" * 100)
    assert read_regular(path, 100) == b"x" * 100
    assert read_regular(path, 100, head=10) == b"x" * 10
    with pytest.raises(UnsafeFileError, match="above the 0 MiB a mesh file may have"):
        read_regular(path, 99)


def test_short_path_keeps_the_tail():
    long = "/very" * 40 + "/meshes/link.stl"
    assert short_path(long) == ".../very/very/very/very/very/very/very/very/meshes/link.stl"
    assert len(short_path(long)) <= 60 and short_path("/a/b.stl") == "/a/b.stl"


# --------------------------------------------------------------------------- OBJ text


def test_an_obj_with_lone_cr_endings_is_refused_and_crlf_is_read(tmp_path):
    assert obj_problem(TETRA.replace(b"\n", b"\r\n")) is None
    problem = obj_problem(TETRA.replace(b"\n", b"\r"))
    assert "lone CR line endings" in problem.problem and "tr '\\r' '\\n'" in problem.fix
    mixed = TETRA.replace(b"f 1 2 4\n", b"f 1 2 4\r")  # one lone CR among LF lines
    assert "lone CR" in obj_problem(mixed).problem


@pytest.mark.parametrize(
    ("faces", "message"),
    [
        (b"f 0 1 2\n", "index 0 names no vertex"),
        (b"f -5 1 2\n", "index -5 names no vertex"),
        (b"f 1 2 5\n", "has a face naming vertex 5, but the file has 4"),
        (b"vt 0 0\nf 1/2 2/1 3/1\n", "has a face naming texture coordinate 2, but the file has 1"),
        (b"vn 0 0 1\nf 1//1 2//1 3//9\n", "has a face naming normal 9, but the file has 1"),
        (b"f 1 2 x\n", "'x' is not a vertex reference"),
        (b"f 1 2 4294967297\n", "has a face naming vertex 4,294,967,297"),
    ],
)
def test_a_face_naming_what_the_obj_lacks_is_refused(faces, message):
    problem = obj_problem(TETRA + faces)
    assert problem is not None and message in problem.problem


def test_faces_within_the_obj_pass_negative_and_forward_indices_included():
    assert obj_problem(TETRA + b"f -1 -2 -3\n") is None  # relative to the last vertices
    assert obj_problem(b"f 1 2 3\n" + TETRA) is None  # named before defined: both engines read it
    assert obj_problem(TETRA + b"vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3//1  # a comment\n") is None
    assert obj_problem(TETRA + b"l 1 2\np 3\n") is None


def test_the_validator_reports_the_obj_problem_with_its_fix(tmp_path):
    (tmp_path / "bad.obj").write_bytes(TETRA + b"f 1 2 99999999\n")
    (error,) = validate(robot(tmp_path, "bad.obj"), native=False).errors
    assert error.element == "link 'arm'" and "vertex 99,999,999" in error.problem
    assert error.fix.startswith("export the mesh again")


# --------------------------------------------------------------------------- OBJ side files


def test_a_material_library_outside_the_mesh_folder_is_refused(tmp_path):
    """``mtllib ../../../dev/zero``: PyBullet would read /dev/zero; refused (an error), where it
    leads is named."""
    depth = len(tmp_path.resolve().parts)
    (tmp_path / "tetra.obj").write_bytes(b"mtllib " + b"../" * depth + b"dev/zero\n" + TETRA)
    (error,) = validate(robot(tmp_path, "tetra.obj"), native=False).errors
    assert "which leads out of the mesh's folder" in error.problem
    assert error.fix.startswith("keep a mesh's material libraries, textures and buffers in its")


@pytest.mark.parametrize(
    ("mtllib", "map_kd", "message"),
    [
        ("lib", "skin.png", "names material library 'lib', which is a folder, not a regular"),
        ("tetra.mtl", "lib", "names texture 'lib', which is a folder, not a regular file"),
        ("/home/me/tetra.mtl", "skin.png", "'/home/me/tetra.mtl', which is an absolute path"),
        ("tetra.mtl", "../pipe", "names texture '../pipe', which leads out of the mesh's folder"),
    ],
)
def test_side_file_names_pybullet_would_misread_are_refused(tmp_path, mtllib, map_kd, message):
    """A folder where a material library or texture belongs aborts PyBullet (std::bad_alloc);
    a texture it cannot find beside the mesh it looks for from its working directory (a
    missing ``../pipe`` blocked it on a FIFO there), so a name leaving the folder is refused
    whether or not anything is there."""
    (tmp_path / "lib").mkdir()
    (tmp_path / "tetra.mtl").write_bytes(f"newmtl a\nmap_Kd {map_kd}\n".encode())
    (tmp_path / "tetra.obj").write_bytes(f"mtllib {mtllib}\n".encode() + TETRA)
    problem = mesh_problem(tmp_path / "tetra.obj")
    assert problem is not None and message in problem.problem


def test_a_missing_material_library_is_no_error_and_a_plain_one_passes(tmp_path):
    (tmp_path / "gone.obj").write_bytes(b"mtllib gone.mtl\n" + TETRA)
    assert mesh_problem(tmp_path / "gone.obj") is None  # every reader leaves it out
    (tmp_path / "1").mkdir()  # a folder named like a word of the statement: no reader reads it
    (tmp_path / "tetra.mtl").write_bytes(b"newmtl a\nKd 1 0 0\nmap_Kd -s 1 1 1 skin.png\n")
    Image.new("RGB", (64, 64), (200, 30, 30)).save(tmp_path / "skin.png")
    (tmp_path / "tetra.obj").write_bytes(b"mtllib tetra.mtl\nusemtl a\n" + TETRA)
    report = validate(robot(tmp_path, "tetra.obj", role="visual"), engine="pybullet")
    assert report.ok, report.format()


def test_a_texture_over_the_pixel_limit_or_not_an_image_is_refused(tmp_path):
    (tmp_path / "tetra.mtl").write_bytes(b"newmtl a\nmap_Kd skin.png\n")
    (tmp_path / "tetra.obj").write_bytes(b"mtllib tetra.mtl\n" + TETRA)
    png_header(tmp_path / "skin.png", 4096, 4096)
    assert MAX_TEXTURE_PIXELS == 4096 * 4096 and mesh_problem(tmp_path / "tetra.obj") is None
    png_header(tmp_path / "skin.png", 30_000, 30_000)  # 2.7 GB once decoded
    problem = mesh_problem(tmp_path / "tetra.obj")
    assert "pixels, more than the 16,777,216 a texture may have" in problem.problem
    png_header(tmp_path / "skin.png", 4097, 4096)
    problem = mesh_problem(tmp_path / "tetra.obj")
    assert "is an image of 16,781,312 pixels, more than the 16,777,216" in problem.problem
    (tmp_path / "skin.png").write_bytes(b"not an image")
    assert "is not an image whose size can be read" in mesh_problem(tmp_path / "tetra.obj").problem


# --------------------------------------------------------------------------- glTF, Collada, .zae


def test_a_gltf_converts_through_its_buffers_and_a_buffer_outside_is_refused(tmp_path):
    gltf, buffers = gltf_box(tmp_path)
    np.testing.assert_allclose(load_mesh(gltf).bounds, [[-0.05, -0.1, -0.15], [0.05, 0.1, 0.15]])
    outside = tmp_path.parent / f"{tmp_path.name}_outside.bin"
    outside.write_bytes(buffers[0].read_bytes())
    buffers[0].unlink()
    buffers[0].symlink_to(outside)
    with pytest.raises(MeshConvertError, match=r"names buffer 'gltf_buffer_0\.bin', which leads"):
        load_mesh(gltf)


def test_gltf_buffers_over_the_side_file_limit_are_refused_before_they_are_read(tmp_path):
    gltf, buffers = gltf_box(tmp_path)
    with open(buffers[0], "r+b") as f:
        f.truncate(MAX_SIDE_BYTES + 1)  # sparse: no disk space used
    with pytest.raises(MeshConvertError, match="above the 32 MiB a glTF buffer may have"):
        load_mesh(gltf)


def nested_instances(path: Path, levels: int) -> Path:
    """A Collada box instanced 2**levels times: each level a node holding two
    ``<instance_node>`` of the level below (the file stays a few KB)."""
    text = trimesh.exchange.dae.export_collada(trimesh.creation.box(extents=(0.1, 0.1, 0.1)))
    text = text.decode() if isinstance(text, bytes) else text
    start = text.index("<node ")
    end = text.index("</node>", start) + len("</node>")
    inner = text[text.index(">", start) + 1 : end - len("</node>")]
    library = [f'<library_nodes><node id="n0">{inner}</node>']
    library += [
        f'<node id="n{i}"><instance_node url="#n{i - 1}"/><instance_node url="#n{i - 1}"/></node>'
        for i in range(1, levels + 1)
    ]
    top = f'<node id="top"><instance_node url="#n{levels}"/></node>'
    text = text[:start] + top + text[end:]
    text = text.replace(
        "<library_visual_scenes>", "".join(library) + "</library_nodes>" + "<library_visual_scenes>"
    )
    path.write_text(text)
    return path


def test_a_collada_scene_instancing_its_geometry_2_to_the_30_times_is_refused_at_once(tmp_path):
    few = load_mesh(nested_instances(tmp_path / "few.dae", 3))
    assert len(few.faces) == 8 * 12  # 8 boxes of 12 triangles
    at_limit = nested_instances(tmp_path / "at.dae", 12)  # 4,096 instances: read (about 4 s)
    assert len(load_mesh(at_limit).faces) == MAX_SCENE_PARTS * 12
    over = nested_instances(tmp_path / "over.dae", 13)
    with pytest.raises(MeshConvertError, match="holds 8,192 geometry instances, more than the"):
        load_mesh(over)
    bomb = nested_instances(tmp_path / "bomb.dae", 30)
    assert bomb.stat().st_size < 10_000
    with pytest.raises(MeshConvertError, match="holds 1,073,741,824 geometry instances"):
        load_mesh(bomb)


def test_a_large_collada_geometry_instanced_past_the_byte_bound_is_refused(tmp_path):
    """40 instances of a 1.4 MB sphere: few instances, but 56 MB of geometry to copy."""
    sphere = trimesh.creation.icosphere(subdivisions=5)  # 20,480 faces
    text = trimesh.exchange.dae.export_collada(sphere)
    text = text.decode() if isinstance(text, bytes) else text
    start = text.index("<instance_geometry")
    end = text.index("</instance_geometry>", start) + len("</instance_geometry>")
    text = text[:start] + text[start:end] * 40 + text[end:]
    (tmp_path / "spheres.dae").write_text(text)
    assert 40 * len(text) > MAX_INSTANCED_BYTES
    with pytest.raises(MeshConvertError, match="instances its geometry to more than 32 MiB"):
        load_mesh(tmp_path / "spheres.dae")


def test_a_gltf_of_more_nodes_than_the_part_limit_is_refused_before_trimesh_reads_it(tmp_path):
    gltf, _ = gltf_box(tmp_path)
    header = json.loads(gltf.read_text())
    header["nodes"] = [{"mesh": 0}] * (MAX_SCENE_PARTS + 1)  # trimesh: about 2 ms a node
    header["scenes"] = [{"nodes": list(range(MAX_SCENE_PARTS + 1))}]
    gltf.write_text(json.dumps(header))
    with pytest.raises(MeshConvertError, match="holds 4,097 nodes, more than the 4,096"):
        load_mesh(gltf)


def zae(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def test_a_zae_converts_and_its_declared_unpacked_size_is_bounded(tmp_path):
    dae = trimesh.exchange.dae.export_collada(trimesh.creation.box(extents=(0.1, 0.2, 0.3)))
    mesh = load_mesh(zae(tmp_path / "box.zae", {"box.dae": dae}))
    np.testing.assert_allclose(mesh.bounds, [[-0.05, -0.1, -0.15], [0.05, 0.1, 0.15]])
    bomb = zae(tmp_path / "bomb.zae", {"box.dae": dae, "skin.png": bytes(MAX_SIDE_BYTES)})
    assert bomb.stat().st_size < 100_000  # 32 MiB of zeros pack to about 32 KB
    with pytest.raises(MeshConvertError, match=r"of files unpacked \(as its directory declares\)"):
        load_mesh(bomb)
    many = zae(tmp_path / "many.zae", {f"{i}.png": b"" for i in range(300)} | {"box.dae": dae})
    with pytest.raises(MeshConvertError, match="holds 301 files, more than the 256"):
        load_mesh(many)


def test_a_zae_member_that_unpacks_past_its_declared_size_is_cut_there(tmp_path):
    """A .zae whose directory says its .dae has 1,000 bytes while its data unpacks to 8 MiB:
    no more than 1,001 bytes are unpacked, and the archive is a named error."""
    path = zae(tmp_path / "liar.zae", {"box.dae": bytes(8 * 2**20)})
    data = bytearray(path.read_bytes())
    local, central = 0, data.index(b"PK\x01\x02")
    struct.pack_into("<I", data, local + 22, 1000)  # uncompressed size, local header
    struct.pack_into("<I", data, central + 24, 1000)  # and in the central directory
    path.write_bytes(bytes(data))
    with pytest.raises(MeshConvertError, match=r"cannot be unpacked|more than the 1,000 bytes"):
        load_mesh(path)


# --------------------------------------------------------------------------- report lines


def test_every_report_line_of_hostile_meshes_in_deep_folders_is_under_300_characters(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    folder = tmp_path / ("deep_folder_name_" * 6) / ("another_long_folder_" * 5)
    folder.mkdir(parents=True)
    (folder / "cr.obj").write_bytes(TETRA.replace(b"\n", b"\r"))
    (folder / "zero.obj").write_bytes(b"mtllib " + b"../" * 30 + b"dev/zero\n" + TETRA)
    png_header(folder / "skin.png", 4097, 4096)
    (folder / "skin.mtl").write_bytes(b"newmtl a\nmap_Kd skin.png\n")
    (folder / "skin.obj").write_bytes(b"mtllib skin.mtl\n" + TETRA)
    meshes = ["file:///etc/passwd", "x" * 1000 + ".dae", "cr.obj", "zero.obj", "a/" * 300 + "b.stl"]
    meshes += ["package://" + "p" * 300 + "/meshes/part.stl", "skin.obj"]
    for i, mesh in enumerate(meshes):
        code = main(["validate", str(robot(folder, mesh, name=f"r{i}"))])
        out, err = capsys.readouterr()
        assert code == 2, out
        lines = (out + err).splitlines()
        assert all(len(line) < 300 for line in lines), [line for line in lines if len(line) >= 300]
