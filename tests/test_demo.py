"""``mjx-arm demo --quick`` end to end (about 40-60 s on a 2-core CPU)."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import pytest

from mjx_arm.cli import EXIT_INVALID, EXIT_OK, main
from mjx_arm.replay import rendering_available


@pytest.mark.slow
def test_demo_quick_end_to_end(tmp_path: Path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == EXIT_OK
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["quick"] and "demo done" in printed
    for name in ("ur5e_touch.xml", "policy.npz", "replay.png", "trajectory_mujoco.npz"):
        assert (out / name).is_file(), name
        assert name in printed
    assert set(summary["eval"]) == {"mujoco", "pybullet", "batch"}
    for result in summary["eval"].values():
        low, high = result["success_ci95"]
        assert 0.0 <= low <= result["success_rate"] <= high <= 1.0
        assert result["episodes"] == 20
        assert Path(result["json"]).is_file()
    if "onnx" in summary["export"]:
        assert summary["export"]["npz_vs_onnx_max_abs_diff"] < 1e-5
    video = summary["eval"]["mujoco"]["video"]
    assert (video is not None) == rendering_available()[0]
    if video is not None:
        assert Path(video).stat().st_size > 0


def test_demo_refuses_a_folder_with_a_run(tmp_path: Path, capsys):
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == EXIT_INVALID
    assert "already holds a demo run" in capsys.readouterr().err


def test_demo_converts_the_arm_it_is_given(tmp_path: Path):
    from mjx_arm.demo import validate_and_convert
    from mjx_arm.paths import asset
    from mjx_arm.urdf.arm_config import load_arm

    lines: list[str] = []
    result = validate_and_convert(tmp_path, lines.append, load_arm(asset("ur5e_gripper.urdf")))
    mjcf = tmp_path / "ur5e_gripper_touch.xml"
    assert result["mjcf"] == str(mjcf)
    model = mujoco.MjModel.from_xml_path(str(mjcf))
    assert model.nu == 7  # six arm joints and the driven finger
    assert model.body("target").id > 0  # the Touch scene
    assert "0 errors" in lines[0]


def test_demo_names_an_arm_it_cannot_load(tmp_path: Path, capsys):
    missing = tmp_path / "missing.toml"
    assert main(["demo", "--quick", "--out", str(tmp_path / "o"), "--arm", str(missing)]) == (
        EXIT_INVALID
    )
    assert "no such URDF or arm file" in capsys.readouterr().err
    (tmp_path / "bad.toml").write_text('urdf = "nothere.urdf"\n')
    arm = str(tmp_path / "bad.toml")
    assert main(["demo", "--quick", "--out", str(tmp_path / "o2"), "--arm", arm]) == EXIT_INVALID
    assert "urdf 'nothere.urdf'" in capsys.readouterr().err  # named before any work


@pytest.mark.slow
def test_demo_quick_on_another_arm(tmp_path: Path):
    from mjx_arm.paths import asset
    from mjx_arm.policy import load as load_policy

    out = tmp_path / "demo"
    arm = str(asset("ur5e_gripper.urdf"))
    assert main(["demo", "--quick", "--out", str(out), "--arm", arm]) == EXIT_OK
    summary = json.loads((out / "summary.json").read_text())
    assert summary["arm"] == arm
    recorded = load_policy(out / "policy.npz").metadata["arm"]  # the policy records its arm
    assert Path(recorded["config"]["urdf"]).name == "ur5e_gripper.urdf"
    assert set(summary["eval"]) == {"mujoco", "pybullet", "batch"}
