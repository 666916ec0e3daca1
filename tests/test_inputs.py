"""Named input errors (:mod:`mjx_arm.inputs`): the probes of issue 33 and the checks behind
them, and nothing lost: atomic outputs, locked run directories, a full disk mid-checkpoint."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from input_fuzz.corpus import Corpus, brax_params, build
from mjx_arm.cli import main
from mjx_arm.inputs import ConfigError, InputError, write_atomic
from mjx_arm.names import EXIT_INVALID
from mjx_arm.policy import ContractVersionError, PolicyFileError, load
from mjx_arm.policy.numpy_policy import read_npz, write_npz
from mjx_arm.train.checkpoints import CheckpointError
from mjx_arm.train.rundir import RunDir, RunDirError

# orbax's restore threads outlive their event loop after a read error: noise, not our error
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("inputs_corpus"))


def _fails(argv: list[str], capsys) -> str:
    """Run ``mjx-arm argv``: it must exit 2 with one error line and no traceback; the line."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err
    assert code == EXIT_INVALID, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1, err
    return lines[0]


# --------------------------------------------------------------------------- issue 33's probes


def test_missing_arm_and_config_files(capsys) -> None:
    base = ["train", "--task", "reach", "--preset", "cpu"]
    line = _fails([*base, "--arm", "/nonexistent.urdf"], capsys)
    assert line.startswith("error: arm '/nonexistent.urdf': no such URDF or arm file")
    line = _fails([*base, "--config", "/nonexistent.toml"], capsys)
    assert line.startswith("error: config file '/nonexistent.toml' does not exist")


def test_an_arm_file_with_wrong_types_names_each_field(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('urdf = 5\nhome_qpos = "x"\n')
    line = _fails(["arm", str(bad)], capsys)
    assert "urdf must be a text, got 5" in line and "home_qpos must be a list" in line


def test_a_truncated_policy(corpus: Corpus, tmp_path: Path, capsys) -> None:
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(corpus.policy.read_bytes()[:5000])
    line = _fails(["eval", str(trunc)], capsys)
    assert line.startswith(f"error: cannot read {trunc} as a policy .npz")


def test_numeric_arguments_out_of_range(corpus: Corpus, capsys) -> None:
    line = _fails(["eval", str(corpus.policy), "--episodes", "-3"], capsys)
    assert "argument --episodes: must be an integer in [1, 100000], got -3" in line
    line = _fails(["train", "--set", "num_envs=-5"], capsys)
    assert line == "error: --set num_envs=-5: num_envs must be >= 1, got -5"
    line = _fails(["eval", str(corpus.policy), "--seed", "4294967296"], capsys)
    assert "--seed" in line


def test_a_urdf_without_links_is_an_arm_config_error(tmp_path: Path) -> None:
    """example-robot-data's ur3.urdf is an empty <robot> (a xacro stub)."""
    from mjx_arm.arm.config import ArmConfig, ArmConfigError, resolve_arm

    empty = tmp_path / "ur3.urdf"
    empty.write_text(
        '<?xml version="1.0"?>\n<robot xmlns:xacro="http://wiki.ros.org/xacro">\n</robot>\n'
    )
    with pytest.raises(ArmConfigError, match="no leaf link"):
        resolve_arm(ArmConfig(urdf=str(empty)))


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ('urdf = "URDF"\nee_link = {a = 1}\n', "ee_link must be str, not a table"),
        ('urdf = "URDF"\njoints = {a = 1}\n', "joints must be"),
        ("urdf = {a = {b = [1, 2]}}\n", "urdf must be str, not a table"),
        ('urdf = "' + "x" * 100_000 + '"\n', "cannot be a path (File name too long)"),
    ],
)
def test_arm_file_values_of_the_wrong_kind_are_one_error_line(
    tmp_path: Path, capsys, body: str, message: str
) -> None:
    """A table where a name or list belongs, or a path longer than the filesystem takes, is an
    error line (was: TypeError, AttributeError, OSError)."""
    from mjx_arm.paths import asset

    arm = tmp_path / "arm.toml"
    arm.write_text(body.replace("URDF", str(asset("ur5e.urdf"))))
    line = _fails(["arm", str(arm), "--check"], capsys)
    assert message in line and len(line) <= 300, line


