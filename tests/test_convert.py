"""Tests of the URDF -> MJCF converter (:mod:`mjx_arm.urdf.convert`) on the shipped arm.

What the converter adds to MuJoCo's import (actuators, damping, armature, the ``ee`` site, the
F/T sensors, options, contact filtering, scenes) is checked on the compiled model; the physics
it is for (a tared wrench that reads zero in free motion and the contact force when pressing,
velocity tracking without chatter at the torque cap) is checked by stepping it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjx_arm.arm.config import SHIPPED_HOME_QPOS
from mjx_arm.arm.info import arm_info
from mjx_arm.arm.model_io import SensorReader
from mjx_arm.paths import default_arm_urdf
from mjx_arm.urdf import ConversionError, ConvertConfig, load_model, parse_urdf, to_mjcf
from mjx_arm.urdf.convert import EE_SITE, FT_SITE, SENSORS, TOOL_COM_SITE
from mjx_arm.urdf.kinematics import link_frames
from mjx_arm.urdf.model import RobotModel
from mjx_arm.urdf.scene import TARGET_BODY, TARGET_GEOM

URDF = default_arm_urdf()
SENSOR_DIMS = {"ee_quat": 4, "ft_quat": 4}  # every other sensor is a 3-vector
SENSOR_SITES = {  # sensor -> the site it reads (ft_quat: orientation of the F/T frame)
    "ft_force": FT_SITE,
    "ft_torque": FT_SITE,
    "tool_acc": TOOL_COM_SITE,
    "tool_gyro": FT_SITE,
    "tool_angacc": FT_SITE,
    "ft_quat": FT_SITE,
    "ee_pos": EE_SITE,
    "ee_quat": EE_SITE,
}
# MJCF text carries 6 significant digits (mj_saveXML), so values read back from the written
# file match the URDF to a relative 1e-6 (pi is written 3.14159).
XML_RTOL = 1e-5


@pytest.fixture(scope="module")
def arm() -> RobotModel:
    """The shipped arm, parsed."""
    return parse_urdf(URDF)


@pytest.fixture(scope="module")
def xml_text() -> str:
    """The shipped arm converted with default settings, as MJCF text."""
    return to_mjcf(URDF)


@pytest.fixture(scope="module")
def model(xml_text: str) -> mujoco.MjModel:
    """The model compiled from the written MJCF text."""
    return mujoco.MjModel.from_xml_string(xml_text)


@pytest.fixture(scope="module")
def touch_model() -> mujoco.MjModel:
    """The arm in the touch scene (table and box), as the task envs build it."""
    return load_model(URDF, scene="touch", self_collision=False)


def _effort(arm: RobotModel) -> np.ndarray:
    return np.array([j.limit.effort for j in arm.actuated_joints])  # type: ignore[union-attr]


def _write(root: ET.Element, path: Path) -> Path:
    ET.ElementTree(root).write(path, encoding="unicode")
    return path


def _joint_elem(root: ET.Element, name: str) -> ET.Element:
    return next(j for j in root.findall("joint") if j.get("name") == name)


# --------------------------------------------------------------------------- model contents


def test_six_velocity_actuators_sized_from_the_urdf(model: mujoco.MjModel, arm: RobotModel):
    joints = arm.actuated_joints
    assert model.nu == 6 == len(joints)
    for i, joint in enumerate(joints):
        act = model.actuator(i)
        assert act.name == joint.name
        assert model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT
        assert model.joint(int(model.actuator_trnid[i, 0])).name == joint.name
        assert model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_NONE
        assert model.actuator_gaintype[i] == mujoco.mjtGain.mjGAIN_FIXED
        assert model.actuator_biastype[i] == mujoco.mjtBias.mjBIAS_AFFINE
        kv = model.actuator_gainprm[i, 0]
        assert kv > 0
        np.testing.assert_array_equal(model.actuator_biasprm[i, :3], [0.0, 0.0, -kv])
        assert model.actuator_ctrllimited[i] and model.actuator_forcelimited[i]
        lim = joint.limit
        assert lim is not None
        np.testing.assert_allclose(
            model.actuator_ctrlrange[i], [-lim.velocity, lim.velocity], rtol=XML_RTOL
        )
        np.testing.assert_allclose(
            model.actuator_forcerange[i], [-lim.effort, lim.effort], rtol=XML_RTOL
        )


def test_urdf_damping_is_kept_and_armature_scales_with_effort(
    model: mujoco.MjModel, arm: RobotModel
):
    dofs = [model.joint(j.name).dofadr[0] for j in arm.actuated_joints]
    np.testing.assert_allclose(model.dof_damping[dofs], [2.0, 2.0, 2.0, 0.5, 0.5, 0.5])
    armature = ConvertConfig().armature_per_effort * _effort(arm)
    np.testing.assert_allclose(model.dof_armature[dofs], armature, rtol=XML_RTOL)
    assert np.all(model.dof_damping > 0)


def test_missing_or_zero_damping_gets_the_default(tmp_path: Path, arm: RobotModel):
    root = ET.parse(URDF).getroot()
    for joint in root.findall("joint"):
        dynamics = joint.find("dynamics")
        if dynamics is None:
            continue
        if joint.get("name") == "elbow_joint":
            dynamics.set("damping", "0")
        else:
            joint.remove(dynamics)
    path = _write(root, tmp_path / "undamped.urdf")
    converted = load_model(path, default_damping=0.7, armature_per_effort=0.01)
    dofs = [converted.joint(j.name).dofadr[0] for j in arm.actuated_joints]
    np.testing.assert_allclose(converted.dof_damping[dofs], 0.7)
    np.testing.assert_allclose(converted.dof_armature[dofs], 0.01 * _effort(arm))
    default = load_model(path)
    np.testing.assert_allclose(default.dof_damping[dofs], ConvertConfig().default_damping)


def test_ee_site_sits_at_the_tool_tip(model: mujoco.MjModel, arm: RobotModel):
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    site = model.site(EE_SITE).id
    assert model.body(int(model.site_bodyid[site])).name == "ee_link"
    tool = model.body("tool_link").id
    tool_pos, tool_rot = data.xpos[tool], data.xmat[tool].reshape(3, 3)
    tip = tool_rot.T @ (data.site_xpos[site] - tool_pos)  # ee point in the tool frame
    # the farthest point of the tool's collision shapes along the tool axis (z)
    reach = []
    for g in np.flatnonzero((model.geom_bodyid == tool) & (model.geom_contype > 0)):
        size = model.geom_size[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
            reach.append(model.geom_pos[g][2] + size[0])
        elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
            reach.append(model.geom_pos[g][2] + size[1] + size[0])  # capsules along z here
    np.testing.assert_allclose(tip, [0.0, 0.0, max(reach)], atol=1e-9)
    np.testing.assert_allclose(tip[2], 0.115, atol=1e-9)
    ee = link_frames(arm, np.zeros(6))["ee_link"]
    np.testing.assert_allclose(data.site_xpos[site], ee[:3, 3], atol=1e-9)


def test_sensors_are_named_and_placed(model: mujoco.MjModel):
    names = [model.sensor(i).name for i in range(model.nsensor)]
    assert names == list(SENSORS)
    for name in SENSORS:
        sensor = model.sensor(name)
        assert int(sensor.dim[0]) == SENSOR_DIMS.get(name, 3), name
        assert sensor.objtype[0] == mujoco.mjtObj.mjOBJ_SITE, name
    assert set(SENSOR_SITES) - {"ft_quat"} <= set(SENSORS)
    site_of = {name: model.site(int(model.sensor(name).objid[0])).name for name in SENSORS}
    assert site_of == {name: site for name, site in SENSOR_SITES.items() if name in SENSORS}
    # the F/T site is at the fixed ft_sensor_joint: the origin of tool_link
    ft = model.site(FT_SITE)
    assert model.body(int(ft.bodyid[0])).name == "tool_link"
    np.testing.assert_array_equal(ft.pos, 0.0)


@pytest.mark.parametrize(
    "config", [ConvertConfig(), ConvertConfig(solver_iterations=7, ls_iterations=3, sim_dt=0.002)]
)
def test_solver_options_for_mjx(config: ConvertConfig):
    converted = load_model(URDF, config)
    opt = converted.opt
    assert opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    assert opt.iterations == config.solver_iterations
    assert opt.ls_iterations == config.ls_iterations
    assert opt.timestep == pytest.approx(config.sim_dt, rel=1e-12)


def _excluded_pairs(model: mujoco.MjModel) -> set[tuple[str, str]]:
    pairs = set()
    for signature in model.exclude_signature:
        b1, b2 = int(signature) >> 16, int(signature) & 0xFFFF
        pairs.add(tuple(sorted((model.body(b1).name, model.body(b2).name))))
    return pairs  # type: ignore[return-value]


def test_neighbour_and_base_contacts_are_excluded(model: mujoco.MjModel, arm: RobotModel):
    excluded = _excluded_pairs(model)
    neighbours = {tuple(sorted((j.parent, j.child))) for j in arm.joints.values()}
    assert neighbours <= excluded
    assert ("base_link", "shoulder_link") in excluded
    # only the pair whose shapes touch at rest is added beyond the neighbours
    assert excluded - neighbours == {("wrist_1_link", "wrist_3_link")}
    # no contact in the reference and home configurations, self-collision on
    data = mujoco.MjData(model)
    for q in (np.zeros(6), np.array(SHIPPED_HOME_QPOS)):
        data.qpos[:6] = q
        mujoco.mj_forward(model, data)
        assert data.ncon == 0, q


def test_self_collision_switch_sets_the_arm_bits():
    arm_geoms = lambda m: (m.geom_contype > 0) & (m.geom_bodyid > 0)  # noqa: E731
    with_self = load_model(URDF, self_collision=True)
    assert set(with_self.geom_conaffinity[arm_geoms(with_self)]) == {3}
    without = load_model(URDF, self_collision=False)
    assert set(without.geom_conaffinity[arm_geoms(without)]) == {2}
    assert set(without.geom_contype[arm_geoms(without)]) == {1}


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("scene", ["none", "reach", "touch"])
def test_scenes_compile_and_mjx_accepts_them(scene: str):
    from mujoco import mjx

    converted = load_model(URDF, scene=scene)
    assert mjx.put_model(converted).nu == 6
    body_names = {converted.body(i).name for i in range(converted.nbody)}
    geom_names = {converted.geom(i).name for i in range(converted.ngeom)}
    if scene == "none":
        assert TARGET_BODY not in body_names
        return
    target = converted.body(TARGET_BODY).id
    assert converted.body_mocapid[target] >= 0
    if scene == "touch":
        box = converted.geom(TARGET_GEOM)
        assert int(box.bodyid[0]) == target
        assert box.type[0] == mujoco.mjtGeom.mjGEOM_BOX
    else:
        assert TARGET_GEOM not in geom_names


def test_conversion_is_byte_identical_and_the_text_compiles(xml_text: str, arm: RobotModel):
    assert to_mjcf(URDF).encode() == xml_text.encode()
    assert to_mjcf(URDF, scene="touch") == to_mjcf(URDF, scene="touch")
    from_text = mujoco.MjModel.from_xml_string(xml_text)
    direct = load_model(URDF)
    for size in ("nq", "nv", "nu", "nbody", "ngeom", "nsite", "nsensor", "nexclude"):
        assert getattr(from_text, size) == getattr(direct, size), size
    # the text carries 6 significant digits; kinematics agree to well below a millimetre
    data_text, data_direct = mujoco.MjData(from_text), mujoco.MjData(direct)
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, 6)
        data_text.qpos[:6] = data_direct.qpos[:6] = q
        mujoco.mj_kinematics(from_text, data_text)
        mujoco.mj_kinematics(direct, data_direct)
        np.testing.assert_allclose(data_text.site_xpos, data_direct.site_xpos, atol=1e-5)


# --------------------------------------------------------------------------- error handling


def test_zero_joint_axis_is_a_conversion_error(tmp_path: Path):
    root = ET.parse(URDF).getroot()
    _joint_elem(root, "elbow_joint").find("axis").set("xyz", "0 0 0")  # type: ignore[union-attr]
    path = _write(root, tmp_path / "zero_axis.urdf")
    for convert in (to_mjcf, load_model):
        with pytest.raises(ConversionError) as info:
            convert(path)
        message = str(info.value)
        assert str(path) in message
        assert "axis too small" in message and "elbow_joint" in message  # MuJoCo's own text


def test_corrupt_mesh_is_a_conversion_error(tmp_path: Path):
    (tmp_path / "broken.stl").write_bytes(b"not an stl file at all")
    root = ET.parse(URDF).getroot()
    link = next(x for x in root.findall("link") if x.get("name") == "forearm_link")
    geometry = link.find("collision/geometry")
    assert geometry is not None
    geometry.clear()
    ET.SubElement(geometry, "mesh", {"filename": "broken.stl"})
    path = _write(root, tmp_path / "corrupt_mesh.urdf")
    with pytest.raises(ConversionError) as info:
        to_mjcf(path)
    message = str(info.value)
    assert str(path) in message
    assert "broken.stl" in message and "STL" in message  # MuJoCo's decoder message


@pytest.fixture(scope="module")
def panda_urdf() -> Path:
    """The Franka Panda of pybullet_data: a parallel gripper with a ``<mimic>`` finger."""
    pybullet_data = pytest.importorskip("pybullet_data")
    return Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"


@pytest.mark.filterwarnings("ignore::UserWarning")  # the Panda's OBJ texture coordinates
def test_mimic_joint_gets_no_actuator(panda_urdf: Path):
    panda = parse_urdf(panda_urdf)
    assert panda.joints["panda_finger_joint2"].mimic == "panda_finger_joint1"
    assert panda.joints["panda_finger_joint1"].mimic is None
    converted = load_model(panda_urdf)
    names = [converted.actuator(i).name for i in range(converted.nu)]
    assert names == [j.name for j in panda.actuated_joints if j.mimic is None]
    assert "panda_finger_joint2" not in names and converted.nu == 8
    # MuJoCo's importer couples the fingers with a joint equality
    assert converted.neq == 1 and converted.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT
    coupled = {
        converted.joint(int(converted.eq_obj1id[0])).name,
        converted.joint(int(converted.eq_obj2id[0])).name,
    }
    assert coupled == {"panda_finger_joint1", "panda_finger_joint2"}
    assert converted.dof_damping[converted.joint("panda_finger_joint2").dofadr[0]] > 0
    # driving the first finger moves the second with it
    data = mujoco.MjData(converted)
    finger = converted.actuator("panda_finger_joint1").id
    for ctrl in (0.05, 0.0):
        data.ctrl[finger] = ctrl
        mujoco.mj_step(converted, data, nstep=60)
    q1 = data.qpos[converted.joint("panda_finger_joint1").qposadr[0]]
    q2 = data.qpos[converted.joint("panda_finger_joint2").qposadr[0]]
    assert q1 > 0.005
    assert abs(q1 - q2) < 1e-3


# --------------------------------------------------------------------------- physics


def _settle_at_home(model: mujoco.MjModel, reader: SensorReader) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[reader.qpos_adr] = SHIPPED_HOME_QPOS
    mujoco.mj_forward(model, data)
    return data


def _far_target(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    data.mocap_pos[model.body_mocapid[model.body(TARGET_BODY).id]] = [0.5, 0.6, 0.0]
    mujoco.mj_forward(model, data)


def _free_motion_wrenches(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Tared wrenches at rest (0.5 s) and under random velocity steps (0.5 s), ``(n, 6)`` each."""
    reader = SensorReader(model, arm_info())
    data = _settle_at_home(model, reader)
    _far_target(model, data)
    rest = []
    for _ in range(120):
        mujoco.mj_step(model, data)
        rest.append(reader.wrench(np, data.sensordata))
    rng = np.random.default_rng(0)
    moving = []
    v_max = arm_info().v_max
    for _ in range(4):
        data.ctrl[reader.actuators] = rng.uniform(-0.5, 0.5, 6) * v_max
        for _ in range(30):
            mujoco.mj_step(model, data)
            assert data.ncon == 0
            moving.append(reader.wrench(np, data.sensordata))
    assert np.abs(data.qvel[reader.dof_adr]).max() > 0.5  # it did move
    return np.array(rest), np.array(moving)


