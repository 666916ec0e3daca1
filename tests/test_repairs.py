"""An arm whose URDF breaks the inertia triangle inequality: each command that loads it names a
fix it takes, and with the repair (flag or arm file) MuJoCo and PyBullet load and step the same
repaired arm."""

from __future__ import annotations

import argparse
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.arm.config import ArmConfig, load_arm
from mjx_arm.cli import EXIT_INVALID, EXIT_OK, build_parser, main
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.paths import default_arm_urdf
from mjx_arm.task import touch_config
from mjx_arm.urdf.errors import UrdfError
from mjx_arm.urdf.inertia import principal_moments, repair_inertia
from mjx_arm.urdf.repair import link_tensor
from mjx_arm.urdf.repair_args import with_repair_arguments
from mjx_arm.urdf.validate import validate
from pybullet_ref.env import BulletClient, PybulletArmEnv, pybullet

# The links given broken tensors: one a joint moves (its rotor inertia is added in PyBullet),
# and the tool below the F/T joint (PyBullet steps it as loaded).
BROKEN = {"wrist_1_link": {"ixx": "0.0003"}, "tool_link": {"izz": "0.0005"}}
RTOL = 1e-9  # relative: both engines read the same repaired numbers
COMMANDS = ("convert", "validate", "arm", "train", "warmup", "eval")


def _broken_urdf(folder: Path) -> Path:
    """The shipped arm with :data:`BROKEN`'s inertias: a + b < c on both links."""
    root = ET.parse(default_arm_urdf()).getroot()
    for link in root.findall("link"):
        for key, value in BROKEN.get(link.get("name"), {}).items():
            link.find("inertial/inertia").set(key, value)
    path = folder / "broken.urdf"
    ET.ElementTree(root).write(path)
    return path


def _repaired_moments(urdf: Path, link: str) -> np.ndarray:
    """Principal moments (kg m^2), ascending, of the repair of ``link``'s tensor, ``(3,)``."""
    (elem,) = [e for e in ET.parse(urdf).getroot().findall("link") if e.get("name") == link]
    return principal_moments(repair_inertia(link_tensor(elem)))


def _parser(command: str) -> argparse.ArgumentParser:
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices[command]


def _takes(command: str, flag: str) -> bool:
    return any(flag in action.option_strings for action in _parser(command)._actions)


def test_arm_check_names_a_fix_the_command_takes(tmp_path: Path, capsys) -> None:
    urdf = _broken_urdf(tmp_path)
    assert main(["arm", str(urdf), "--check"]) == EXIT_INVALID
    line = capsys.readouterr().err
    assert "link 'wrist_1_link': inertia" in line
    # the line ends in the fix: a flag of this command, and the arm-file key
    assert "--repair-inertia" in line and "repair_inertia = true in an arm file" in line
    for command in COMMANDS:
        assert _takes(command, "--repair-inertia"), command
        assert _takes(command, "--default-effort") and _takes(command, "--default-velocity")
    assert main(["arm", str(urdf), "--check", "--repair-inertia"]) == EXIT_OK
    shown = capsys.readouterr().out
    assert "repairs     inertia (in MuJoCo and PyBullet alike)" in shown and "touch  yes" in shown
    # the arm file it writes keeps the repair
    out = tmp_path / "arm.toml"
    assert main(["arm", str(urdf), "--repair-inertia", "-o", str(out)]) == EXIT_OK
    assert load_arm(out).repair_inertia


def _arm(source: str, urdf: Path) -> ArmConfig:
    """The repaired arm, from the ``arm`` command's flag or from an arm file."""
    if source == "flag":
        args = build_parser().parse_args(["arm", str(urdf), "--repair-inertia"])
        return with_repair_arguments(load_arm(args.arm), args)
    arm_file = urdf.parent / "arm.toml"
    arm_file.write_text(f'urdf = "{urdf.name}"\nrepair_inertia = true\n')
    return load_arm(arm_file)