def test_a_chain_of_2000_joints_is_an_error_line_not_a_recursion_error(tmp_path: Path, capsys):
    """The URDF model walks its tree with a stack: deploy-sim on a 2,000-joint chain names the
    joint count instead of exhausting Python's recursion limit."""
    n = 2000
    inertia = '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>'
    links = "".join(
        f'<link name="l{i}"><inertial><mass value="1"/>{inertia}</inertial></link>'
        for i in range(n + 1)
    )
    joints = "".join(
        f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
        for i in range(n)
    )
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(f'<robot name="c">{links}{joints}</robot>')
    policy = Path(__file__).parents[1] / "benchmarks/results/policies/touch_fast_seed0.npz"
    line = _fails(["deploy-sim", str(policy), "--arm", str(urdf)], capsys)
    assert "has 1999" in line and len(line) <= 300, line


# --------------------------------------------------------------------------- typed configs


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"num_envs": "64"}, "num_envs must be an integer"),
        ({"num_envs": True}, "num_envs must be an integer"),
        ({"learning_rate": float("nan")}, "learning_rate must be a finite number"),
        ({"policy_hidden": [64, "x"]}, "policy_hidden must be a list of integers"),
        ({"physics": {"njmax": -1}}, "physics.njmax must be >= 0"),
        ({"randomization": {"friction": [2.0, 1.0]}}, "low <= high"),
        ({"discounting": 1.5}, "discounting must be"),
        ({"no_such": 1}, "unknown training config keys"),
    ],
)
def test_train_config_fields_are_checked_by_type_and_range(data: dict, message: str) -> None:
    from mjx_arm.train.config import TrainConfig

    with pytest.raises(ConfigError, match=message):
        TrainConfig.from_dict(data)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("learning_rate=nan", "learning_rate must be a finite number"),
        ("num_envs=1.5", "is not an integer"),
        ("policy_hidden=0,64", "each entry of policy_hidden must be >= 1"),
        ("task.episode_steps=0", "episode_steps must be >= 1"),
        ("task.no_such=1", "unknown task key"),
        ("arm.urdf=/nonexistent.urdf", "arm.urdf '/nonexistent.urdf' is not a file"),
    ],
)
def test_set_items_name_the_item(item: str, message: str) -> None:
    from mjx_arm.train.presets import load_config

    with pytest.raises(ConfigError, match=message):
        load_config("cpu", None, ["task=reach", item])


# --------------------------------------------------------------------------- policy files


def _policy_with(corpus: Corpus, tmp_path: Path, **changes) -> Path:
    arrays, meta = read_npz(corpus.policy)
    arrays.update(changes.pop("arrays", {}))
    return write_npz(tmp_path / "changed.npz", arrays, {**meta, **changes})


def test_a_newer_contract_version_asks_for_an_upgrade(corpus: Corpus, tmp_path: Path) -> None:
    with pytest.raises(ContractVersionError, match="newer than this runtime's '1': upgrade"):
        load(_policy_with(corpus, tmp_path, contract_version="2"))


def test_non_finite_weights_and_layers_that_do_not_fit(corpus: Corpus, tmp_path: Path) -> None:
    arrays, _ = read_npz(corpus.policy)
    nan = arrays["kernel_1"].copy()
    nan[0, 0] = np.nan
    with pytest.raises(PolicyFileError, match="kernel_1 holds NaN"):
        load(_policy_with(corpus, tmp_path, arrays={"kernel_1": nan}))
    with pytest.raises(PolicyFileError, match=r"kernel_0 has shape \(21, 16\)"):
        load(_policy_with(corpus, tmp_path, arrays={"kernel_0": arrays["kernel_0"][:21]}))
    with pytest.raises(PolicyFileError, match="not an mjx_arm policy"):
        load(_policy_with(corpus, tmp_path, format="someone.else"))


