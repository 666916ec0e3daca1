"""Tests of the ``mjx-arm`` command line (:mod:`mjx_arm.cli`), without training."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import pytest

from mjx_arm.cli import EXIT_OK, build_parser, main
from mjx_arm.inputs import ConfigError

ARM_URDF = Path(__file__).resolve().parents[1] / "assets" / "ur5e.urdf"


def _subcommands() -> list[str]:
    """Names of the subcommands, read from the parser itself."""
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sorted(sub.choices)


def _exit_code(argv: list[str]) -> int:
    """Run ``mjx-arm argv`` in process; argparse's SystemExit becomes the exit code."""
    try:
        return main(argv)
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            return exc.code or 0
        return 1  # a message instead of a number


def test_subcommands_are_the_documented_ones():
    assert set(_subcommands()) >= {"validate", "convert", "train"}


def test_top_level_help(capsys):
    assert _exit_code(["--help"]) == 0
    out = capsys.readouterr().out
    for name in _subcommands():
        assert name in out


@pytest.mark.parametrize("command", _subcommands())
def test_subcommand_help(command: str, capsys):
    assert _exit_code([command, "--help"]) == 0
    assert f"mjx-arm {command}" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "names"), [([], ("train", "eval")), (["bench"], ("parity",))])
def test_a_command_group_without_its_command_prints_its_help(argv, names, capsys):
    assert _exit_code(argv) == 2  # a usage error, help instead of an error line
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"usage: {' '.join(['mjx-arm', *argv])} ")
    assert "error:" not in captured.err and all(name in captured.err for name in names)


def test_version(capsys):
    from mjx_arm import __version__

    assert _exit_code(["--version"]) == 0
    assert capsys.readouterr().out == f"mjx-arm {__version__}\n"


def test_validate_the_shipped_arm(capfd):
    assert _exit_code(["validate", str(ARM_URDF)]) == EXIT_OK
    assert "ur5e.urdf" in capfd.readouterr().out


def test_convert_the_shipped_arm(tmp_path: Path, capsys):
    output = tmp_path / "X.xml"
    assert _exit_code(["convert", str(ARM_URDF), "-o", str(output)]) == EXIT_OK
    model = mujoco.MjModel.from_xml_path(str(output))
    assert model.nu == 6
    assert "velocity actuators 6" in capsys.readouterr().out


def test_convert_with_scene(tmp_path: Path):
    output = tmp_path / "touch.xml"
    assert _exit_code(["convert", str(ARM_URDF), "-o", str(output), "--scene", "touch"]) == 0
    model = mujoco.MjModel.from_xml_path(str(output))
    assert model.geom("target_box").id >= 0


def test_convert_rejects_a_broken_urdf(tmp_path: Path, capsys):
    broken = tmp_path / "broken.urdf"
    broken.write_text(ARM_URDF.read_text().replace('effort="28"', 'effort="0"'))
    output = tmp_path / "broken.xml"
    assert _exit_code(["convert", str(broken), "-o", str(output)]) != EXIT_OK
    assert not output.exists()
    assert "wrist" in capsys.readouterr().err


