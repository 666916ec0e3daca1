"""A resumed run is the run it continues: checkpoints keep the optimiser state, the PRNG keys
and the training envs' state (:mod:`mjx_arm.train.resume`).

Three epochs of a small Reach config on the C MuJoCo backend, a checkpoint after each. One run
trains them uninterrupted; another stops after the first epoch (``stop_after=1``), and copies
of it are resumed: as they are (the same arrays and evaluations as the uninterrupted run, to
the bit: the same programs on the same device from the same state), with the resume files
deleted (a checkpoint of an older version: params only, with a warning), and with resume
files that do not fit (a named error before anything compiles).
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from tiny_run import EPOCH_STEPS, EPOCHS, SETTINGS

from mjx_arm.cli import main
from mjx_arm.inputs import InputError
from mjx_arm.names import EXIT_INVALID
from mjx_arm.train.ppo import train
from mjx_arm.train.presets import load_config
from mjx_arm.train.resume import ENV_STATE_FILE, RESUME_FILE, ResumeStateError
from mjx_arm.train.rundir import RunDir

CONFIG = load_config("cpu", None, [f"{k}={v}" for k, v in SETTINGS.items()])
FIRST, LAST = EPOCH_STEPS, EPOCHS * EPOCH_STEPS


def _checkpoint(run_dir: Path, step: int) -> Path:
    return RunDir(run_dir).checkpoint_dir(step)


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def _figures(run_dir: Path) -> list[dict[str, float]]:
    """Each row of metrics.csv without its timings: the evaluations and the losses."""
    timings = ("time", "walltime", "sps", "_s")
    return [
        {k: v for k, v in row.items() if not k.endswith(timings)}
        for row in RunDir(run_dir).read_metrics()
    ]


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run trained without a stop."""
    run_dir = tmp_path_factory.mktemp("resume") / "whole"
    train(CONFIG, run_dir, quiet=True)
    return run_dir


