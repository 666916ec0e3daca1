"""Collision meshes MuJoCo cannot read (Collada ``.dae``) are converted to STL with trimesh.

A tiny one-joint URDF whose moving link collides through a Collada box converts; the MJCF's mesh
is the cached STL, with the box's bounding box; a second conversion reuses the file; a corrupt
file is a named error with the fix; and the published Kinova arm (Collada collision meshes in
``example-robot-data``) converts with no error.
"""

from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjx_arm.urdf import ConversionError, to_mjcf
from mjx_arm.urdf.mesh_convert import (
    CACHE_FOLDER,
    cache_dir_for,
    convert_mesh,
    default_cache_dir,
    mesh_bounds,
)
from mjx_arm.urdf.validate import validate

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("collada", reason="pycollada reads Collada for trimesh")

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
EXTENTS = np.array([0.04, 0.06, 0.2])  # the box's size (m)
OFFSET = np.array([0.01, -0.02, 0.1])  # where the box's centre lies in the link frame (m)

URDF = """<robot name="one_joint">
  <link name="base">
    <inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0"
      iyz="0"/></inertial>
  </link>
  <link name="arm">
    <inertial><origin xyz="0 0 0.1"/><mass value="1"/>
      <inertia ixx="0.004" iyy="0.004" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="{mesh}"/></geometry></collision>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="0 0 0.05"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="20" velocity="2"/><dynamics damping="0.5"/>
  </joint>
</robot>
"""


@pytest.fixture(autouse=True)
def _user_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The per-user mesh cache lies in the test's folder."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user_cache"))


def _collada(path: Path, boxes: list[tuple[np.ndarray, str]]) -> Path:
    """Write a Collada file with one node per ``(extents, transform)`` box, the transform as
    Collada XML inside the node (``<translate>``, ``<rotate>``)."""
    meshes = [trimesh.creation.box(extents=extents) for extents, _ in boxes]
    text = trimesh.exchange.dae.export_collada(meshes)
    text = text.decode() if isinstance(text, bytes) else text
    for i, (_, transform) in enumerate(boxes):
        node = f'<node id="node{i}" name="node{i}">'
        assert node in text
        text = text.replace(node, node + transform, 1)
    path.write_text(text)
    return path


def _box_dae(path: Path) -> Path:
    """A Collada box of :data:`EXTENTS` turned 90 degrees about z, then moved to :data:`OFFSET`
    (node transforms, not vertex coordinates)."""
    move = "<translate>{} {} {}</translate><rotate>0 0 1 90</rotate>".format(*OFFSET)
    return _collada(path, [(EXTENTS, move)])


def _urdf(folder: Path, mesh: str = "meshes/box.dae") -> Path:
    path = folder / "one_joint.urdf"
    path.write_text(URDF.format(mesh=mesh))
    return path


def _robot(tmp_path: Path) -> Path:
    (tmp_path / "meshes").mkdir()
    _box_dae(tmp_path / "meshes/box.dae")
    return _urdf(tmp_path)


def _mesh_geom_box(model: mujoco.MjModel) -> np.ndarray:
    """Bounding box ``(2, 3)`` of the only mesh geom's vertices, in its body's frame."""
    geom = int(np.flatnonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)[0])
    mesh = model.geom_dataid[geom]
    start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, model.geom_quat[geom])
    vertices = model.mesh_vert[start : start + count] @ rotation.reshape(3, 3).T
    vertices += model.geom_pos[geom]
    return np.stack([vertices.min(axis=0), vertices.max(axis=0)])