def test_console_script_is_on_the_venv_path(tmp_path: Path):
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}"}
    script = shutil.which("mjx-arm", path=env["PATH"])
    assert script is not None, f"mjx-arm is not installed in {bin_dir}"
    assert Path(script).parent == bin_dir
    result = subprocess.run(
        ["mjx-arm", "--help"], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert "usage: mjx-arm" in result.stdout


def test_short_run_says_why_it_has_no_speed() -> None:
    """Too few evaluations for the compile/steady split: a sentence, not NaN."""
    from types import SimpleNamespace

    from mjx_arm.train.run_lines import done_line

    nan = float("nan")
    short = SimpleNamespace(
        steps=2048,
        train_seconds=12.0,
        compile_seconds=nan,
        steps_per_second=nan,
        metrics={"eval/episode_success": 0.25},
        best=None,
    )
    line = done_line(short)
    assert "nan" not in line.lower() and "3 or more evaluations" in line and "0.250" in line
    full = SimpleNamespace(**{**vars(short), "compile_seconds": 4.0, "steps_per_second": 1500.0})
    assert "compile 4.0 s, 1,500 steps/s" in done_line(full)


def test_the_done_line_gives_the_last_and_the_best_evaluation() -> None:
    """A run that ended under its best says both, with their steps."""
    from types import SimpleNamespace

    from mjx_arm.train.run_lines import done_line

    result = SimpleNamespace(
        steps=30_900_000,
        train_seconds=80.0,
        compile_seconds=30.0,
        steps_per_second=7.4e5,
        metrics={"eval/episode_success": 0.0},
        best=(0.963, 26_600_000),
    )
    line = done_line(result)
    assert "last eval success 0.000 at step 30,900,000" in line
    assert "best 0.963 at step 26,600,000" in line


def test_a_shipped_arm_is_named_by_its_short_name(tmp_path: Path, capsys, monkeypatch):
    from mjx_arm.arm.config import load_arm, shipped_arm_names
    from mjx_arm.paths import asset

    assert {"ur5e", "ur5e_gripper"} <= set(shipped_arm_names())
    assert not {"table", "target_box"} & set(shipped_arm_names())  # the scene's pieces
    assert load_arm("ur5e_gripper") == load_arm(asset("ur5e_gripper.urdf"))
    assert _exit_code(["arm", "ur5e_gripper"]) == EXIT_OK
    assert "assets/ur5e_gripper.urdf" in capsys.readouterr().out
    assert _exit_code(["arm", "ur5f"]) == 2
    assert "give a path, or a shipped arm: ur5e, " in capsys.readouterr().err
    mine = tmp_path / "ur5e_gripper"  # a file of that name in the working folder wins
    mine.write_text(ARM_URDF.read_text())
    monkeypatch.chdir(tmp_path)
    assert load_arm("ur5e_gripper").urdf == str(mine.resolve())


def _train_args(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(["train", *argv])


def test_train_seed_is_the_config_field(capsys):
    """--seed N is --set seed=N through the typed config: checked as the field is, last word
    over --set, and refused with --resume like every flag that changes the config."""
    from mjx_arm.settings import attribute_doc
    from mjx_arm.train.cli import _check_resume_flags, config_from_args
    from mjx_arm.train.config import TrainConfig

    assert config_from_args(_train_args("--preset", "cpu", "--seed", "7")).seed == 7
    assert config_from_args(_train_args("--preset", "cpu")).seed == TrainConfig().seed
    assert config_from_args(_train_args("--set", "seed=3", "--seed", "9")).seed == 9
    for bad, message in (("x", "'x' is not an integer"), ("-1", "seed must be >= 0")):
        assert _exit_code(["train", "--seed", bad]) == 2
        assert f"error: argument --seed: {message}" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="--seed would be ignored"):
        _check_resume_flags(_train_args("--resume", "r", "--seed", "1"))
    assert _exit_code(["train", "--help"]) == 0
    shown = " ".join(capsys.readouterr().out.split())
    assert f"--seed SEED {attribute_doc(TrainConfig, 'seed')} Short for --set seed=VALUE" in shown


def test_train_help_lists_each_preset_on_a_line(capsys):
    from mjx_arm.names import PRESET_NAMES
    from mjx_arm.train.presets import PRESETS

    assert _exit_code(["train", "--help"]) == 0
    lines = [line.strip() for line in capsys.readouterr().out.splitlines()]
    for name in PRESET_NAMES:
        config = PRESETS[name]
        start = f"{name}: {config.num_envs:,} envs, {config.num_timesteps / 1e6:g}M env steps:"
        assert sum(line.startswith(start) for line in lines) == 1, name


def test_a_gpu_preset_on_a_cpu_says_how_long_first(tmp_path: Path, capsys):
    import jax

    from mjx_arm.train.cli import config_from_args
    from mjx_arm.train.run_lines import CPU_STEPS_PER_S, start_lines

    if jax.default_backend() != "cpu":
        pytest.skip("an accelerator is present: no note")
    config = config_from_args(_train_args())  # no flags: the seed preset
    start_lines(tmp_path, config, "seed")
    captured = capsys.readouterr()
    assert captured.out == f"run directory: {tmp_path}\n"
    minutes = round(config.num_timesteps / CPU_STEPS_PER_S / 60)
    assert captured.err.startswith("note: preset seed is meant for a GPU: 2,048 envs")
    assert f"would take {minutes} min or more" in captured.err
    assert "--preset cpu --backend mujoco" in captured.err
    for preset in ("cpu", None):  # the cpu preset, a resumed run: no note
        start_lines(tmp_path, config, preset)
        assert capsys.readouterr().err == ""


@pytest.mark.parametrize("stem", ["a" * 246, "é" * 123])  # 251 bytes with ".json": valid on Linux
def test_a_file_name_of_250_bytes_is_written(stem: str, tmp_path: Path) -> None:
    from mjx_arm.inputs import check_output, write_atomic

    target = tmp_path / f"{stem}.json"
    assert len(target.name.encode()) == 251
    write_atomic(b"{}", check_output(target, "-o"))
    assert target.read_bytes() == b"{}"
    assert [p.name for p in tmp_path.iterdir()] == [target.name]  # no temporary file left


ROBOTS = Path(__import__("sysconfig").get_paths()["purelib"]) / (
    "cmeel.prefix/share/example-robot-data/robots"
)


@pytest.mark.skipif(not ROBOTS.is_dir(), reason="example-robot-data is not installed")
def test_convert_writes_mesh_paths_relative_to_the_mjcf(tmp_path: Path) -> None:
    """The MJCF names its meshes from its own folder: the two move together."""
    shutil.copytree(ROBOTS / "panda_description", tmp_path / "a/robots/panda_description")
    urdf = tmp_path / "a/robots/panda_description/urdf/panda.urdf"
    mjcf = tmp_path / "a/out/panda.xml"
    mjcf.parent.mkdir()
    argv = [
        "convert",
        str(urdf),
        "-o",
        str(mjcf),
        "--package",
        f"example-robot-data={tmp_path / 'a'}",
    ]
    assert _exit_code(argv) == EXIT_OK
    files = [line.split('file="')[1].split('"')[0] for line in mjcf.read_text().splitlines()
             if 'file="' in line]  # fmt: skip
    assert files and all(f.startswith("../robots/panda_description/meshes/") for f in files)
    (tmp_path / "a").rename(tmp_path / "moved")
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "moved/out/panda.xml"))
    assert model.nmesh == len(files)