@pytest.fixture(scope="module")
def stopped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same run stopped after its first epoch (and checkpoint); tests resume copies."""
    run_dir = tmp_path_factory.mktemp("resume") / "stopped"
    result = train(CONFIG, run_dir, quiet=True, stop_after=1)
    assert result.steps == FIRST
    return run_dir


def _copy(stopped: Path, tmp_path: Path) -> Path:
    run_dir = tmp_path / "run"
    shutil.copytree(stopped, run_dir)
    return run_dir


def test_a_resumed_run_is_the_run_it_continues(whole: Path, stopped: Path, tmp_path) -> None:
    run_dir = _copy(stopped, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing dropped: no env reset, no params-only resume
        result = train(CONFIG, run_dir, resume=True, quiet=True)
    assert result.steps == LAST
    for name in (RESUME_FILE, ENV_STATE_FILE):
        want = _arrays(_checkpoint(whole, LAST) / name)
        got = _arrays(_checkpoint(run_dir, LAST) / name)
        assert sorted(got) == sorted(want), name
        for key, array in want.items():
            assert got[key].dtype == array.dtype and got[key].shape == array.shape, key
            np.testing.assert_array_equal(got[key], array, err_msg=f"{name}: {key}")
    # the same evaluations and losses, each step logged once
    figures = _figures(run_dir)
    assert [int(r["step"]) for r in figures] == [i * EPOCH_STEPS for i in range(EPOCHS + 1)]
    assert "eval/episode_reward" in figures[-1] and "training/policy_loss" in figures[-1]
    assert figures == _figures(whole)


def test_only_the_newest_checkpoint_keeps_the_env_state(whole: Path) -> None:
    folders = sorted((whole / "checkpoints").iterdir())
    assert [f.name for f in folders] == [_checkpoint(whole, s).name for s in (640, 1280, 1920)]
    assert all((f / RESUME_FILE).is_file() for f in folders)
    assert [(f / ENV_STATE_FILE).is_file() for f in folders] == [False, False, True]
    keys = _arrays(folders[-1] / RESUME_FILE)
    assert {"key_epochs", "key_evaluation"} <= set(keys)
    env = _arrays(folders[-1] / ENV_STATE_FILE)
    assert env and all(a.shape[0] == SETTINGS["num_envs"] for a in env.values())


def test_a_params_only_checkpoint_resumes_with_a_warning(stopped: Path, tmp_path) -> None:
    """A checkpoint written before resume.npz: fresh optimiser moments, new keys, reset envs."""
    run_dir = _copy(stopped, tmp_path)
    for name in (RESUME_FILE, ENV_STATE_FILE):
        (_checkpoint(run_dir, FIRST) / name).unlink()
    with pytest.warns(UserWarning, match="holds params only"):
        result = train(CONFIG, run_dir, resume=True, quiet=True)
    assert result.steps == LAST
    assert [int(r["step"]) for r in RunDir(run_dir).read_metrics()] == [0, 640, 1280, 1920]
    assert (_checkpoint(run_dir, LAST) / RESUME_FILE).is_file()  # it writes the new kind


def test_resume_files_of_another_network_are_a_named_error(
    stopped: Path, tmp_path: Path, capsys, monkeypatch
) -> None:
    """config.json asks for a wider policy than the checkpoint's: one error line, exit 2,
    before anything is compiled."""
    import jax

    # the command turns on the compilation cache: the one the tests use
    monkeypatch.setenv("MJX_ARM_JAX_CACHE", jax.config.jax_compilation_cache_dir)
    run_dir = _copy(stopped, tmp_path)
    path = run_dir / "config.json"
    saved = json.loads(path.read_text())
    saved["train"]["policy_hidden"] = [64, 64]
    path.write_text(json.dumps(saved))
    assert main(["train", "--resume", str(run_dir), "--quiet"]) == EXIT_INVALID
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    assert f"{RESUME_FILE} does not fit this run's config" in lines[0]
    assert "is float32[32], expected float32[64]" in lines[0]  # a layer's biases


@pytest.mark.parametrize("damage", ["cut", "garbage"])
def test_a_damaged_resume_file_is_a_named_error(stopped: Path, tmp_path, damage: str) -> None:
    run_dir = _copy(stopped, tmp_path)
    path = _checkpoint(run_dir, FIRST) / RESUME_FILE
    content = path.read_bytes()
    path.write_bytes(content[: len(content) // 2] if damage == "cut" else b"not an npz")
    with pytest.raises(ResumeStateError, match=f"{RESUME_FILE} cannot be read") as caught:
        train(CONFIG, run_dir, resume=True, quiet=True)
    assert isinstance(caught.value, InputError)


@pytest.mark.parametrize("hostile", ["huge_header", "zip_bomb"])
def test_a_resume_file_that_declares_more_than_the_state_is_refused_unread(
    stopped: Path, tmp_path, hostile: str
) -> None:
    """A member whose header declares 2^40 floats, or 3 GiB of zeros compressed to 3 MB, is
    refused from its declared size, before anything is allocated."""
    from input_fuzz import hostile_npz

    run_dir = _copy(stopped, tmp_path)
    path = _checkpoint(run_dir, FIRST) / RESUME_FILE
    good = tmp_path / "good.npz"
    good.write_bytes(path.read_bytes())
    getattr(hostile_npz, hostile)(good, path, np.random.default_rng(0))
    with pytest.raises(ResumeStateError, match="declares more than this run's state holds"):
        train(CONFIG, run_dir, resume=True, quiet=True)


def test_flags_that_would_change_a_resumed_run_are_an_error(tmp_path: Path, capsys) -> None:
    """--resume keeps the run's config: --task, --arm, --set ... are named, not dropped."""
    code = main(["train", "--resume", str(tmp_path), "--task", "lift", "--set", "no_such_key=1"])
    assert code == EXIT_INVALID
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--task, --set would be ignored" in line and line.startswith("error:")
