"""``mjx-arm bench parity`` and ``mjx-arm bench transfer`` (:mod:`mjx_arm.bench`).

The quick parity run compares C MuJoCo and PyBullet in seconds; the run with MJX (minutes of
compilation on a CPU) is marked slow. Tolerances are about 2-10x the figures measured on the
shipped arm (mujoco 4.0.0, mujoco-mjx 3.17.0, pybullet 3.2.7), stated beside each assertion.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_policy import trained_run_dir

from mjx_arm.bench.engines import Trace
from mjx_arm.bench.parity import ParityConfig
from mjx_arm.bench.parity_figures import (
    check_goals,
    curve_stats,
    jitter_figures,
    joint_divergence,
)
from mjx_arm.bench.settings import add_arguments, from_arguments
from mjx_arm.bench.transfer import TransferConfig, plan_engines
from mjx_arm.cli import EXIT_INVALID, EXIT_OK, main

ROOT = Path(__file__).resolve().parents[1]
PARITY_PLOTS = tuple(f"parity_{p}.png" for p in ("divergence", "press", "jitter"))
SIM_DT = 1.0 / 240.0


def _trace(qpos: np.ndarray, qvel: np.ndarray | None = None) -> Trace:
    runs, steps, _ = qpos.shape
    qvel = np.zeros_like(qpos) if qvel is None else qvel
    return Trace(qpos, qvel, np.zeros((runs, steps, 3)), np.zeros((runs, steps, 6)))


# --------------------------------------------------------------------------- figures


def test_joint_divergence_wraps_angles():
    """pi - 0.01 against -pi + 0.01 is 0.02 rad apart, not 2 pi - 0.02."""
    a = np.zeros((1, 2, 6))
    b = np.zeros((1, 2, 6))
    a[0, 0, 3], b[0, 0, 3] = math.pi - 0.01, -math.pi + 0.01
    a[0, 1, 1] = 0.3
    np.testing.assert_allclose(joint_divergence(_trace(a), _trace(b)), [[0.02, 0.3]], atol=1e-12)


def test_curve_stats_hand_worked():
    values = np.arange(20.0).reshape(10, 2)  # column 0: 0, 2, ..., 18; column 1: 1, 3, ..., 19
    stats = curve_stats(values, index=1)
    np.testing.assert_allclose(stats["median"], [9.0, 10.0])
    assert stats["at_goal_median"] == 10.0 and stats["final_median"] == 10.0
    assert stats["at_goal_p95"] == pytest.approx(18.1)  # numpy's linear interpolation
    assert stats["max"] == 19.0


def test_jitter_figures_of_a_sine():
    """A joint velocity ``A sin(w t)``: its differences over ``dt`` have a std of
    ``A g / sqrt(2)``, with the finite difference's gain ``g = 2 sin(w dt / 2) / dt``."""
    t = np.arange(960) * SIM_DT
    amp, omega = 0.01, 2 * np.pi * 60.0  # 60 Hz: above the 30 Hz control rate
    qvel = np.zeros((1, len(t), 6))
    qvel[0, :, 2] = amp * np.sin(omega * t)
    out = jitter_figures(_trace(np.zeros_like(qvel), qvel), SIM_DT, window=2.0, smooth=8)
    gain = 2.0 * math.sin(omega * SIM_DT / 2) / SIM_DT  # 0.90 w at 60 Hz
    assert out["acc_std_max"] == pytest.approx(amp * gain / math.sqrt(2), rel=0.01)
    assert out["hf_vel_rms_max"] == pytest.approx(amp / math.sqrt(2), rel=0.1)
    assert out["acc_std"].shape == (1, 6) and np.all(out["acc_std"][0, [0, 1, 3, 4, 5]] == 0)


