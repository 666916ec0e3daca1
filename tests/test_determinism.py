"""Same seed, same run: the repeat check, the deterministic switch, and two short runs that are
identical bit for bit on the C MuJoCo backend and on MJX's JAX physics on the CPU."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest
from tiny_run import EPOCHS, SETTINGS

from mjx_arm.train.presets import load_config
from mjx_arm.train.repeat import TIMING_COLUMNS, compare_runs

# The tiny run of the resume tests, with the settings a deterministic run may change.
TINY = {
    **SETTINGS,
    "schedule.kind": "adaptive",
    "normalizer.std_floor": "0.01",
    "normalizer.clip": "10",
    "deterministic": "true",
}


def _write_metrics(run: Path, rows: list[dict[str, float]]) -> None:
    run.mkdir(parents=True)
    with (run / "metrics.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_compare_runs_names_the_first_step_and_column_that_differ(tmp_path: Path) -> None:
    rows = [
        {"step": 0, "time": 1.0, "eval/episode_success": 0.0, "training/sps": 10.0},
        {"step": 100, "time": 2.0, "eval/episode_success": 0.5, "training/sps": 11.0},
        {"step": 200, "time": 3.0, "eval/episode_success": 0.9, "training/sps": 12.0},
    ]
    _write_metrics(tmp_path / "a", rows)
    other = [dict(r) for r in rows]
    other[1]["time"], other[1]["training/sps"] = 9.0, 99.0  # timing columns never count
    other[2]["eval/episode_success"] = 0.9 + 1e-12  # one bit off
    _write_metrics(tmp_path / "b", other)
    report = compare_runs(tmp_path / "a", tmp_path / "b")
    assert not report.identical
    assert (report.first_step, report.column) == (200, "eval/episode_success")
    assert "step 200" in report.line() and "eval/episode_success" in report.line()
    assert {"time", "training/sps"} <= TIMING_COLUMNS


def test_compare_runs_of_the_same_rows_is_identical(tmp_path: Path) -> None:
    rows = [{"step": 0, "time": 1.0, "eval/episode_reward": -3.25}]
    _write_metrics(tmp_path / "a", rows)
    _write_metrics(tmp_path / "b", [{**rows[0], "time": 5.0}])
    report = compare_runs(tmp_path / "a", tmp_path / "b")
    assert report.identical and report.rows == 1
    assert report.line().startswith("repeat: identical")


def test_enable_sets_xla_deterministic_ops(monkeypatch) -> None:
    from mjx_arm.train import determinism

    monkeypatch.setenv("XLA_FLAGS", "--xla_dump_to=/tmp/x")
    done = determinism.enable()
    assert determinism.XLA_FLAG in os.environ["XLA_FLAGS"]
    assert "--xla_dump_to=/tmp/x" in os.environ["XLA_FLAGS"]  # other flags kept
    determinism.enable()  # idempotent: the flag once
    assert os.environ["XLA_FLAGS"].count(determinism.XLA_FLAG) == 1
    assert done["xla"] == determinism.XLA_FLAG


def test_the_deterministic_flag_and_setting_reach_the_config() -> None:
    config = load_config("cpu", None, ["deterministic=true"])
    assert config.deterministic
    assert not load_config("cpu", None, []).deterministic


def _repeat(tmp_path: Path, backend: str, extra: dict[str, str]) -> None:
    from mjx_arm.train.cli import check_repeat

    items = [f"{k}={v}" for k, v in {**TINY, "backend": backend, **extra}.items()]
    config = load_config("cpu", None, items)
    assert check_repeat(config, tmp_path / "run", quiet=True) == 0
    report = compare_runs(tmp_path / "run" / "repeat-a", tmp_path / "run" / "repeat-b")
    assert report.identical and report.rows == EPOCHS + 1 and report.checkpoints == EPOCHS


@pytest.mark.slow
def test_two_runs_are_identical_on_the_c_backend(tmp_path: Path) -> None:
    """Every logged figure but time, and every checkpoint's params, bit for bit (about 3 min
    on the 2-core CPU, compilation included)."""
    _repeat(tmp_path, "mujoco", {})


@pytest.mark.slow
@pytest.mark.skipif(
    not os.environ.get("MJX_ARM_MJX_CPU_TESTS"),
    reason="compiles MJX's training programs on the CPU (over 20 min on a loaded 2-core "
    "machine); set MJX_ARM_MJX_CPU_TESTS=1 to run it",
)
def test_two_runs_are_identical_on_mjx_jax_on_the_cpu(tmp_path: Path) -> None:
    """MJX's JAX physics under XLA's CPU backend (the MJX graph compiles on the CPU)."""
    _repeat(tmp_path, "mjx", {"physics.impl": "jax"})


def test_a_deterministic_run_steps_jax_physics_where_warp_would_run(monkeypatch) -> None:
    """physics.impl=auto on a GPU (Warp) becomes jax; warp by name is a named error."""
    from mjx_arm.envs import physics_config
    from mjx_arm.inputs import ConfigError
    from mjx_arm.train import determinism

    monkeypatch.setattr(
        physics_config, "resolve_impl", lambda impl: "warp" if impl == "auto" else impl
    )
    monkeypatch.setattr("mjx_arm.envs.backend.resolve_backend", lambda backend: "mjx")
    config = load_config("fast", None, ["task=touch", "deterministic=true"])
    assert determinism.deterministic_physics(config).physics.impl == "jax"
    warp = config.replace(physics=config.physics.replace(impl="warp"))
    with pytest.raises(ConfigError, match=r"physics\.impl=jax"):
        determinism.deterministic_physics(warp)