def test_collada_collision_mesh_converts_with_its_bounding_box(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    text = to_mjcf(_robot(tmp_path), mesh_cache_dir=str(cache))
    model = mujoco.MjModel.from_xml_string(text)
    assert ".dae" not in text and model.nmesh == 1
    (stl,) = cache.iterdir()
    assert stl.suffix == ".stl" and str(stl) in text
    turned = EXTENTS[[1, 0, 2]]  # the 90 degree turn about z swaps x and y
    expected = np.stack([OFFSET - turned / 2, OFFSET + turned / 2])
    np.testing.assert_allclose(_mesh_geom_box(model), expected, atol=1e-6)


def test_validator_warns_where_the_mesh_goes(tmp_path: Path) -> None:
    report = validate(_robot(tmp_path), engine="mujoco")
    assert report.ok, report.format()
    (warning,) = [w for w in report.warnings if ".dae" in w.problem]
    assert "converted to STL with trimesh" in warning.problem
    assert str(default_cache_dir()) in warning.problem


def test_second_conversion_reuses_the_cached_file(tmp_path: Path) -> None:
    source = _box_dae(tmp_path / "box.dae")
    first = convert_mesh(source, tmp_path / "cache")
    stamp = first.stat().st_mtime_ns
    second = convert_mesh(source, tmp_path / "cache")
    assert second == first and second.stat().st_mtime_ns == stamp
    assert list((tmp_path / "cache").iterdir()) == [first]


def test_same_urdf_converts_to_the_same_bytes(tmp_path: Path) -> None:
    urdf = _robot(tmp_path)
    assert to_mjcf(urdf) == to_mjcf(urdf)  # the per-user cache: same file, same text
    assert len(list(default_cache_dir().iterdir())) == 1


def test_scene_geometries_are_concatenated_with_their_transforms(tmp_path: Path) -> None:
    cube = np.full(3, 0.1)
    boxes = [(cube, "<translate>-1 0 0</translate>"), (cube, "<translate>0 0 2</translate>")]
    stl = trimesh.load(convert_mesh(_collada(tmp_path / "two.dae", boxes), tmp_path))
    assert len(stl.faces) == 24
    np.testing.assert_allclose(stl.bounds, [[-1.05, -0.05, -0.05], [0.05, 0.05, 2.05]], atol=1e-6)


def test_collada_unit_is_applied(tmp_path: Path) -> None:
    source = _collada(tmp_path / "box_mm.dae", [(EXTENTS, "")])
    text = source.read_text().replace("<asset>", '<asset><unit meter="0.001" name="mm"/>', 1)
    source.write_text(text)
    np.testing.assert_allclose(mesh_bounds(source)[1], EXTENTS / 2 * 1e-3, rtol=1e-6)


def test_corrupt_collada_is_a_conversion_error_with_the_fix(tmp_path: Path) -> None:
    urdf = _robot(tmp_path)
    (tmp_path / "meshes/box.dae").write_text("<COLLADA><library_geometries>")
    with pytest.raises(ConversionError, match=r"box\.dae.*re-export the mesh as binary \.stl"):
        convert_mesh(tmp_path / "meshes/box.dae", tmp_path / "cache")
    report = validate(urdf, engine="mujoco")
    (error,) = report.errors
    assert "trimesh cannot convert it" in error.problem and "re-export" in error.fix
    with pytest.raises(ConversionError, match="trimesh cannot convert it"):
        to_mjcf(urdf)


def test_empty_collada_is_a_conversion_error(tmp_path: Path) -> None:
    source = tmp_path / "empty.dae"
    source.write_bytes(trimesh.exchange.dae.export_collada([]))
    message = r"empty\.dae: the file holds no triangle mesh; re-export the mesh as binary"
    with pytest.raises(ConversionError, match=message):
        convert_mesh(source, tmp_path)


def test_without_pycollada_the_mesh_stays_an_error_naming_the_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    urdf = _robot(tmp_path)
    monkeypatch.setitem(sys.modules, "collada", None)  # import collada now fails
    (error,) = validate(urdf, engine="mujoco").errors
    assert "MuJoCo cannot read" in error.problem and "pycollada" in error.problem
    assert "pip install trimesh pycollada" in error.fix
    with pytest.raises(ConversionError, match="pip install trimesh pycollada"):
        convert_mesh(tmp_path / "meshes/box.dae", tmp_path / "cache")


def test_pybullet_check_is_unchanged(tmp_path: Path) -> None:
    report = validate(_robot(tmp_path), engine="pybullet", native=False)
    assert not [f for f in report.findings if ".dae" in f.problem]


def test_conversion_off_keeps_the_error(tmp_path: Path) -> None:
    with pytest.raises(ConversionError, match="MuJoCo cannot read"):
        to_mjcf(_robot(tmp_path), convert_meshes=False)


def test_cache_dir_beside_the_output_or_per_user(tmp_path: Path) -> None:
    assert cache_dir_for(tmp_path / "out/arm.xml") == tmp_path / "out" / CACHE_FOLDER
    assert cache_dir_for(None) == tmp_path / "user_cache/mjx_arm/meshes" == default_cache_dir()


@pytest.mark.skipif(
    not ROBOTS.is_dir(), reason="example-robot-data is not installed (pip install -e '.[test]')"
)
def test_published_kinova_with_collada_collision_meshes_converts(tmp_path: Path) -> None:
    path = ROBOTS / "kinova_description/robots/kinova.urdf"
    report = validate(path, engine="mujoco", native=False)
    assert report.ok, report.format()
    assert sum("converted to STL" in w.problem for w in report.warnings) == 11
    model = mujoco.MjModel.from_xml_string(to_mjcf(path, mesh_cache_dir=str(tmp_path)))
    assert (model.nu, model.nmesh) == (6, 9)  # the two fingers share their two meshes
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)
    assert np.isfinite(data.qacc).all()