def test_goals_name_a_cause_when_missed():
    config = ParityConfig.quick()
    stats = {"at_goal_median": 0.02}
    figures = {
        "fk_m": {"mujoco vs mjx-jax": 2e-6},
        "open_loop": {"pairs": {"mujoco vs mjx-jax": stats, "mujoco vs pybullet": stats}},
        "press": {"engines": {"mujoco": {"steady_n": np.array([20.0, 60.0])}}},
    }
    goals = {
        (g["check"].split(",")[0], g["subject"]): g for g in check_goals(figures, config, (1, 50))
    }
    assert not goals["forward kinematics", "mujoco vs mjx-jax"]["met"]
    assert "float32" in goals["forward kinematics", "mujoco vs mjx-jax"]["cause"]
    assert not goals["joint divergence at 1 s", "mujoco vs mjx-jax"]["met"]  # goal 1e-2
    assert goals["joint divergence at 1 s", "mujoco vs pybullet"]["met"]  # goal 5e-2
    press = goals["steady press force in the Touch band", "mujoco"]
    assert not press["met"] and press["value"] == [20.0, 60.0] and press["cause"]


def test_config_rejects_bad_settings():
    with pytest.raises(ValueError, match="engines"):
        ParityConfig(engines=("gazebo",))
    with pytest.raises(ValueError, match="two engines"):
        ParityConfig(engines=("mujoco",))
    with pytest.raises(ValueError, match="goal_time"):
        ParityConfig(seconds=0.5, goal_time=1.0)
    with pytest.raises(ValueError, match="engines"):
        TransferConfig(engines=())


def test_flags_come_from_the_config():
    parser = argparse.ArgumentParser()
    add_arguments(parser, ParityConfig)
    args = parser.parse_args(["--press-boxes", "99"])
    with pytest.raises(ValueError, match="press_boxes"):
        from_arguments(ParityConfig(), args)
    args = parser.parse_args(["--sequences", "7", "--engines", "mujoco", "mjx", "--seconds", "1.5"])
    config = from_arguments(ParityConfig.quick(), args)
    assert config.sequences == 7 and config.engines == ("mujoco", "mjx")
    assert config.seconds == 1.5 and config.press_boxes == ParityConfig.quick().press_boxes


def test_transfer_plan_without_a_gpu():
    keys, notes = plan_engines(TransferConfig(), "cpu")
    assert keys == ["batch", "mujoco", "pybullet"] and "MJX skipped" in notes[0]
    keys, _ = plan_engines(TransferConfig(engines=("mjx", "batch")), "cpu")
    assert keys == ["batch"]
    assert plan_engines(TransferConfig(), "gpu") == (["mjx", "mujoco", "pybullet"], [])
    assert plan_engines(TransferConfig(mjx_on_cpu=True), "cpu")[0][0] == "mjx"


# --------------------------------------------------------------------------- parity runs


def _run_parity(folder: Path, *extra: str) -> dict:
    """A quick parity run into ``folder``: the JSON and markdown there, and with ``--plot`` the
    three PNGs, and nothing else."""
    assert main(["bench", "parity", "--quick", "--out", str(folder), *extra]) == EXIT_OK
    plots = PARITY_PLOTS if "--plot" in extra else ()
    assert sorted(p.name for p in folder.iterdir()) == sorted(["parity.md", "parity.json", *plots])
    for name in plots:
        assert (folder / name).stat().st_size > 0, name
    return json.loads((folder / "parity.json").read_text())


def _results_pictures() -> set[Path]:
    """Every picture, video or log under the repository's ``benchmarks/results``."""
    kinds = ("*.png", "*.mp4", "*.gif", "*.log")
    return {p for kind in kinds for p in (ROOT / "benchmarks" / "results").rglob(kind)}


def _check_shapes(result: dict, config: ParityConfig) -> None:
    steps = round(config.seconds * 30)
    ol = result["figures"]["open_loop"]
    assert len(ol["time_s"]) == steps and ol["sequences"] == config.sequences
    for stats in ol["pairs"].values():
        for key in ("median", "p95"):
            assert len(stats[key]) == steps and np.isfinite(stats[key]).all()
    for press in result["figures"]["press"]["engines"].values():
        assert np.shape(press["force_n"]) == (config.press_boxes, round(config.press_seconds * 30))


