"""What an engine's URDF loader reads comes from its row's reader (:mod:`mjx_arm.urdf.readers`):
a toy engine with a reader of its own gets its own static checks, under its own label, beside
the built-in engines' unchanged ones."""

from __future__ import annotations

from pathlib import Path

import pytest

from mjx_arm import engines
from mjx_arm.cli import build_parser
from mjx_arm.urdf.findings import ENGINES
from mjx_arm.urdf.readers import UrdfReader
from mjx_arm.urdf.validate import validate

# A loader that reads STL and OBJ only and jitters below 0.5 N m s/rad of damping.
TOY_READER = UrdfReader(label="Toy", mesh_formats=frozenset({".stl", ".obj"}), min_damping=0.5)

_INERTIAL = (
    '<inertial><mass value="1"/>'
    '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
)


@pytest.fixture
def toy_engine(register_engine):
    return register_engine(
        engines.EngineSpec(name="toy", label="Toy point", urdf_reader=f"{__name__}:TOY_READER")
    )


@pytest.fixture
def dae_arm(tmp_path: Path) -> Path:
    """A one-joint arm whose moving link draws a Collada mesh, with damping 0.1."""
    (tmp_path / "part.dae").write_bytes(b"")
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(
        f'<robot name="arm"><link name="base">{_INERTIAL}</link>'
        f'<link name="arm">{_INERTIAL}'
        '<visual><geometry><mesh filename="part.dae"/></geometry></visual></link>'
        '<joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/>'
        '<dynamics damping="0.1"/></joint></robot>'
    )
    return urdf


def _problems(path: Path, engine: str, **kw) -> list[str]:
    return [f.problem for f in validate(path, engine=engine, native=False, **kw).findings]


DAE_UNREAD = "has <visual> mesh 'part.dae' in format .dae, which Toy cannot read"
TOO_LITTLE = "has damping 0.1 < 0.5: Toy jitters with so little damping"


def test_a_toy_reader_reports_what_it_cannot_read_under_its_label(toy_engine, dae_arm) -> None:
    assert ENGINES["toy"] == ("toy",)
    assert ENGINES["all"] == ("mujoco", "pybullet", "toy")
    assert build_parser().parse_args(["validate", "a.urdf", "--engine", "toy"]).engine == "toy"
    assert _problems(dae_arm, "toy") == [TOO_LITTLE, DAE_UNREAD]
    everyone = _problems(dae_arm, "all")
    # MuJoCo leaves the visual out (a warning), PyBullet reads Collada: only the toy errs.
    assert DAE_UNREAD in everyone and TOO_LITTLE in everyone
    assert any("which MuJoCo cannot read: the converter leaves" in p for p in everyone)
    for engine in ("mujoco", "pybullet"):
        assert not any("Toy" in p for p in _problems(dae_arm, engine)), engine


def test_min_damping_replaces_every_readers_own(toy_engine, dae_arm) -> None:
    assert TOO_LITTLE not in _problems(dae_arm, "toy", min_damping=0.05)
    assert "has damping 0.1 < 0.2: Toy jitters with so little damping" in _problems(
        dae_arm, "toy", min_damping=0.2
    )


def test_a_removed_engine_is_no_choice_of_validate(toy_engine, dae_arm) -> None:
    engines.unregister_engine("toy")
    assert "toy" not in ENGINES and ENGINES["all"] == ("mujoco", "pybullet")
    with pytest.raises(ValueError, match="engine must be one of"):
        validate(dae_arm, engine="toy")


def test_min_damping_pybullet_still_works_and_says_it_is_deprecated(dae_arm) -> None:
    expected = "has damping 0.1 < 0.5: PyBullet jitters with so little damping"
    assert expected not in _problems(dae_arm, "pybullet")  # PyBullet's own limit is 0.01
    assert expected in _problems(dae_arm, "pybullet", min_damping=0.5)
    with pytest.warns(DeprecationWarning, match="use min_damping="):
        assert expected in _problems(dae_arm, "pybullet", min_damping_pybullet=0.5)
