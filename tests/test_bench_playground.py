"""The Playground comparison's robot files: placeholder meshes stand in only where they cannot
change the physics (no MuJoCo Playground needed)."""

from __future__ import annotations

import mujoco
import pytest

from benchmarks.bench_playground_pick import check_meshes_inert, prepare_menagerie

ARM = """<mujoco model="two links">
  <compiler meshdir="assets"/>
  <asset><mesh name="shell" file="shell.obj"/><mesh name="core" file="core.stl"/></asset>
  <worldbody>
    <body name="link1">
      <inertial mass="1" pos="0 0 0.1" diaginertia="0.01 0.01 0.01"/>
      <joint name="j1" axis="0 0 1"/>
      <geom type="mesh" mesh="shell" contype="0" conaffinity="0"/>
      <body name="link2" pos="0 0 0.2">
        <inertial mass="0.5" pos="0 0 0.1" diaginertia="0.005 0.005 0.005"/>
        <joint name="j2" axis="0 1 0"/>
        <geom type="mesh" mesh="core" contype="{contype}" conaffinity="0"/>
        <geom name="pad" type="box" size="0.01 0.01 0.01"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _laid_out(tmp_path, contype: int):
    source = tmp_path / "panda"
    source.mkdir()
    (source / "mjx_panda.xml").write_text(ARM.format(contype=contype))
    made = prepare_menagerie(source, tmp_path / "menagerie")
    target = tmp_path / "menagerie" / "franka_emika_panda"
    return made, mujoco.MjModel.from_xml_path(str(target / "mjx_panda.xml"))


def test_missing_meshes_get_placeholders_that_load(tmp_path):
    made, model = _laid_out(tmp_path, contype=0)
    assert sorted(made) == ["core.stl", "shell.obj"]
    assert model.nmesh == 2
    check_meshes_inert(model)  # visual-only meshes, stated inertias: nothing raised
    # stated inertias are kept whatever the mesh (placeholders change no mass)
    assert model.body_mass[1:].tolist() == pytest.approx([1.0, 0.5], abs=1e-12)


def test_a_colliding_mesh_is_refused(tmp_path):
    _, model = _laid_out(tmp_path, contype=1)
    with pytest.raises(RuntimeError, match="collides"):
        check_meshes_inert(model)