def test_tared_wrench_reads_zero_at_rest_and_in_free_motion(touch_model):
    rest, moving = _free_motion_wrenches(touch_model)
    assert np.abs(rest).max() < 1e-6  # measured: 2e-16 N and N m
    assert np.abs(moving[:, :3]).max() < 1e-6  # measured: 1.7e-11 N
    # measured: 1.1e-12 N m (0.035 N m while tool_angacc, a world-frame sensor, was read as if
    # it were in the sensor frame)
    assert np.abs(moving[:, 3:]).max() < 1e-6


@pytest.mark.parametrize("push", [5.0, 20.0, 45.0])
def test_pressing_the_box_reads_the_contact_force(touch_model: mujoco.MjModel, push: float):
    model = touch_model
    reader = SensorReader(model, arm_info())
    data = _settle_at_home(model, reader)
    box_body = model.body(TARGET_BODY).id
    # the box's top face 2 mm under the tool tip
    data.mocap_pos[model.body_mocapid[box_body]] = data.site_xpos[reader.ee_site] - [0, 0, 0.052]
    mujoco.mj_forward(model, data)
    tool_geoms = set(np.flatnonzero(model.geom_bodyid == model.body("tool_link").id))
    box_geom = model.geom(TARGET_GEOM).id
    kv = model.actuator_gainprm[reader.actuators, 0]
    jacp = np.zeros((3, model.nv))
    for _ in range(240):  # 1 s: joint torques J^T f push the tip down with |f| = push
        mujoco.mj_jacSite(model, data, jacp, None, reader.ee_site)
        torque = jacp[:, reader.dof_adr].T @ np.array([0.0, 0.0, -push])
        data.ctrl[reader.actuators] = torque / kv
        mujoco.mj_step(model, data)
    normal = 0.0
    assert data.ncon >= 1
    for i in range(data.ncon):
        contact = data.contact[i]
        assert {contact.geom1, contact.geom2} <= tool_geoms | {box_geom}, "unexpected contact"
        force = np.zeros(6)
        mujoco.mj_contactForce(model, data, i, force)
        normal += force[0]
    wrench = reader.wrench(np, data.sensordata)
    force_norm = float(np.linalg.norm(wrench[:3]))
    # measured: relative difference 2.3e-8 to 2.8e-8 after 1 s
    assert force_norm == pytest.approx(normal, rel=1e-6)
    assert normal == pytest.approx(push, rel=0.01)
    assert wrench[2] < -0.99 * force_norm  # pushes back along -z of the ee frame (tool axis)


