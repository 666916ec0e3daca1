"""Arm URDFs as their description packages publish them convert with no edit by hand.

The robots come from the ``example-robot-data`` package (a pinned test dependency): UR3, UR5 and
UR10 (Collada visuals, ``package://`` paths, massless frame links ``base``, ``tool0`` and
``ee_link``, the last with a collision box) and Panda (Collada visuals, frames ``panda_link8``
and ``panda_hand_tcp``, a mimic finger joint). Warnings are allowed; errors are not.
"""

from __future__ import annotations

import sysconfig
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjx_arm.urdf import ConversionError, to_mjcf
from mjx_arm.urdf.validate import validate

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
ARMS = {  # URDF -> (joints, actuated joints)
    "ur_description/urdf/ur3_robot.urdf": (6, 6),
    "ur_description/urdf/ur5_robot.urdf": (6, 6),
    "ur_description/urdf/ur10_robot.urdf": (6, 6),
    "panda_description/urdf/panda.urdf": (9, 8),  # 7 arm joints, 2 fingers (one mimics)
}

pytestmark = pytest.mark.skipif(
    not ROBOTS.is_dir(), reason="example-robot-data is not installed (pip install -e '.[test]')"
)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_published_arm_converts_and_compiles(name: str, tmp_path: Path) -> None:
    path = ROBOTS / name
    report = validate(path, engine="mujoco", native=False)
    assert report.ok, report.format()
    text = to_mjcf(path)
    model = mujoco.MjModel.from_xml_string(text)
    joints, actuated = ARMS[name]
    assert (model.njnt, model.nu) == (joints, actuated)
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)
    assert np.isfinite(data.qacc).all() and np.isfinite(data.qpos).all()


def test_collada_visuals_are_warnings_and_left_out() -> None:
    path = ROBOTS / "ur_description/urdf/ur5_robot.urdf"
    report = validate(path, engine="mujoco", native=False)
    dae = [w for w in report.warnings if ".dae" in w.problem]
    assert len(dae) == 7 and all("leaves this visual out" in w.problem for w in dae)
    assert ".dae" not in to_mjcf(path)


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_massless_frame_with_collision_is_a_warning(engine: str) -> None:
    # UR's ee_link writes out mass 0 (PyBullet keeps 0), and carries a collision box
    path = ROBOTS / "ur_description/urdf/ur5_robot.urdf"
    report = validate(path, engine=engine, native=False)
    frames = [w for w in report.warnings if "massless frame" in w.problem]
    assert [w.element for w in frames] == ["link 'ee_link'"]
    assert not report.errors


def test_frame_without_inertial_is_an_error_for_pybullet_only(tmp_path: Path) -> None:
    root = ET.parse(ROBOTS / "ur_description/urdf/ur5_robot.urdf").getroot()
    ee = next(link for link in root.findall("link") if link.get("name") == "ee_link")
    ee.remove(ee.find("inertial"))  # PyBullet would invent 1 kg for it
    path = tmp_path / "ur5_no_inertial.urdf"
    ET.ElementTree(root).write(path, encoding="unicode")
    packages = {"example-robot-data": str(ROBOTS.parent)}
    mujoco_report = validate(path, engine="mujoco", native=False, package_dirs=packages)
    assert not mujoco_report.errors
    pybullet_report = validate(path, engine="pybullet", native=False, package_dirs=packages)
    assert any("ee_link" in e.element for e in pybullet_report.errors)


def test_mimic_joint_becomes_an_equality() -> None:
    model = mujoco.MjModel.from_xml_string(to_mjcf(ROBOTS / "panda_description/urdf/panda.urdf"))
    assert model.neq == 1 and model.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT


def test_a_moving_massless_link_stays_a_named_error(tmp_path: Path) -> None:
    root = ET.parse(ROBOTS / "ur_description/urdf/ur5_robot.urdf").getroot()
    wrist = next(link for link in root.findall("link") if link.get("name") == "wrist_3_link")
    wrist.remove(wrist.find("inertial"))
    path = tmp_path / "ur5_massless_wrist.urdf"
    ET.ElementTree(root).write(path, encoding="unicode")
    packages = {"example-robot-data": str(ROBOTS.parent)}  # the copy lies outside the package
    with pytest.raises(ConversionError, match=r"wrist_3_link.*inertial"):
        to_mjcf(path, package_dirs=packages)


def test_package_paths_resolve_from_ros_package_path(tmp_path: Path, monkeypatch) -> None:
    """A copy of the URDF outside its package finds the meshes through ROS_PACKAGE_PATH."""
    copy = tmp_path / "ur5.urdf"
    copy.write_text((ROBOTS / "ur_description/urdf/ur5_robot.urdf").read_text())
    with pytest.raises(ConversionError, match="example-robot-data"):
        to_mjcf(copy)  # no package folder above tmp_path
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(ROBOTS.parent))
    assert mujoco.MjModel.from_xml_string(to_mjcf(copy)).nu == 6


def test_missing_joint_limits_name_the_setting_that_supplies_them(tmp_path: Path) -> None:
    root = ET.parse(ROBOTS / "ur_description/urdf/ur5_robot.urdf").getroot()
    elbow = next(j for j in root.findall("joint") if j.get("name") == "elbow_joint")
    for attr in ("effort", "velocity"):
        del elbow.find("limit").attrib[attr]
    path = tmp_path / "ur5_no_limits.urdf"
    ET.ElementTree(root).write(path, encoding="unicode")
    packages = {"example-robot-data": str(ROBOTS.parent)}
    with pytest.raises(ConversionError, match=r"--default-effort VALUE"):
        to_mjcf(path, package_dirs=packages)
    text = to_mjcf(path, package_dirs=packages, default_effort=28.0, default_velocity=3.15)
    model = mujoco.MjModel.from_xml_string(text)
    elbow_id = model.joint("elbow_joint").id
    assert model.jnt_actfrcrange[elbow_id].tolist() == [-28.0, 28.0]
    report = validate(
        path,
        "mujoco",
        {"example-robot-data": str(ROBOTS.parent)},
        False,
        default_limits={"effort": 28.0, "velocity": 3.15},
    )
    assert report.ok and sum("--default-" in w.problem for w in report.warnings) == 2