def test_convert_names_a_missing_output_folder_instead_of_making_it(tmp_path: Path, capsys):
    output = tmp_path / "no" / "such" / "arm.xml"
    assert _exit_code(["convert", str(ARM_URDF), "-o", str(output)]) == 2
    assert "does not exist; create it first" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_training_says_its_compile_time_once(tmp_path: Path, capfd) -> None:
    """One "compiled in" line: after the first epoch, or at the end with --quiet (no bar); the
    end names the compile report where the line came before."""
    argv = ["train", "--task", "reach", "--preset", "cpu", "--backend", "mujoco", "--set"]
    argv += ["num_timesteps=20000", "num_evals=3", "num_envs=16", "batch_size=16"]
    for extra in ([], ["--quiet"]):
        run = tmp_path / f"run{len(extra)}"
        assert _exit_code([*argv, "num_eval_envs=16", "--run-dir", str(run), *extra]) == EXIT_OK
        lines = capfd.readouterr().out.splitlines()
        assert sum(line.startswith("compiled in ") for line in lines) == 1, extra
        if not extra:
            assert lines[-1] == f"compile report: {run / 'compile.json'}"
            assert (run / "compile.json").is_file()


@pytest.mark.skipif(not ROBOTS.is_dir(), reason="example-robot-data is not installed")
def test_validate_says_a_finding_shared_by_several_joints_once(capfd) -> None:
    urdf = ROBOTS / "panda_description/urdf/panda.urdf"
    assert _exit_code(["validate", str(urdf), "--engine", "all"]) == EXIT_OK
    lines = capfd.readouterr().out.splitlines()
    damping = [line for line in lines if "jitters with so little damping" in line]
    assert damping == [
        "  WARNING [2] joints 'panda_joint1', 'panda_joint2', 'panda_joint3' and 4 more (7): "
        "has damping 0.003 < 0.01: PyBullet jitters with so little damping. Fix: raise "
        "<dynamics damping> to at least 0.01"
    ]
    assert lines[-1] == "valid (18 warnings)"  # the count still counts each joint


def test_known_library_warnings_stay_off_the_console() -> None:
    import warnings

    from mjx_arm.cli import LIBRARY_WARNINGS

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert _exit_code(["validate", str(ARM_URDF)]) == EXIT_OK  # the command sets the filters
        warnings.warn("JAXopt is no longer maintained. See ...", DeprecationWarning, stacklevel=1)
        warnings.warn("os.fork() was called. It is incompatible", RuntimeWarning, stacklevel=1)
        warnings.warn("a warning of this project's own", UserWarning, stacklevel=1)
    assert [str(w.message) for w in seen] == ["a warning of this project's own"]
    assert len(LIBRARY_WARNINGS) >= 4


def test_a_run_on_several_devices_says_what_was_measured_first(capsys) -> None:
    """``--devices N`` says on stderr what was measured on two GPUs: the split batch (the
    default) no sooner than one GPU, the grown one (``scale_with_devices=true``) later; both
    point at a seed per GPU. One device says nothing."""
    from mjx_arm.train.config import TrainConfig
    from mjx_arm.train.run_lines import devices_note

    devices_note(2, TrainConfig())
    err = capsys.readouterr().err
    assert err.startswith("note: --devices 2 splits the batch over 2 devices")
    assert "bench seeds" in err
    devices_note(4, TrainConfig(scale_with_devices=True))
    err = capsys.readouterr().err
    assert err.startswith("note: --devices 4 grows the batch 4 times") and "bench seeds" in err
    for devices in (None, 1):
        devices_note(devices, TrainConfig())
        assert capsys.readouterr().err == ""
