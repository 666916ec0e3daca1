"""``mjx-arm demo --quick`` end to end (about 40-60 s on a 2-core CPU)."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import pytest

from mjx_arm.cli import EXIT_INVALID, EXIT_OK, build_parser, main
from mjx_arm.replay import rendering_available


@pytest.mark.slow
def test_demo_quick_end_to_end(tmp_path: Path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == EXIT_OK
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["quick"] and "demo done" in printed
    for name in ("ur5e_reach.xml", "policy.npz", "replay.png", "trajectory_mujoco.npz"):
        assert (out / name).is_file(), name
        assert name in printed
    assert set(summary["eval"]) == {"mujoco", "pybullet", "mjx"}
    for result in summary["eval"].values():
        low, high = result["success_ci95"]
        assert 0.0 <= low <= result["success_rate"] <= high <= 1.0
        assert result["episodes"] == 20
        assert Path(result["json"]).is_file()
    assert json.loads((out / "eval_mjx.json").read_text())["engine"] == "mjx"
    backend = summary["eval"]["mjx"]["backend"]  # mujoco on a CPU, mjx on a GPU
    assert f"mjx (backend {backend})" in printed  # one name for the engine and its backend
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


def test_demo_writes_the_model_of_the_task_it_trains(tmp_path: Path):
    """The MJCF is named after the task the demo trains and holds that task's model."""
    from mjx_arm.arm.config import load_arm
    from mjx_arm.demo import TASK, validate_and_convert
    from mjx_arm.envs.mujoco_env import MujocoArmEnv
    from mjx_arm.paths import asset
    from mjx_arm.task.config import task_config

    arm = load_arm(asset("ur5e_gripper.urdf"))
    lines: list[str] = []
    result = validate_and_convert(tmp_path, lines.append, arm)
    mjcf = tmp_path / f"ur5e_gripper_{TASK}.xml"
    assert TASK == "reach" and result["mjcf"] == str(mjcf)
    model = mujoco.MjModel.from_xml_path(str(mjcf))
    env = MujocoArmEnv(task_config(TASK), arm)  # the model the Reach envs build
    try:
        trained = env.model
        assert (model.nbody, model.nu, model.ngeom) == (trained.nbody, trained.nu, trained.ngeom)
        # the MJCF text keeps six significant digits
        assert model.opt.timestep == pytest.approx(trained.opt.timestep, rel=1e-6)
    finally:
        env.close()
    assert model.nu == 7  # six arm joints and the driven finger
    assert "0 errors" in lines[0] and "Reach's model" in lines[1]


def test_demo_summary_names_each_engine_with_its_backend():
    """The closing table names the batched env ``mjx (backend B)``; the CPU engines alone."""
    from mjx_arm.demo import format_demo_summary
    from mjx_arm.evaluate import format_summary

    def result(engine: str, **extra) -> dict:
        return {
            "engine": engine, "task": "reach", "episodes": 4, "wall_seconds": 1.0,
            "success_rate": 0.5, "success_ci95": [0.1, 0.9], "mean_return": -3.0,
            "mean_steps_to_success": None, "mean_peak_contact_force": 0.0,
            "json": f"eval_{engine}.json", "video": None, "notes": [], **extra,
        }  # fmt: skip

    summary = {
        "out": "o", "wall_seconds": 9.0, "timings_s": {"train": 5.0},
        "urdf": {"mjcf": "o/ur5e_reach.xml"}, "train": {"run_dir": "o/run"},
        "export": {"npz": "o/policy.npz"}, "replay": {"trajectory": "t.npz", "plot": "r.png"},
        "eval": {"mujoco": result("mujoco"), "mjx": result("mjx", backend="mujoco")},
    }  # fmt: skip
    table = format_demo_summary(summary).splitlines()
    assert any(line.startswith("mjx (backend mujoco) ") for line in table)
    assert any(line.startswith("mujoco ") for line in table)
    assert "MJCF (reach model)" in "\n".join(table)
    first = format_summary(result("mjx", backend="mujoco")).splitlines()[0]
    assert first == "mjx (backend mujoco), task reach: 4 episodes in 1.0 s"


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
    assert set(summary["eval"]) == {"mujoco", "pybullet", "mjx"}


def test_demo_takes_the_repair_flags(tmp_path: Path, capsys):
    """A URDF that needs --repair-inertia: the demo names the flag, takes it, and its first
    step then validates the repaired arm and writes its model."""
    from test_repairs import _broken_urdf

    from mjx_arm.arm.config import load_arm
    from mjx_arm.demo import validate_and_convert

    urdf = _broken_urdf(tmp_path)
    assert main(["demo", "--quick", "--out", str(tmp_path / "o"), "--arm", str(urdf)]) == (
        EXIT_INVALID
    )
    assert "--repair-inertia" in capsys.readouterr().err
    args = build_parser().parse_args(["demo", "--arm", str(urdf), "--repair-inertia"])
    assert args.repair_inertia
    lines: list[str] = []
    arm = load_arm(urdf).replace(repair_inertia=True)  # what cmd_demo hands run_demo
    result = validate_and_convert(tmp_path / "o", lines.append, arm)
    assert "0 errors" in lines[0] and Path(result["mjcf"]).is_file()


@pytest.mark.parametrize("name", ["ur5e_reach.xml", "replay.png", "policy.npz"])
def test_demo_never_replaces_a_file_it_did_not_write(tmp_path: Path, name: str, capsys):
    mine = tmp_path / name
    mine.write_bytes(b"the user's own file")
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == EXIT_INVALID
    err = capsys.readouterr().err
    assert f"holds {name}, which the demo would replace and did not write" in err
    assert "pass a fresh folder with --out" in err
    assert mine.read_bytes() == b"the user's own file"


def test_demo_takes_a_folder_of_other_files_and_marks_it(tmp_path: Path):
    from mjx_arm.demo import MARKER, claim_out

    (tmp_path / "notes.txt").write_text("mine")
    claim_out(tmp_path, "ur5e")  # no name the demo writes: taken
    assert (tmp_path / MARKER).is_file()
    (tmp_path / "replay.png").write_bytes(b"from an earlier demo")  # the demo's own folder
    claim_out(tmp_path, "ur5e")