def test_a_policy_of_another_layout_is_refused_before_the_env(
    corpus: Corpus, tmp_path: Path, capsys
) -> None:
    """A policy whose layers fit its own metadata, but not the task it is evaluated in."""
    line = _fails(["eval", str(corpus.policy), "--task", "lift", "--episodes", "1"], capsys)
    assert "pass the task (--task) and arm (--arm) it was trained on" in line


# --------------------------------------------------------------------------- nothing lost


def test_write_atomic_leaves_the_old_file_whole_when_writing_fails(
    tmp_path: Path, monkeypatch
) -> None:
    target = tmp_path / "policy.npz"
    target.write_bytes(b"good")

    def full_disk(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space"):
        write_atomic(b"new and longer", target)
    assert target.read_bytes() == b"good"
    assert [p.name for p in tmp_path.iterdir()] == ["policy.npz"]


def test_a_second_training_on_a_run_directory_is_refused(corpus: Corpus, capsys) -> None:
    run = RunDir(corpus.run_dir)
    with run.lock():
        with (
            pytest.raises(RunDirError, match=f"in use by another training \\(pid {os.getpid()}\\)"),
            run.lock(),
        ):
            pass
        line = _fails(["train", "--resume", str(corpus.run_dir)], capsys)
        assert "in use by another training" in line
    with run.lock():  # released: free again
        pass


def test_a_new_training_never_overwrites_a_run(corpus: Corpus, capsys) -> None:
    before = sorted(p.name for p in (corpus.run_dir / "checkpoints").iterdir())
    line = _fails(["train", "--preset", "cpu", "--run-dir", str(corpus.run_dir)], capsys)
    assert "already holds a run" in line and "--resume" in line
    assert sorted(p.name for p in (corpus.run_dir / "checkpoints").iterdir()) == before


def test_a_damaged_checkpoint_is_a_named_error(corpus: Corpus, tmp_path: Path, capsys) -> None:
    """Checked against the file sizes and hashes its meta.json recorded, before orbax reads
    it (orbax's threads print tracebacks after a failed read)."""
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree(corpus.run_dir, run_dir)
    for path in (run_dir / "checkpoints").rglob("*"):
        if path.is_file() and path.parent.name == "d":  # orbax's data files
            path.write_bytes(path.read_bytes()[:10])
    line = _fails(["train", "--resume", str(run_dir)], capsys)
    assert "cannot be read: params/d/" in line and "has changed since it was saved" in line
    line = _fails(["export", str(run_dir), "-o", str(tmp_path / "p.npz")], capsys)
    assert "cannot be read" in line and not (tmp_path / "p.npz").exists()


def test_a_huge_params_file_is_named_without_being_read(corpus: Corpus, tmp_path: Path, capsys):
    """A params file made 3 GiB (sparse) differs in size from its record: named from its size
    alone, never read whole (peak memory of the check stays under 200 MB more than before)."""
    import resource
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree(corpus.run_dir, run_dir)
    data = next(p for p in (run_dir / "checkpoints").rglob("*") if p.parent.name == "d")
    with data.open("r+b") as f:
        f.truncate(3 * 2**30)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    line = _fails(["export", str(run_dir), "-o", str(tmp_path / "p.npz")], capsys)
    assert "has changed since it was saved (3221225472 bytes)" in line
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 200, grown_mb


def test_a_same_step_save_killed_between_its_renames_is_recovered(tmp_path: Path) -> None:
    run = RunDir(tmp_path / "run")
    params = brax_params(22, 6, np.random.default_rng(0))
    folder = run.save_checkpoint(100, params, {"task": "reach"})
    os.replace(folder, folder.with_name(".old-" + folder.name))  # the kill
    assert run.latest_checkpoint() == folder
    assert RunDir.load_meta(folder)["step"] == 100


def _check_full_disk_keeps_the_last_checkpoint(run: RunDir, fill) -> None:
    small = brax_params(22, 6, np.random.default_rng(0))
    first = run.save_checkpoint(100, small, {"task": "reach"})
    fill()
    big = brax_params(22, 6, np.random.default_rng(1))
    big[1]["params"]["hidden_0"]["kernel"] = np.ones((22, 20_000), np.float32)
    with pytest.raises(CheckpointError, match=r"last good checkpoint is kept \(step_0+100\)"):
        run.save_checkpoint(200, big, {"task": "reach"})
    assert run.latest_checkpoint() == first
    assert RunDir.load_params(first)[0]["mean"].shape == (22,)
    assert [p.name for p in run.checkpoints.iterdir()] == [first.name]  # no partial left


def test_a_full_disk_during_a_checkpoint_keeps_the_last_good_one_tmpfs(tmp_path: Path) -> None:
    """A real full disk: a 1 MiB tmpfs (needs root to mount; skipped elsewhere). orbax reports
    the ENOSPC as a ValueError, which a simulated OSError would not have shown."""
    mount = tmp_path / "tmpfs"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                          capture_output=True)  # fmt: skip
    if done.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:

        def fill() -> None:
            stat = os.statvfs(mount)
            (mount / "filler").write_bytes(b"0" * (stat.f_bavail * stat.f_frsize - 4096))

        _check_full_disk_keeps_the_last_checkpoint(RunDir(mount / "run"), fill)
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_full_disk_during_a_checkpoint_keeps_the_last_good_one_simulated(
    tmp_path: Path, monkeypatch
) -> None:
    """The same on any machine: ENOSPC simulated by making the checkpoint writer fail."""
    from mjx_arm.train import checkpoints

    state = {"full": False}
    real = checkpoints._write_partial

    def write(partial, *args):
        if state["full"]:
            partial.mkdir(parents=True)
            (partial / "half").write_bytes(b"x")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(partial, *args)

    monkeypatch.setattr(checkpoints, "_write_partial", write)
    _check_full_disk_keeps_the_last_checkpoint(
        RunDir(tmp_path / "run"), lambda: state.update(full=True)
    )


