"""MuJoCo Warp's buffer bounds (mjx_arm/envs/warp_buffers.py), computed on the CPU without Warp."""

from __future__ import annotations

import mujoco
import pytest

from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.envs.warp_buffers import (
    DROPPED_BITS,
    convex_pair_count,
    model_bounds,
    overflow_message,
)
from mjx_arm.inputs import ConfigError

TETRA = 'vertex="0 0 0  0.05 0 0  0 0.05 0  0 0 0.05"'


def _model(bodies: str, extra: str = "") -> mujoco.MjModel:
    xml = f"""<mujoco>
      <asset><mesh name="tetra" {TETRA}/></asset>
      <worldbody>
        <geom name="floor" type="plane" size="1 1 0.1"/>
        {bodies}
      </worldbody>
      {extra}
    </mujoco>"""
    return mujoco.MjModel.from_xml_string(xml)


def _free(name: str, geoms: str, z: float) -> str:
    return f'<body name="{name}" pos="0 0 {z}"><freejoint/>{geoms}</body>'


MESH = '<geom type="mesh" mesh="tetra"/>'
BOX = '<geom type="box" size="0.02 0.02 0.02"/>'
CAPSULE = '<geom type="capsule" size="0.01 0.02"/>'


def test_counts_the_most_common_convex_type_pair():
    """Three free meshes make 3 mesh-mesh pairs; with one box, 3 box-mesh pairs; the plane's
    pairs and box-capsule (primitive colliders) do not count."""
    meshes = "".join(_free(f"m{i}", MESH, 0.1 * (i + 1)) for i in range(3))
    assert convex_pair_count(_model(meshes)) == 3
    with_box = meshes + _free("box", BOX, 0.5) + _free("cap", CAPSULE, 0.6)
    assert convex_pair_count(_model(with_box)) == 3  # mesh-mesh 3, box-mesh 3, capsule-mesh 3
    four = with_box + _free("m3", MESH, 0.7)
    assert convex_pair_count(_model(four)) == 6  # mesh-mesh: 4 choose 2
    primitives = _free("box", BOX, 0.5) + _free("cap", CAPSULE, 0.6)
    assert convex_pair_count(_model(primitives)) == 0


def test_filtered_pairs_do_not_count():
    """An <exclude> and contype/conaffinity that never match remove pairs from the bound."""
    meshes = "".join(_free(f"m{i}", MESH, 0.1 * (i + 1)) for i in range(3))
    excluded = _model(meshes, '<contact><exclude body1="m0" body2="m1"/></contact>')
    assert convex_pair_count(excluded) == 2
    silent = _free("m0", '<geom contype="0" conaffinity="0" type="mesh" mesh="tetra"/>', 0.1)
    silent += "".join(_free(f"m{i}", MESH, 0.1 * (i + 1)) for i in (1, 2))
    assert convex_pair_count(_model(silent)) == 1


def test_bounds_of_a_mesh_model_and_the_shipped_touch_scene():
    """A model's convex pairs never exceed its contacts; the shipped Touch scene has none (its
    box-box pairs go to the box-box collider), so Warp's convex scratch stays one row per env."""
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.task import touch_config

    meshes = "".join(_free(f"m{i}", MESH, 0.1 * (i + 1)) for i in range(3))
    bounds = model_bounds(_model(meshes))
    assert 0 < bounds.convex_pairs <= bounds.contacts
    env = make_batched_env(touch_config(), "mujoco", None, 1)
    touch = model_bounds(env.physics.mj_model)
    assert (touch.contacts, touch.convex_pairs) == (44, 0)


def test_setting_overflow_bit_and_message():
    """The convex collider's overflow (Warp's CCD bit, 16) counts as dropped contacts, the error
    names the setting, and the setting is range-checked."""
    assert DROPPED_BITS & 16
    text = overflow_message(3, {"naconmax_per_env": 44, "njmax": 182, "naccdmax_per_env": 2})
    assert "naccdmax_per_env=2" in text and "physics.naccdmax_per_env=N" in text
    assert PhysicsConfig(naccdmax_per_env=8).naccdmax_per_env == 8
    with pytest.raises(ConfigError, match=r"physics\.naccdmax_per_env"):
        PhysicsConfig(naccdmax_per_env=-1)