@pytest.mark.pybullet
def test_quick_parity_mujoco_and_pybullet(tmp_path: Path):
    """Its plots go to the folder given, never under ``benchmarks/results``."""
    before = _results_pictures()
    result = _run_parity(tmp_path, "--engines", "mujoco", "pybullet", "--plot")
    assert _results_pictures() == before
    config = ParityConfig.quick(engines=("mujoco", "pybullet"))
    assert result["config"] == json.loads(json.dumps(config.to_dict()))
    _check_shapes(result, config)
    figures = result["figures"]
    assert figures["fk_m"]["mujoco vs pybullet"] < 1e-7  # measured 1.5e-8 m
    pair = figures["open_loop"]["pairs"]["mujoco vs pybullet"]
    assert pair["at_goal_median"] < 0.02  # measured 5.9e-3 rad after 1 s
    press = figures["press"]["engines"]
    for name in ("mujoco", "pybullet"):
        assert all(20.0 < f < 45.0 for f in press[name]["steady_n"])  # measured 25.7-37.8 N
    assert press["pybullet"]["rel_to_reference_max"] < 0.15  # measured 4.0 %
    for name, scenarios in figures["jitter"].items():
        assert scenarios["hold"]["converted"]["acc_std_max"] < 1e-6, name  # measured ~0
        for damping in ("converted", "zeroed"):  # measured 0.007 / 0.019 rad/s^2
            assert scenarios["press"][damping]["acc_std_max"] < 0.2, name
    assert all(g["met"] for g in result["goals"])
    report = (tmp_path / "parity.md").read_text()
    assert "| forward kinematics, max | mujoco vs pybullet |" in report
    assert all(f"({name})" in report for name in PARITY_PLOTS)


@pytest.mark.slow
@pytest.mark.pybullet
def test_quick_parity_with_mjx(tmp_path: Path):
    """All three engines, named (--quick alone leaves MJX out on a CPU); MJX on JAX compiles
    for minutes on a CPU. No --plot: the JSON and the markdown only, which links no picture."""
    result = _run_parity(tmp_path, "--impls", "jax", "--engines", "mujoco", "mjx", "pybullet")
    assert ".png" not in (tmp_path / "parity.md").read_text()
    assert result["engines"] == ["mujoco", "mjx-jax", "pybullet"]
    _check_shapes(result, ParityConfig.quick())
    figures = result["figures"]
    assert figures["fk_m"]["mujoco vs mjx-jax"] < 1e-6  # measured 1.4e-7 m (float32)
    assert figures["open_loop"]["pairs"]["mujoco vs mjx-jax"]["at_goal_median"] < 1e-2
    assert result["seconds"]["mjx-jax"]["compile"] > 0


def test_parity_rejects_bad_flags(tmp_path: Path, capsys):
    argv = ["bench", "parity", "--quick", "--goal-time", "3", "--out", str(tmp_path)]
    assert main(argv) == EXIT_INVALID
    assert "goal_time" in capsys.readouterr().err


POLICY = ROOT / "benchmarks/results/policies/touch_fast_seed0.npz"


@pytest.mark.parametrize(
    "argv",
    [
        ["parity", "--quick", "--plot"],
        ["parity", "--quick", "--grasp", "--grasp-video"],
        ["grasp", "--video"],
        ["transfer", str(POLICY), "--plot"],
        ["robustness", str(POLICY), "--quick", "--plot"],
        ["seeds", "--seeds", "0", "--plot"],
    ],
    ids=lambda argv: " ".join(a for a in argv if not a.endswith(".npz")),
)
def test_pictures_never_go_into_benchmarks_results(argv, tmp_path: Path, capsys):
    """A plot or video asked for into an --out under ``benchmarks/results`` is refused before
    any work, naming --out; nothing is written."""
    out = tmp_path / "benchmarks" / "results" / "topic"
    assert main(["bench", *argv, "--out", str(out)]) == EXIT_INVALID
    err = capsys.readouterr().err
    assert "keeps JSON and Markdown only" in err and "give --out a folder outside it" in err
    assert list(tmp_path.iterdir()) == []


