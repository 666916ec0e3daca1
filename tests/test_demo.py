"""``mjx-arm demo --quick`` end to end (about 40-60 s on a 2-core CPU)."""

from __future__ import annotations

import json
from pathlib import Path

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
