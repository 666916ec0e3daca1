"""The table and box contact scaled by the arm's tool mass (:mod:`pybullet_ref.tool_contact`)."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import pytest

from mjx_arm.arm.info import arm_info
from pybullet_ref.contact import RIGID, SOFT, SceneContact
from pybullet_ref.tool_contact import arm_contact, tool_mass

pytestmark = pytest.mark.pybullet

ROBOTS = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
XARM7 = ROBOTS / "xarm_description/urdf/xarm7.urdf"


def test_the_shipped_arm_keeps_the_calibrated_contact():
    assert arm_contact("soft", arm_info()) == SOFT
    assert arm_contact(SOFT, arm_info()) == SOFT


def test_a_given_contact_is_kept_on_any_arm():
    arm = arm_info(XARM7) if XARM7.is_file() else arm_info()
    assert arm_contact("rigid", arm) == RIGID
    given = SceneContact.parse("2e4:100/3e3:100")
    assert arm_contact("2e4:100/3e3:100", arm) == given


@pytest.mark.skipif(not XARM7.is_file(), reason="example-robot-data not installed")
def test_a_lighter_arm_gets_a_softer_table_and_box():
    """The xArm7's tool (3.9 kg at its Touch home, measured) against the shipped arm's 5.2 kg:
    spring and damper scale by the same ratio (within 1e-9), the cube keeps its values."""
    xarm, shipped = arm_info(XARM7), arm_info()
    ratio = tool_mass(xarm) / tool_mass(shipped)
    assert 3.5 < tool_mass(xarm) < 4.3 and 4.8 < tool_mass(shipped) < 5.5
    contact = arm_contact("soft", xarm)
    assert contact.fixed.stiffness == pytest.approx(SOFT.fixed.stiffness * ratio, rel=1e-9)
    assert contact.fixed.damping == pytest.approx(SOFT.fixed.damping * ratio, rel=1e-9)
    assert contact.cube == SOFT.cube


def test_a_smaller_cube_gets_a_stiffer_spring():
    """The SO-101 holds a cube of half the shipped edge: its spring is 4x the calibrated one
    (the jaw sank 6-8 mm into it and knocked the cube away), its damper and the table's are
    unchanged by the cube; the shipped size (0, or 1) keeps the calibration."""
    shipped = arm_info()
    assert arm_contact("soft", shipped, 0.0) == SOFT
    assert arm_contact("soft", shipped, 1.0) == SOFT
    half = arm_contact("soft", shipped, 0.5)
    assert half.cube.stiffness == pytest.approx(4.0 * SOFT.cube.stiffness, rel=1e-12)
    assert half.cube.damping == SOFT.cube.damping and half.fixed == SOFT.fixed
    assert arm_contact("rigid", shipped, 0.5) == RIGID  # a named contact is kept as given
