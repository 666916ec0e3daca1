"""The URDF limits that keep counts and sizes below what MuJoCo, PyBullet and trimesh accept
(:mod:`mjx_arm.urdf.findings`), each tested at its edge: just under passes, just over is the
named finding."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from test_error_lines import chain_urdf

from mjx_arm.urdf import to_mjcf
from mjx_arm.urdf.findings import (
    MAX_CHAIN_LINKS,
    MAX_LINE_BYTES,
    MAX_LINKS,
    MAX_MESH_BYTES,
    MAX_MESH_FACES,
    MAX_MESH_PATH_BYTES,
    MAX_MESH_VERTICES,
)
from mjx_arm.urdf.mesh_convert import MeshConvertError, load_mesh
from mjx_arm.urdf.mesh_limits import count_problem, mesh_problem
from mjx_arm.urdf.validate import validate

_INERTIAL = (
    '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" '
    'iyz="0"/></inertial>'
)
_JOINT = (
    '<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
    '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/>'
    '<dynamics damping="0.1"/></joint>'
)


def _static(path: Path, engine: str = "all"):
    """The static layers' report (no native load)."""
    return validate(path, engine=engine, native=False)


def star_urdf(path: Path, links: int) -> Path:
    """A base link with ``links - 1`` children, each on its own revolute joint."""
    body = [f'<link name="base">{_INERTIAL}</link>']
    for i in range(1, links):
        body.append(f'<link name="l{i}">{_INERTIAL}</link>')
        body.append(_JOINT.format(name=f"j{i}", parent="base", child=f"l{i}"))
    path.write_text('<robot name="star">\n' + "\n".join(body) + "\n</robot>")
    return path


def mesh_urdf(path: Path, mesh: str) -> Path:
    """Two links and one joint; the moving link collides through mesh file ``mesh``."""
    shape = f'<collision><geometry><mesh filename="{mesh}"/></geometry></collision>'
    links = f'<link name="base">{_INERTIAL}</link><link name="arm">{_INERTIAL}{shape}</link>'
    joint = _JOINT.format(name="j", parent="base", child="arm")
    path.write_text(f'<robot name="m">{links}{joint}</robot>')
    return path