def test_seed_runs_never_go_into_benchmarks_results(tmp_path: Path, capsys):
    """The seeds' runs and their logs are refused under ``benchmarks/results`` too."""
    runs = tmp_path / "benchmarks" / "results" / "runs"
    argv = ["bench", "seeds", "--seeds", "0", "--runs", str(runs), "--out", str(tmp_path)]
    assert main(argv) == EXIT_INVALID
    assert "give --runs a folder outside it" in capsys.readouterr().err
    assert not runs.exists()


def test_seeds_on_the_command_line_count_a_task_solved_where_it_is(tmp_path: Path, capsys):
    """``bench seeds --task lift`` counts a seed solved at Lift's 0.9 unless --threshold says
    otherwise: a training stopped under it is refused, naming the threshold it defaulted to."""
    argv = ["bench", "seeds", "--task", "lift", "--seeds", "0", "--out", str(tmp_path)]
    argv += ["--runs", str(tmp_path / "runs")]
    assert main([*argv, "--set", "stop_at_success=0.85"]) == EXIT_INVALID
    assert "under --threshold 0.9," in capsys.readouterr().err
    assert main([*argv, "--threshold", "0.95"]) == EXIT_INVALID
    assert "stops at its first evaluation at 0.9 success" in capsys.readouterr().err


# --------------------------------------------------------------------------- transfer


@pytest.mark.slow
@pytest.mark.pybullet
def test_transfer_writes_the_matrix(tmp_path_factory, tmp_path: Path):
    """A small trained Reach policy; without a GPU the C MuJoCo batch stands in for MJX."""
    import jax

    run_dir = trained_run_dir(tmp_path_factory)
    argv = ["bench", "transfer", str(run_dir), "--episodes", "4", "--plot", "--out", str(tmp_path)]
    if jax.default_backend() != "cpu":
        argv += ["--engines", "batch", "mujoco", "pybullet"]
    assert main(argv) == EXIT_OK
    result = json.loads((tmp_path / "transfer_reach.json").read_text())
    assert [r["key"] for r in result["rows"]] == ["batch", "mujoco", "pybullet"]
    assert result["config"]["episodes"] == 4 and result["task"] == "reach"
    for row in result["rows"]:
        low, high = row["success_ci95"]
        assert row["episodes"] == 4 and 0 <= low <= row["success_rate"] <= high <= 1
        assert row["success_met"] == (row["success_rate"] >= 0.95)
        assert row["force_met"] is None  # no force goal on Reach
        assert math.isfinite(row["mean_peak_contact_force"])
    table = (tmp_path / "transfer_reach.md").read_text()
    assert "| CPU MuJoCo (Gymnasium) | 4 |" in table and "success >= 0.95" in table
    assert (tmp_path / "transfer_reach.png").stat().st_size > 0


def test_a_given_commit_is_what_results_record(monkeypatch) -> None:
    """A tree copied onto another machine over older git metadata records the commit it is
    told (MJX_ARM_GIT_COMMIT); without it, this checkout's own."""
    from mjx_arm.bench.results import environment_metadata, git_commit

    monkeypatch.delenv("MJX_ARM_GIT_COMMIT", raising=False)
    own = git_commit()
    assert own is None or len(own.removesuffix("-dirty")) == 40
    monkeypatch.setenv("MJX_ARM_GIT_COMMIT", "0123abc")
    assert git_commit() == "0123abc"
    assert environment_metadata(packages=())["git_commit"] == "0123abc"