def test_every_named_error_is_an_input_error_or_mapped() -> None:
    from mjx_arm.cli import named_errors
    from mjx_arm.demo import DemoError
    from mjx_arm.replay import TrajectoryError
    from mjx_arm.urdf.errors import UrdfError

    for error in (DemoError, TrajectoryError, UrdfError, RunDirError, CheckpointError):
        assert issubclass(error, InputError)
    assert PolicyFileError in named_errors()
    json.dumps([e.__name__ for e in named_errors()])


def test_mujoco_data_that_cannot_be_allocated_is_a_config_error() -> None:
    """Under a 2 GiB address-space cap, a model asking for a 3 GiB arena: MuJoCo's FatalError
    becomes a ConfigError naming the arena (run in a child: the cap would hold this process)."""
    code = (
        "import resource, mujoco\n"
        "from mjx_arm.envs.mujoco_batch import new_data\n"
        "m = mujoco.MjModel.from_xml_string('<mujoco><size memory=\"3G\"/><worldbody/></mujoco>')\n"
        "resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))\n"
        "try:\n    new_data(m)\nexcept Exception as e:\n    print(type(e).__name__, e)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    ).stdout
    assert out.startswith("ConfigError MuJoCo could not allocate its data"), out
    assert "3072 MiB of arena" in out


@pytest.mark.parametrize("task", [{"a": 1}, ["touch"], 3])
def test_a_config_file_task_of_the_wrong_kind_is_a_config_error(tmp_path: Path, task) -> None:
    from mjx_arm.inputs import ConfigError
    from mjx_arm.train.presets import load_config

    path = tmp_path / "config.json"
    path.write_text(json.dumps({"task": task}))
    with pytest.raises(ConfigError, match="task must be a task's name"):
        load_config("cpu", path)