def binary_stl(path: Path, faces: int) -> Path:
    """A binary STL of ``faces`` small random triangles."""
    records = np.zeros(faces, dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    records["v"] = np.random.default_rng(0).random((faces, 3, 3), dtype=np.float32) * 0.05
    path.write_bytes(b"\0" * 80 + struct.pack("<I", faces) + records.tobytes())
    return path


# --------------------------------------------------------------------------- chain depth


def test_a_chain_at_the_depth_limit_passes_one_link_more_is_an_error(tmp_path):
    at_limit = _static(chain_urdf(tmp_path / "at.urdf", MAX_CHAIN_LINKS - 1))
    assert at_limit.ok, at_limit.format()
    over = _static(chain_urdf(tmp_path / "over.urdf", MAX_CHAIN_LINKS))
    (error,) = over.errors
    assert error.layer == 1 and error.element == f"link 'l{MAX_CHAIN_LINKS}'"
    assert f"is {MAX_CHAIN_LINKS + 1} links down from the root link" in error.problem
    assert "MuJoCo cannot read an MJCF nested that deep" in error.problem


def test_the_deep_chain_error_comes_before_the_converter(tmp_path):
    """A chain deeper than MuJoCo reads (500 links) is refused by the static check, in well
    under the minutes the converter would take to fail."""
    report = _static(chain_urdf(tmp_path / "deep.urdf", 500), engine="mujoco")
    assert [e.element for e in report.errors] == ["link 'l500'"]


@pytest.mark.slow
def test_a_chain_at_the_depth_limit_converts_and_loads_in_both_engines(tmp_path):
    urdf = chain_urdf(tmp_path / "at.urdf", MAX_CHAIN_LINKS - 1)
    model = mujoco.MjModel.from_xml_string(to_mjcf(urdf))
    assert model.nbody == MAX_CHAIN_LINKS + 1  # the world body and one per link
    report = validate(urdf, engine="pybullet")  # PyBullet's loader, in a child process
    assert report.ok, report.format()


def test_mujoco_reads_back_the_measured_chain_depth_and_refuses_one_more(tmp_path):
    """The failure point behind MAX_CHAIN_LINKS: MuJoCo's URDF import, written as MJCF, reads
    back with 497 links and not with 498 (tinyxml2's nesting limit of 500 elements)."""

    def reads_back(joints: int) -> bool:
        spec = mujoco.MjSpec.from_file(str(chain_urdf(tmp_path / f"c{joints}.urdf", joints)))
        spec.compile()
        try:
            mujoco.MjModel.from_xml_string(spec.to_xml())
        except ValueError as exc:
            assert "XML_ELEMENT_DEPTH_EXCEEDED" in str(exc)
            return False
        return True

    assert reads_back(496) and not reads_back(497)
    assert MAX_CHAIN_LINKS <= 497 // 2 + 10  # the limit keeps about half of it in reserve


# --------------------------------------------------------------------------- link count


def test_links_at_the_count_limit_pass_one_more_is_an_error(tmp_path):
    at_limit = _static(star_urdf(tmp_path / "at.urdf", MAX_LINKS))
    assert at_limit.ok, at_limit.format()
    over = _static(star_urdf(tmp_path / "over.urdf", MAX_LINKS + 1))
    problems = [e.problem for e in over.errors]
    assert problems == [f"has {MAX_LINKS + 1} <link> elements, more than the {MAX_LINKS} this "
                        "tool accepts"]  # fmt: skip


# --------------------------------------------------------------------------- meshes


def test_an_stl_at_the_face_limit_passes_one_face_more_is_an_error(tmp_path):
    binary_stl(tmp_path / "at.stl", MAX_MESH_FACES)
    at_limit = _static(mesh_urdf(tmp_path / "at.urdf", "at.stl"), engine="mujoco")
    assert at_limit.ok, at_limit.format()
    binary_stl(tmp_path / "over.stl", MAX_MESH_FACES + 1)
    (error,) = _static(mesh_urdf(tmp_path / "over.urdf", "over.stl"), engine="mujoco").errors
    assert error.element == "link 'arm'" and error.layer == 2
    assert f"has {MAX_MESH_FACES + 1:,} faces, more than the {MAX_MESH_FACES:,}" in error.problem


def test_a_mesh_file_over_the_size_limit_is_refused_before_it_is_read(tmp_path):
    at_limit, over = tmp_path / "at.stl", tmp_path / "over.stl"
    for path, size in ((at_limit, MAX_MESH_BYTES), (over, MAX_MESH_BYTES + 1)):
        with open(path, "wb") as f:
            f.write(b"\0" * 84)
            f.truncate(size)  # a sparse file: no disk space used
    assert mesh_problem(at_limit) is None
    assert mesh_problem(over).problem == "is 32.0 MiB, above the 32 MiB a mesh file may have"
    (error,) = _static(mesh_urdf(tmp_path / "over.urdf", "over.stl")).errors
    assert "above the 32 MiB a mesh file may have" in error.problem


def mesh_at_path_length(root: Path, length: int) -> Path:
    """A small binary STL whose absolute path has ``length`` bytes, under ``root``."""
    root = root.resolve()
    rel = ""
    while length - len(str(root)) - 1 - len(rel) - 4 > 200:
        rel += "d" * 150 + "/"
    rel += "m" * (length - len(str(root)) - 1 - len(rel) - 4) + ".stl"
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    binary_stl(path, 4)
    assert len(str(path)) == length
    return path


def test_a_mesh_path_at_the_limit_passes_one_byte_more_is_an_error_for_pybullet(tmp_path):
    for length, ok in ((MAX_MESH_PATH_BYTES, True), (MAX_MESH_PATH_BYTES + 1, False)):
        folder = tmp_path / str(length)
        mesh = mesh_at_path_length(folder, length)
        urdf = mesh_urdf(folder / "arm.urdf", str(mesh.relative_to(folder.resolve())))
        report = _static(urdf, engine="pybullet")
        assert report.ok == ok, report.format()
        assert _static(urdf, engine="mujoco").ok  # MuJoCo reads long paths
    (error,) = report.errors
    assert f"a path of {MAX_MESH_PATH_BYTES + 1:,} bytes, more than the" in error.problem


def test_pybullet_crashes_on_a_mesh_path_of_1032_bytes(tmp_path):
    """The failure point behind MAX_MESH_PATH_BYTES, in a child process: PyBullet loads a mesh
    whose absolute path has 1,031 bytes and dies of SIGSEGV at 1,032."""
    code = "import sys, pybullet as p; p.connect(p.DIRECT); p.loadURDF(sys.argv[1])"
    codes = []
    for length in (1031, 1032):
        folder = tmp_path / str(length)
        mesh = mesh_at_path_length(folder, length)
        urdf = mesh_urdf(folder / "arm.urdf", str(mesh.relative_to(folder.resolve())))
        run = subprocess.run([sys.executable, "-c", code, str(urdf)], capture_output=True)
        codes.append(run.returncode)
    assert codes == [0, -11]  # -11: SIGSEGV


def test_obj_faces_and_vertices_are_counted_by_their_lines(tmp_path):
    def obj(name: str, vertices: int, faces: int) -> Path:
        path = tmp_path / name
        path.write_bytes(b"v 0 0 0\n" * vertices + b"f 1 1 1\n" * faces)
        return path

    assert mesh_problem(obj("a.obj", 3, MAX_MESH_FACES)) is None
    assert "faces, more than" in mesh_problem(obj("b.obj", 3, MAX_MESH_FACES + 1)).problem
    assert mesh_problem(obj("c.obj", MAX_MESH_VERTICES, 1)) is None
    assert "vertices, more than" in mesh_problem(obj("d.obj", MAX_MESH_VERTICES + 1, 1)).problem
    assert count_problem(MAX_MESH_FACES, MAX_MESH_VERTICES) is None


def test_a_mesh_that_trimesh_reads_is_held_to_the_face_limit(tmp_path):
    """Formats that only trimesh reads (here PLY) are counted once read, before the STL
    for MuJoCo is written."""
    import trimesh

    def ply(name: str, faces: int) -> Path:
        vertices = np.random.default_rng(1).random((3 * faces, 3))
        mesh = trimesh.Trimesh(vertices, np.arange(3 * faces).reshape(-1, 3), process=False)
        path = tmp_path / name
        path.write_bytes(mesh.export(file_type="ply"))
        return path

    assert len(load_mesh(ply("at.ply", MAX_MESH_FACES)).faces) == MAX_MESH_FACES
    with pytest.raises(MeshConvertError, match=f"more than the {MAX_MESH_FACES:,} MuJoCo reads"):
        load_mesh(ply("over.ply", MAX_MESH_FACES + 1))


# --------------------------------------------------------------------------- line length


def long_line_urdf(path: Path, line_bytes: int, joint: str = "abcdefghij") -> Path:
    """A two-link URDF whose joint ends line 4, a line of ``line_bytes`` bytes padded by a
    comment before the joint."""
    joint_text = _JOINT.format(name=joint, parent="base", child="a")
    pad = line_bytes - len(joint_text) - len("<!---->")
    lines = [
        '<robot name="long">',
        f'<link name="base">{_INERTIAL}</link>',
        f'<link name="a">{_INERTIAL}</link>',
        "<!--" + "x" * pad + "-->" + joint_text,
        "</robot>",
    ]
    path.write_text("\n".join(lines))
    return path


def test_a_line_at_the_byte_limit_passes_one_byte_more_is_an_error_for_pybullet(tmp_path):
    at_limit = _static(long_line_urdf(tmp_path / "at.urdf", MAX_LINE_BYTES))
    assert at_limit.ok, at_limit.format()
    over = long_line_urdf(tmp_path / "over.urdf", MAX_LINE_BYTES + 1)
    (error,) = _static(over).errors
    assert error.element == "line 4" and error.layer == 2
    assert f"has {MAX_LINE_BYTES + 1:,} bytes, more than the {MAX_LINE_BYTES:,}" in error.problem
    assert _static(over, engine="mujoco").ok  # MuJoCo reads long lines whole


def test_pybullet_cuts_a_name_on_a_line_longer_than_8191_bytes(tmp_path):
    """The failure point behind MAX_LINE_BYTES: PyBullet breaks a line after 8,191 bytes, so a
    joint name across that point reads back with a line break in it (in a child process, as
    PyBullet may also crash on what it misreads)."""
    joint_text = _JOINT.format(name="abcdefghij", parent="base", child="a")
    name_end = joint_text.index('abcdefghij"') + 10

    def name_read(cut_after: int) -> str:
        # the line is cut after byte 8,191: put the name's byte `cut_after` there
        line_bytes = 8191 - cut_after + (len(joint_text) - name_end) + 10
        urdf = long_line_urdf(tmp_path / f"cut{cut_after}.urdf", line_bytes)
        code = (
            "import sys, pybullet as p; p.connect(p.DIRECT); "
            "print(repr(p.getJointInfo(p.loadURDF(sys.argv[1]), 0)[1].decode()))"
        )
        run = subprocess.run(
            [sys.executable, "-c", code, str(urdf)], capture_output=True, text=True, timeout=120
        )
        assert run.returncode == 0, run.stderr
        return run.stdout.strip().splitlines()[-1]

    assert name_read(11) == "'abcdefghij'"  # the name and its closing quote before the cut
    assert name_read(5) == "'abcde\\nfghij'"  # cut after its fifth byte