@pytest.mark.parametrize("source", ["flag", "arm_file"])
def test_the_repaired_arm_steps_in_both_engines_with_the_same_inertia(
    source: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    folder = tmp_path / "arm_folder"
    folder.mkdir()
    urdf = _broken_urdf(folder)
    arm = _arm(source, urdf)
    assert arm.repair_inertia
    assert not validate(urdf, "pybullet").ok
    assert validate(urdf, "pybullet", repair_inertia=True).ok
    task = touch_config()
    envs = {"mujoco": MujocoArmEnv(task, arm), "pybullet": PybulletArmEnv(task, arm)}
    for env in envs.values():
        env.reset(seed=0)
        for _ in range(3):
            obs, reward, *_ = env.step(np.zeros(6, np.float32))
        assert np.isfinite(reward) and np.all(np.isfinite(obs["joint_angles"]))
    bullet = envs["pybullet"]
    # PyBullet's copy lives in the cache, not beside the user's file
    assert bullet._urdf.is_relative_to(tmp_path / "cache") and bullet._urdf != urdf
    fresh = BulletClient(pybullet.DIRECT)  # the copy as loaded, before the env's rotor discs
    body = fresh.loadURDF(str(bullet._urdf), flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
    for name in BROKEN:
        repaired = _repaired_moments(urdf, name)
        loaded = fresh.getDynamicsInfo(body, _link_index(fresh, body, name))[2]
        np.testing.assert_allclose(np.sort(loaded), repaired, rtol=RTOL)
        model = envs["mujoco"].model
        np.testing.assert_allclose(np.sort(model.body(name).inertia), repaired, rtol=RTOL)
    fresh.disconnect()
    # the tool link (no rotor inertia added) steps with the repaired tensor in the env itself
    tool = _link_index(bullet.client, bullet.body, "tool_link")
    stepped = bullet.client.getDynamicsInfo(bullet.body, tool)[2]
    np.testing.assert_allclose(np.sort(stepped), _repaired_moments(urdf, "tool_link"), rtol=RTOL)
    for env in envs.values():
        env.close()


def _link_index(client: BulletClient, body: int, name: str) -> int:
    """PyBullet's index of link ``name`` (link index = joint index)."""
    for j in range(client.getNumJoints(body)):
        if client.getJointInfo(body, j)[12].decode() == name:
            return j
    raise KeyError(name)


def test_train_takes_the_repair_flags_and_saves_them_with_the_run(tmp_path: Path, capsys) -> None:
    from mjx_arm.train.cli import config_from_args
    from mjx_arm.train.config import saved_config
    from mjx_arm.train.ppo import full_config, resolve_run_task
    from mjx_arm.train.rundir import RunDir

    urdf = _broken_urdf(tmp_path)
    argv = ["train", "--preset", "cpu", "--arm", str(urdf), "--repair-inertia"]
    config = config_from_args(build_parser().parse_args([*argv, "--default-effort", "80"]))
    assert config.arm.repair_inertia and config.arm.default_effort == 80.0
    resolve_run_task(config)  # what train validates before any compilation
    without = config.replace(arm=config.arm.replace(repair_inertia=False))
    with pytest.raises(UrdfError, match="--repair-inertia"):
        resolve_run_task(without)
    run = RunDir(tmp_path / "run")  # config.json as train writes it
    run.save_config(full_config(config, config.task_config()))
    assert saved_config(run.path).arm == config.arm
    recorded = json.loads((run.path / "config.json").read_text())["arm"]["config"]
    assert recorded["repair_inertia"] is True
    # a resumed run keeps the arm it was started with: the flag is refused, by name
    assert main(["train", "--resume", str(run.path), "--repair-inertia"]) == EXIT_INVALID
    assert "--repair-inertia" in capsys.readouterr().err


@pytest.mark.slow
def test_a_policy_trained_on_a_repaired_arm_is_evaluated_in_pybullet(tmp_path: Path) -> None:
    """A tiny training run with --repair-inertia (2 to 3 minutes of compilation on a cold
    cache), then eval in PyBullet: the run's recorded arm carries the repair there."""
    from tiny_run import EPOCH_STEPS, SETTINGS

    from mjx_arm.train.config import saved_config

    urdf = _broken_urdf(tmp_path)
    settings = {**SETTINGS, "num_timesteps": EPOCH_STEPS, "num_evals": 2}
    run = tmp_path / "run"
    sets = [f"{key}={value}" for key, value in settings.items()]
    argv = ["train", "--quiet", "--preset", "cpu", "--arm", str(urdf), "--repair-inertia"]
    assert main([*argv, "--run-dir", str(run), "--set", *sets]) == EXIT_OK
    assert saved_config(run).arm.repair_inertia
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--engine", "pybullet", "--episodes", "2", "-o", str(out)]) == 0
    assert json.loads(out.read_text())["episodes"] == 2


def test_a_published_arm_with_broken_tensors_loads_repaired_in_pybullet(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """pybullet_data's xArm6: package:// collision meshes, and two links whose tensors (with
    products of inertia) break the triangle inequality."""
    import pybullet_data

    from mjx_arm.task import reach_config
    from mjx_arm.urdf.inertia import inertia_problem
    from mjx_arm.urdf.repair import inertial_links

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    xarm = Path(pybullet_data.getDataPath()) / "xarm/xarm6_with_gripper.urdf"
    (tmp_path / "xarm.toml").write_text(f'urdf = "{xarm}"\nrepair_inertia = true\n')
    env = PybulletArmEnv(reach_config(), load_arm(tmp_path / "xarm.toml"))
    env.reset(seed=0)
    obs, reward, *_ = env.step(np.zeros(6, np.float32))
    assert np.isfinite(reward) and np.all(np.isfinite(obs["joint_angles"]))
    # every mesh of the copy names an existing file by its absolute path
    meshes = [Path(m.get("filename")) for m in ET.parse(env._urdf).getroot().iter("mesh")]
    assert meshes and all(m.is_absolute() and m.is_file() for m in meshes)
    broken = [
        link.get("name")
        for link in inertial_links(ET.parse(xarm).getroot())
        if inertia_problem(link_tensor(link))
    ]
    assert broken == ["link2", "link3"]
    client = env.client
    body = client.loadURDF(str(env._urdf), flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
    for name in broken:
        loaded = client.getDynamicsInfo(body, _link_index(client, body, name))[2]
        np.testing.assert_allclose(np.sort(loaded), _repaired_moments(xarm, name), rtol=RTOL)
    env.close()