def _zigzag(v: np.ndarray) -> float:
    """Largest sign-alternating step of a velocity trace ``(n,)``: 0 for a monotone one."""
    dv = np.diff(v)
    flips = dv[:-1] * dv[1:] < 0
    amplitude = np.minimum(np.abs(dv[:-1]), np.abs(dv[1:]))
    return float((amplitude * flips).max(initial=0.0))


def _step_responses(model: mujoco.MjModel, joint: int, sign: float) -> tuple[np.ndarray, int]:
    """Joint velocities ``(120, 6)`` under a +-1 rad/s step then its reversal; capped substeps."""
    data = mujoco.MjData(model)
    data.qpos[:6] = SHIPPED_HOME_QPOS
    mujoco.mj_forward(model, data)
    trace, capped = [], 0
    for target in (sign, -sign):
        data.ctrl[:] = 0.0
        data.ctrl[joint] = target
        for _ in range(60):
            mujoco.mj_step(model, data)
            trace.append(data.qvel[:6].copy())
            capped += abs(data.actuator_force[joint]) >= model.actuator_forcerange[joint, 1] - 1e-9
    return np.array(trace), capped


@pytest.mark.parametrize("joint", range(6))
def test_velocity_steps_do_not_chatter_at_the_torque_cap(joint: int):
    model = load_model(URDF)
    for sign in (1.0, -1.0):
        trace, capped = _step_responses(model, joint, sign)
        assert capped > 0  # the step saturates the actuator for a few substeps
        v = trace[:, joint]
        worst = max(_zigzag(v[10:60]), _zigzag(v[70:]))
        assert worst < 0.05  # measured: 1.1e-4 rad/s at most
        assert abs(v[59] - sign) < 0.03  # damping keeps it 0.6 % to 1.5 % under the target
        assert abs(v[-1] + sign) < 0.03


def test_chatter_detector_sees_an_overtuned_gain():
    # kv * dt / I > 1 on the wrist_3 joint, whose inertia does not change with the pose: the
    # capped servo overshoots on the reversal and chatters (measured: 0.81 rad/s)
    model = load_model(URDF, kv_factor=3.0)
    trace, _ = _step_responses(model, 5, 1.0)
    assert _zigzag(trace[70:, 5]) > 0.05
