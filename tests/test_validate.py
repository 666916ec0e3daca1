"""Tests of the three-layer URDF validator (:mod:`mjx_arm.urdf.validate`).

Every broken URDF is the shipped arm with one ElementTree edit, written to ``tmp_path``.
"""

from __future__ import annotations

import copy
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.cli import main
from mjx_arm.paths import default_arm_urdf
from mjx_arm.urdf import ConversionError, to_mjcf
from mjx_arm.urdf import validate as validate_mod
from mjx_arm.urdf.errors import UrdfError
from mjx_arm.urdf.validate import (
    Finding,
    ValidationReport,
    require_valid,
    validate,
    validated,
)
from pybullet_ref import urdf_check

# --------------------------------------------------------------------------- helpers

_CUBE_FACES = [
    (0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
    (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7),
]  # fmt: skip


def _cube(half: float) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """Vertices ``(8, 3)`` and triangles of a cube of half-size ``half`` (m)."""
    corners = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
               (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]  # fmt: skip
    return half * np.array(corners, dtype=float), _CUBE_FACES


def _write_binary_stl(path: Path, vertices: np.ndarray, faces) -> Path:
    record = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    data = np.zeros(len(faces), dtype=record)
    data["v"] = vertices[np.array(faces)]
    path.write_bytes(b"\0" * 80 + np.uint32(len(faces)).tobytes() + data.tobytes())
    return path


def _write_ascii_stl(path: Path, vertices: np.ndarray, faces) -> Path:
    lines = ["solid cube"]
    for face in faces:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += [f"vertex {x} {y} {z}" for x, y, z in vertices[list(face)]]
        lines += ["endloop", "endfacet"]
    path.write_text("\n".join([*lines, "endsolid cube\n"]))
    return path


def _write_obj(path: Path, vertices: np.ndarray, faces) -> Path:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _named(root: ET.Element, tag: str, name: str) -> ET.Element:
    return next(e for e in root.findall(tag) if e.get("name") == name)


def _set(root: ET.Element, tag: str, name: str, sub: str | None, **attrs: str) -> None:
    elem = _named(root, tag, name)
    target = elem if sub is None else elem.find(sub)
    assert target is not None
    for key, value in attrs.items():
        target.set(key, value)


def _remove(root: ET.Element, tag: str, name: str, sub: str) -> None:
    elem = _named(root, tag, name)
    elem.remove(elem.find(sub))


def _shape(root: ET.Element, link: str, role: str, xml: str) -> None:
    """Replace every ``role`` (visual or collision) of ``link`` by one holding ``xml``."""
    elem = _named(root, "link", link)
    for old in elem.findall(role):
        elem.remove(old)
    ET.SubElement(ET.SubElement(elem, role), "geometry").append(ET.fromstring(xml))


def _add_joint(root: ET.Element, name: str, parent: str, child: str, kind: str = "fixed") -> None:
    joint = ET.SubElement(root, "joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)


def _duplicate(root: ET.Element, tag: str, name: str) -> None:
    root.append(copy.deepcopy(_named(root, tag, name)))


# --------------------------------------------------------------------------- broken URDFs


Edit = Callable[[ET.Element, Path], object]  # a str return replaces the whole file


@dataclass(frozen=True)
class Case:
    """One way to break the shipped arm and the finding it must produce."""

    id: str
    edit: Edit
    element: str  # the finding's element starts with this
    layer: int
    text: str  # part of the finding's problem
    engine: str = "all"
    severity: str = "error"
    packages: dict[str, str] = field(default_factory=dict)  # name -> folder under tmp_path


def _malformed(root: ET.Element, tmp: Path) -> str:
    return default_arm_urdf().read_text().replace("</joint>", "</jont>", 1)


def _root_cycle(root: ET.Element, tmp: Path) -> None:
    _set(root, "joint", "shoulder_pan_joint", "parent", link="wrist_1_link")


def _no_revolute(root: ET.Element, tmp: Path) -> None:
    for joint in root.findall("joint"):
        if joint.get("type") == "revolute":
            joint.set("type", "prismatic")


def _size_mismatch(root: ET.Element, tmp: Path) -> None:
    folder = tmp / "elsewhere" / "mesh_folder"
    folder.mkdir(parents=True)
    _write_obj(folder / "small.obj", *_cube(0.03))
    _write_binary_stl(folder / "big.stl", *_cube(0.2))
    _shape(root, "wrist_3_link", "visual", '<mesh filename="package://arm_meshes/small.obj"/>')
    _shape(root, "wrist_3_link", "collision", '<mesh filename="package://arm_meshes/big.stl"/>')


def _mesh_file(name: str, content: Callable[[Path], object]) -> Edit:
    """Put a collision mesh ``name`` written by ``content`` on wrist_3_link."""

    def edit(root: ET.Element, tmp: Path) -> None:
        content(tmp / name)
        _shape(root, "wrist_3_link", "collision", f'<mesh filename="{name}"/>')

    return edit


def _flat(path: Path) -> None:
    vertices = np.array([[0, 0, 0], [0.08, 0, 0], [0.08, 0.08, 0], [0, 0.08, 0]], dtype=float)
    _write_binary_stl(path, vertices, [(0, 1, 2), (0, 2, 3)])


def _garbage(path: Path) -> None:
    path.write_bytes(b"this is not a mesh " * 8)


def joint_attr(sub: str | None, **attrs: str) -> Edit:
    """Set attributes on elbow_joint (``sub`` None) or on one of its children."""
    return lambda root, tmp: _set(root, "joint", "elbow_joint", sub, **attrs)


def link_attr(link: str, sub: str, **attrs: str) -> Edit:
    return lambda root, tmp: _set(root, "link", link, sub, **attrs)


def remove(tag: str, name: str, sub: str) -> Edit:
    return lambda root, tmp: _remove(root, tag, name, sub)


def collision(xml: str) -> Edit:
    """Make ``xml`` the only collision shape of wrist_3_link."""
    return lambda root, tmp: _shape(root, "wrist_3_link", "collision", xml)


def other(edit: Callable[[ET.Element], object]) -> Edit:
    """Any in-place edit of the root (what it returns is dropped)."""

    def apply(root: ET.Element, tmp: Path) -> None:
        edit(root)

    return apply


W3 = "link 'wrist_3_link'"
ELBOW = "joint 'elbow_joint'"
CASES = [
    # layer 1: XML and tree
    Case("malformed_xml", _malformed, "XML at line", 1, "mismatched tag"),
    Case(
        "wrong_root",
        other(lambda r: setattr(r, "tag", "model")),
        "root element <model>",
        1,
        "is not <robot>",
    ),
    Case("robot_without_name", other(lambda r: r.attrib.pop("name")), "robot", 1, "has no name"),
    Case(
        "duplicate_link",
        other(lambda r: _duplicate(r, "link", "tool_link")),
        "link 'tool_link'",
        1,
        "defined 2 times",
    ),
    Case(
        "duplicate_joint",
        other(lambda r: _duplicate(r, "joint", "elbow_joint")),
        ELBOW,
        1,
        "defined 2 times",
    ),
    Case(
        "missing_parent_link",
        joint_attr("parent", link="ghost"),
        ELBOW,
        1,
        "parent link 'ghost', which does not exist",
    ),
    Case(
        "missing_child_link",
        joint_attr("child", link="ghost"),
        ELBOW,
        1,
        "child link 'ghost', which does not exist",
    ),
    Case(
        "two_roots",
        other(lambda r: ET.SubElement(r, "link", name="orphan")),
        "robot",
        1,
        "2 root links ('base_link', 'orphan')",
    ),
    Case(
        "cycle",
        _root_cycle,
        "joint 'shoulder_pan_joint'",
        1,
        "kinematic loop shoulder_link -> upper_arm_link -> forearm_link -> wrist_1_link -> "
        "shoulder_link",
    ),
    Case(
        "two_parents",
        other(lambda r: _add_joint(r, "extra_joint", "base_link", "forearm_link")),
        "link 'forearm_link'",
        1,
        "child of joints 'elbow_joint', 'extra_joint'",
    ),
    Case(
        "self_joint",
        joint_attr("child", link="upper_arm_link"),
        ELBOW,
        1,
        "joins link 'upper_arm_link' to itself",
    ),
    Case("no_revolute_joint", _no_revolute, "robot", 1, "no revolute joint"),
    Case("unknown_joint_type", joint_attr(None, type="hinge"), ELBOW, 1, "unknown type 'hinge'"),
    Case(
        "unknown_mimic",
        other(lambda r: ET.SubElement(_named(r, "joint", "elbow_joint"), "mimic", joint="nope")),
        ELBOW,
        1,
        "mimics joint 'nope'",
    ),
    Case(
        "malformed_origin",
        link_attr("forearm_link", "visual/origin", rpy="0 0"),
        "link 'forearm_link'",
        1,
        "malformed <origin rpy='0 0'>",
    ),
    # layer 2: engine compatibility
    Case("missing_limit", remove("joint", "elbow_joint", "limit"), ELBOW, 2, "has no <limit>"),
    Case(
        "lower_ge_upper",
        joint_attr("limit", lower="1", upper="-1"),
        ELBOW,
        2,
        "lower=1 >= upper=-1",
    ),
    Case("effort_zero", joint_attr("limit", effort="0"), ELBOW, 2, "<limit effort> 0.0, not > 0"),
    Case(
        "velocity_negative",
        joint_attr("limit", velocity="-2"),
        ELBOW,
        2,
        "<limit velocity> -2.0, not > 0",
    ),
    Case("zero_axis", joint_attr("axis", xyz="0 0 0"), ELBOW, 2, "zero <axis>"),
    Case(
        "floating_joint_mujoco",
        joint_attr(None, type="floating"),
        ELBOW,
        2,
        "is floating",
        engine="mujoco",
    ),
    Case(
        "low_damping_pybullet",
        joint_attr("dynamics", damping="0.001"),
        ELBOW,
        2,
        "damping 0.001 < 0.01",
        engine="pybullet",
        severity="warning",
    ),
    Case(
        "no_damping_mujoco",
        remove("joint", "elbow_joint", "dynamics"),
        ELBOW,
        2,
        "converter injects its default damping",
        engine="mujoco",
        severity="warning",
    ),
    Case(
        "missing_mesh_file",
        collision('<mesh filename="meshes/gone.stl"/>'),
        W3,
        2,
        "does not exist",
    ),
    Case(
        "unknown_package",
        collision('<mesh filename="package://no_such_pkg/w3.stl"/>'),
        W3,
        2,
        "package 'no_such_pkg', which was not found",
    ),
    Case(
        "dae_mesh_for_mujoco",
        _mesh_file("w3.dae", lambda p: p.write_text("<COLLADA/>")),
        W3,
        2,
        "format .dae, which MuJoCo cannot read",
        engine="mujoco",
    ),
    Case(
        "ascii_stl",
        _mesh_file("w3.stl", lambda p: _write_ascii_stl(p, *_cube(0.04))),
        W3,
        2,
        "an ASCII STL: MuJoCo and PyBullet read binary STL only",
    ),
    Case("zero_box_size", collision('<box size="0.1 0 0.1"/>'), W3, 2, "size='0.1 0 0.1'"),
    Case(
        "collision_visual_size_mismatch",
        _size_mismatch,
        W3,
        2,
        "6.7x larger than its visual",
        severity="warning",
        packages={"arm_meshes": "elsewhere/mesh_folder"},
    ),
    Case(
        "cylinder_collision_mjx",
        collision('<cylinder radius="0.038" length="0.07"/>'),
        W3,
        2,
        "MJX does not collide",
        engine="mujoco",
        severity="warning",
    ),
    # layer 3: physics
    Case(
        "zero_mass",
        link_attr("wrist_3_link", "inertial/mass", value="0"),
        W3,
        3,
        "moved by a non-fixed joint but has mass 0",
    ),
    Case(
        "negative_mass",
        link_attr("tool_link", "inertial/mass", value="-1"),
        "link 'tool_link'",
        3,
        "negative mass -1",
    ),
    Case(
        "no_inertial",
        remove("link", "forearm_link", "inertial"),
        "link 'forearm_link'",
        3,
        "has no <inertial>",
    ),
    Case(
        "inertia_not_positive_definite",
        link_attr("wrist_2_link", "inertial/inertia", ixx="-0.001"),
        "link 'wrist_2_link'",
        3,
        "is not positive definite",
    ),
    Case(
        "inertia_triangle_inequality",
        link_attr("upper_arm_link", "inertial/inertia", ixx="0.3"),
        "link 'upper_arm_link'",
        3,
        "breaks the triangle inequality",
    ),
    # layer 3: native loaders
    Case(
        "mujoco_load_corrupt_stl",
        _mesh_file("w3.stl", _garbage),
        W3,
        3,
        "MuJoCo cannot load the model: Error: stl_decoder",
        engine="mujoco",
    ),
    Case(
        "mujoco_load_coplanar_mesh",
        _mesh_file("w3.stl", _flat),
        W3,
        3,
        "coplanar vertices",
        engine="mujoco",
    ),
    Case(
        "pybullet_load_corrupt_stl",
        _mesh_file("w3.stl", _garbage),
        W3,
        3,
        "PyBullet warns: ",
        engine="pybullet",
        severity="warning",
    ),
]


def _arm_root() -> tuple[ET.ElementTree, ET.Element]:
    tree = ET.parse(default_arm_urdf())
    return tree, tree.getroot()


def _broken(case: Case, tmp_path: Path) -> Path:
    tree, root = _arm_root()
    text = case.edit(root, tmp_path)
    path = tmp_path / f"{case.id}.urdf"
    if isinstance(text, str):
        path.write_text(text)
    else:
        tree.write(path, encoding="unicode")
    return path


def _cli(path: Path, engine: str, packages: dict[str, str]) -> int:
    args = ["validate", str(path), "--engine", engine]
    for name, folder in packages.items():
        args += ["--package", f"{name}={folder}"]
    return main(args)


def test_cases_cover_fifteen_distinct_rules():
    assert len({c.id for c in CASES}) == len(CASES) >= 15


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_broken_urdf_is_reported(case: Case, tmp_path: Path, capsys):
    path = _broken(case, tmp_path)
    packages = {name: str(tmp_path / folder) for name, folder in case.packages.items()}
    report = validate(path, engine=case.engine, package_dirs=packages)

    hits = [
        f for f in report.findings
        if f.element.startswith(case.element) and f.layer == case.layer
        and f.severity == case.severity and case.text in f.problem
    ]  # fmt: skip
    assert hits, report.format()
    assert all(f.file == str(path) and f.fix for f in report.findings)
    assert report.ok == (case.severity == "warning"), report.format()
    if case.layer < 3:  # a static finding: nothing from the native loaders was needed
        assert not [f for f in report.errors if f.layer == 3], report.format()

    capsys.readouterr()
    assert _cli(path, case.engine, packages) == (2 if case.severity == "error" else 0)
    printed = capsys.readouterr().out
    assert case.element in printed and case.text in printed


# --------------------------------------------------------------------------- the shipped arm


@pytest.mark.parametrize("engine", ["mujoco", "pybullet", "all"])
def test_shipped_arm_is_valid_without_warnings(engine: str, capfd):
    report = validate(default_arm_urdf(), engine=engine)
    assert report.ok and report.findings == (), report.format()
    assert report.format().splitlines()[-1] == "valid"
    assert capfd.readouterr().out == ""  # PyBullet's C-level output is captured
    assert main(["validate", str(default_arm_urdf()), "--engine", engine]) == 0


def test_native_loaders_are_skipped_after_static_errors(tmp_path: Path):
    # PyBullet segfaults on a URDF with two root links; the native layer must not run.
    case = next(c for c in CASES if c.id == "two_roots")
    report = validate(_broken(case, tmp_path), engine="pybullet")
    assert not report.ok
    assert {f.layer for f in report.findings} == {1}


# --------------------------------------------------------------------------- files and failures


def test_missing_file_and_directory_are_findings(tmp_path: Path):
    missing = validate(tmp_path / "nope.urdf")
    folder = validate(tmp_path)
    assert [(f.layer, f.element) for f in missing.errors] == [(1, "file")]
    assert "does not exist" in missing.errors[0].problem
    assert "is a directory" in folder.errors[0].problem
    assert main(["validate", str(tmp_path / "nope.urdf")]) == 2


def test_empty_and_binary_files_are_findings(tmp_path: Path):
    (tmp_path / "empty.urdf").write_text("")
    (tmp_path / "binary.urdf").write_bytes(bytes(range(256)))
    for name in ("empty.urdf", "binary.urdf"):
        report = validate(tmp_path / name)
        assert len(report.errors) == 1 and report.errors[0].element.startswith("XML at line")


def test_unexpected_exception_becomes_a_finding(tmp_path: Path, monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(validate_mod, "_check_geometry", boom)
    report = validate(default_arm_urdf())
    assert not report.ok
    assert "failed unexpectedly: RuntimeError: kaboom" in report.errors[0].problem


def test_unknown_engine_is_a_programming_error():
    with pytest.raises(ValueError, match="engine must be one of"):
        validate(default_arm_urdf(), engine="gazebo")


def test_pybullet_failure_text_is_captured(capfd):
    with urdf_check._captured_fds() as captured:
        text = urdf_check._pybullet_load_file("/nonexistent/arm.urdf")
        os.write(2, b"native stderr\n")
    os.write(1, b"after\n")
    assert text is not None and "Cannot load URDF file" in text
    assert "URDF file '/nonexistent/arm.urdf' not found" in captured[0]
    assert "native stderr" in captured[0]
    out, err = capfd.readouterr()
    assert out == "after\n" and err == ""  # nothing leaked, and the descriptors are back


# --------------------------------------------------------------------------- report API


def test_finding_and_report_format():
    error = Finding("error", 2, "arm.urdf", "joint 'j'", "has no <limit>.", "add one")
    warning = Finding("warning", 3, "arm.urdf", "link 'l'", "is odd", "look")
    assert str(error) == "ERROR [2] arm.urdf: joint 'j': has no <limit>. Fix: add one"
    report = ValidationReport("arm.urdf", "all", (warning, error))
    assert report.errors == (error,) and report.warnings == (warning,) and not report.ok
    lines = report.format().splitlines()
    assert lines[0].startswith("Validating arm.urdf")  # the path once, in the header
    assert lines[1] == "  ERROR [2] joint 'j': has no <limit>. Fix: add one"
    assert lines[2].startswith("  WARNING") and "arm.urdf" not in lines[2]
    assert lines[-1] == "INVALID: 1 error, 1 warning"
    assert ValidationReport("a", "all", (warning,)).format().endswith("valid (1 warning)")
    assert report.summary() == "1 error (joint 'j': has no <limit>)"
    many = ValidationReport("a", "all", (error,) * 5)
    assert many.summary() == (
        "5 errors (joint 'j': has no <limit>; joint 'j': has no <limit>; and 3 more)"
    )


def test_repair_inertia_turns_the_error_into_a_warning_in_every_engine(tmp_path: Path):
    case = next(c for c in CASES if c.id == "inertia_triangle_inequality")
    path = _broken(case, tmp_path)
    broken = validate(path, engine="all")
    assert "--repair-inertia" in broken.errors[0].fix
    assert "repair_inertia = true in an arm file" in broken.errors[0].fix
    # PyBullet loads the repaired copy too, and its native load checks that copy
    for engine in ("mujoco", "pybullet", "all"):
        repaired = validate(path, engine=engine, repair_inertia=True)
        assert repaired.ok, repaired.format()
        assert "nearest valid tensor in every engine" in repaired.warnings[0].problem
    assert main(["convert", str(path), "-o", str(tmp_path / "arm.xml"), "--repair-inertia"]) == 0


def test_a_zero_effort_with_a_default_effort_passes_every_layer(tmp_path: Path):
    """ROS-Industrial URDFs (ABB, Fanuc) write effort="0": with --default-effort the static
    check warns, and the native MuJoCo load (layer 3) converts with the same default."""
    root = ET.parse(default_arm_urdf()).getroot()
    for limit in root.iter("limit"):
        limit.set("effort", "0")
    path = tmp_path / "zero_effort.urdf"
    ET.ElementTree(root).write(path)
    assert not validate(path, engine="mujoco").ok
    report = validate(path, engine="mujoco", default_limits={"effort": 50.0})
    assert report.ok, report.format()
    assert any("the repair gives it 50" in w.problem for w in report.warnings)
    # PyBullet loads a copy with the same default: its checks take it too
    report = validate(path, engine="all", default_limits={"effort": 50.0})
    assert report.ok, report.format()


def test_require_valid(tmp_path: Path):
    assert require_valid(default_arm_urdf(), "mujoco").ok
    case = next(c for c in CASES if c.id == "missing_limit")
    with pytest.raises(UrdfError, match="joint 'elbow_joint': is revolute but has no <limit>"):
        require_valid(_broken(case, tmp_path), "mujoco")


def test_validated_is_cached_per_file_version(tmp_path: Path, monkeypatch):
    path = tmp_path / "arm.urdf"
    path.write_text(default_arm_urdf().read_text())
    calls = []
    real = validate_mod.validate
    monkeypatch.setattr(validate_mod, "validate", lambda *a, **k: calls.append(a) or real(*a, **k))
    first = validated(path, "mujoco")
    assert validated(str(path), "mujoco") is first and len(calls) == 1
    validated(path, "pybullet")
    assert len(calls) == 2
    _, root = _arm_root()
    _remove(root, "joint", "elbow_joint", "limit")
    ET.ElementTree(root).write(path, encoding="unicode")
    os.utime(path, ns=(1, 1))  # a different modification time, whatever the clock resolution
    with pytest.raises(UrdfError, match="elbow_joint"):
        validated(path, "mujoco")


# --------------------------------------------------------------------------- third-party arms

THIRD_PARTY = ["xarm/xarm6_robot.urdf", "kuka_iiwa/model.urdf", "franka_panda/panda.urdf"]


def _names_in(path: Path) -> set[str]:
    root = ET.parse(path).getroot()
    return {e.get("name", "") for e in [*root.findall("link"), *root.findall("joint")]}


# MJX's put_model warns that some meshes have coplanar faces of more than 20 vertices (slow
# collisions); that is a property of these arms' meshes, not a failure.
@pytest.mark.filterwarnings("ignore:Mesh .* has a coplanar face:UserWarning")
@pytest.mark.parametrize("relative", THIRD_PARTY)
def test_third_party_arm_validates_and_converts_or_names_the_culprit(relative: str):
    import mujoco
    import pybullet_data
    from mujoco import mjx

    path = Path(pybullet_data.getDataPath()) / relative
    names = _names_in(path)
    report = validate(path, engine="all")
    for finding in report.errors:
        assert finding.element.split(" ", 1)[1].strip("'") in names, report.format()

    converted = 0
    for repair in (False, True):
        try:
            xml = to_mjcf(path, repair_inertia=repair)
        except ConversionError as exc:
            assert any(f"'{name}'" in str(exc) for name in names), str(exc)
            assert not validate(path, "mujoco", native=False, repair_inertia=repair).ok
            continue
        model = mujoco.MjModel.from_xml_string(xml)
        assert mjx.put_model(model).nu == model.nu > 0
        converted += 1
        # the validation the converter runs first agrees with the conversion
        assert validate(path, "mujoco", native=False, repair_inertia=repair).ok
    assert converted >= 1, f"{relative} converts neither with nor without repair_inertia"
