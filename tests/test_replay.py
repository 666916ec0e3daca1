"""Trajectory replay: plot and MuJoCo video (:mod:`mjx_arm.replay`, ``mjx-arm replay``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_policy import trained_run_dir

from mjx_arm.cli import EXIT_INVALID, EXIT_OK, main
from mjx_arm.replay import (
    largest_reward_drop,
    load_trajectory,
    rendering_available,
    save_trajectory,
    trajectory_task,
)
from mjx_arm.task import reach_config, touch_config

# reading a video back starts ffmpeg: JAX warns about any fork, harmless here (exec follows)
pytestmark = pytest.mark.filterwarnings("ignore:os.fork")
needs_render = pytest.mark.skipif(not rendering_available()[0], reason=rendering_available()[1])


@pytest.fixture(scope="module")
def transitions(tmp_path_factory) -> Path:
    from mjx_arm.train.rundir import RunDir

    run_dir = trained_run_dir(tmp_path_factory)
    return RunDir(run_dir).latest_checkpoint() / "transitions.npz"


def _synthetic(steps: int = 12) -> dict[str, np.ndarray]:
    """A made-up trajectory: the base turning from home, the reward dropping by 5 at step 7."""
    from mjx_arm.arm.config import SHIPPED_HOME_QPOS

    obs = np.zeros((steps, 22), np.float32)
    obs[:, 7:13] = SHIPPED_HOME_QPOS
    obs[:, 7] = np.linspace(0.0, 0.5, steps)  # distinct frames (a GIF merges equal ones)
    obs[:, 13:16] = (0.5, 0.1, 0.04)
    reward = -np.linspace(5.0, 1.0, steps)
    reward[7:] -= 5.0
    return {
        "obs": obs,
        "action": np.zeros((steps, 6), np.float32),
        "reward": reward,
        "done": np.zeros(steps, bool),
        "ee_pos": np.tile([0.5, 0.1, 0.3], (steps, 1)),
        "contact_force": np.linspace(0.0, 3.0, steps),
    }


@pytest.mark.parametrize(
    ("force", "limits"),
    [
        (np.array([2.5e-12, 4e-13, 3e-13, 6e-13]), (-0.1, 5.0)),  # noise in free space: flat
        (np.zeros(5), (-0.1, 5.0)),
        (np.array([0.0, 10.0, 30.0, 20.0]), (-0.63, 31.5)),  # a press: the data and 5 %
        (np.array([[0.0, 1.0], [2.0, 8.0]]), (-0.168, 8.4)),  # one column per finger pad
    ],
)
def test_a_force_axis_spans_at_least_a_few_newtons(force: np.ndarray, limits: tuple) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mjx_arm.replay import FORCE_AXIS_MIN_N, _plot_force, force_axis_limits

    assert FORCE_AXIS_MIN_N == 5.0
    np.testing.assert_allclose(force_axis_limits(force), limits, atol=1e-9)
    fig, ax = plt.subplots()
    try:
        _plot_force(ax, np.arange(len(force)), force)
        np.testing.assert_allclose(ax.get_ylim(), limits, atol=1e-9)  # what the plot shows
    finally:
        plt.close(fig)


def test_largest_reward_drop_hand_worked():
    assert largest_reward_drop(np.array([0.0, 1.0, -2.0, -1.0, -4.5])) == 4
    assert largest_reward_drop(np.array([0.0, 1.0, 2.0])) is None
    assert largest_reward_drop(np.array([3.0])) is None
    assert largest_reward_drop(_synthetic()["reward"]) == 7


@needs_render
def test_replay_writes_png_of_the_size_and_a_playable_video(transitions: Path, tmp_path: Path):
    import imageio.v3 as iio

    png, video = tmp_path / "plot.png", tmp_path / "replay.mp4"
    argv = ["replay", str(transitions), "-o", str(png), "--video", str(video)]
    assert main([*argv, "--width", "320", "--height", "240"]) == EXIT_OK
    assert iio.imread(png).shape[:2] == (240, 320)
    steps = len(np.load(transitions)["reward"])
    frames = iio.imread(video)
    assert frames.shape == (steps, 240, 320, 3)
    assert frames.std() > 5  # a scene, not a blank frame


@needs_render
def test_replay_renders_larger_than_the_default_framebuffer(tmp_path: Path):
    import imageio.v3 as iio

    path = save_trajectory(tmp_path / "t.npz", _synthetic(3), touch_config())
    video = tmp_path / "big.gif"
    assert main(["replay", str(path), "-o", str(tmp_path / "p.png"), "--video", str(video),
                 "--width", "800", "--height", "600"]) == EXIT_OK  # fmt: skip
    assert iio.imread(video).shape == (3, 600, 800, 3)


def test_replay_of_an_eval_trajectory(tmp_path: Path, capsys):
    import imageio.v3 as iio

    path = save_trajectory(tmp_path / "traj.npz", _synthetic(), touch_config())
    png = tmp_path / "p.png"
    assert main(["replay", str(path), "-o", str(png)]) == EXIT_OK
    out = capsys.readouterr().out
    assert "largest reward drop at step 7" in out and "touch" in out
    assert iio.imread(png).shape[:2] == (600, 800)


def test_task_comes_from_the_file_or_the_run_directory(transitions: Path, tmp_path: Path):
    path = save_trajectory(tmp_path / "t.npz", _synthetic(), reach_config(action_scale=0.3))
    task, source = trajectory_task(path, load_trajectory(path))
    assert task.task == "reach" and task.action_scale == 0.3 and "file" in source
    task, source = trajectory_task(transitions, load_trajectory(transitions))
    assert task.task == "reach" and source.endswith("config.json")
    assert trajectory_task(path, load_trajectory(path), "touch")[0].task == "touch"


def test_a_config_json_of_no_run_is_not_read(tmp_path: Path, capsys):
    """A trajectory two folders below an unrelated config.json (one replay would refuse), and
    one laid out like a checkpoint's but without its meta.json: neither reads that file; the
    plot is drawn with the default task."""
    (tmp_path / "config.json").write_text('{"task": {"task": "no such task"}}')
    rows = _synthetic()
    for where in ("a/b/t.npz", "checkpoints/step_1/transitions.npz"):
        path = tmp_path / where
        path.parent.mkdir(parents=True)
        np.savez_compressed(path, **rows)  # no task_config of its own
        task, source = trajectory_task(path, load_trajectory(path))
        assert task.task == "touch" and source.startswith("default"), where
        assert main(["replay", str(path), "-o", str(tmp_path / "p.png")]) == EXIT_OK
        assert "config.json" not in capsys.readouterr().out


def test_replay_rejects_other_files(tmp_path: Path, capsys):
    np.savez(tmp_path / "x.npz", reward=np.zeros(3))
    assert main(["replay", str(tmp_path / "x.npz"), "-o", str(tmp_path / "p.png")]) == EXIT_INVALID
    assert "not a trajectory file" in capsys.readouterr().err


def test_no_renderer_skips_the_video_with_a_note(tmp_path: Path):
    """Without a working GL backend the plot is still written and the video skipped."""
    path = save_trajectory(tmp_path / "t.npz", _synthetic(), reach_config())
    png, video = tmp_path / "p.png", tmp_path / "v.mp4"
    argv = ["replay", str(path), "-o", str(png), "--video", str(video)]
    code = f"import sys; from mjx_arm.cli import main; sys.exit(main({argv!r}))"
    env = {**os.environ, "MUJOCO_GL": "no-such-backend"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "video skipped" in done.stdout and "MUJOCO_GL=no-such-backend" in done.stdout
    assert png.is_file() and not video.exists()


ROBOTS = Path(__import__("sysconfig").get_paths()["purelib"]) / (
    "cmeel.prefix/share/example-robot-data/robots"
)
needs_robots = pytest.mark.skipif(
    not ROBOTS.is_dir(), reason="example-robot-data is not installed (pip install -e '.[test]')"
)


def _recorded_on(urdf: Path, path: Path, steps: int = 4) -> list[np.ndarray]:
    """Record ``steps`` steps of Reach on ``urdf`` in CPU MuJoCo into the trajectory ``path``
    (with its task and arm, as eval --trajectory writes it); the env's own frames of them."""
    from mjx_arm.evaluate import make_eval_env, run_episode

    env = make_eval_env(reach_config(), "mujoco", True, 160, 120, arm=urdf)
    frames: list[np.ndarray] = []
    action = np.linspace(-0.8, 0.8, env.action_space.shape[0]).astype(np.float32)
    try:
        _, traj = run_episode(
            lambda obs: action, env, 3, lambda: len(frames) < steps and frames.append(env.render())
        )
    finally:
        env.close()
    rows = {k: v[:steps] for k, v in traj.items()}
    save_trajectory(path, rows, env.unwrapped.task, env.unwrapped.arm.config)
    return frames


@needs_render
@needs_robots
@pytest.mark.parametrize(
    "name", ["panda_description/urdf/panda.urdf", "ur_description/urdf/ur5_robot.urdf"]
)
def test_replay_draws_the_arm_the_trajectory_was_recorded_on(name: str, tmp_path: Path, capsys):
    """A 7-joint Panda, and a 6-joint UR5 of another make than the shipped UR5e: the video is
    of that arm, frame for frame what the env drew (within 1 of 255 levels on average), and
    --arm draws another arm."""
    from mjx_arm.replay import render_frames, trajectory_arm

    urdf, path = ROBOTS / name, tmp_path / "t.npz"
    drawn = _recorded_on(urdf, path)
    video = tmp_path / "v.mp4"
    argv = ["replay", str(path), "-o", str(tmp_path / "p.png"), "--video", str(video)]
    assert main([*argv, "--width", "160", "--height", "120"]) == EXIT_OK
    assert f"arm: {urdf} (from the trajectory file)" in capsys.readouterr().out
    traj = load_trajectory(path)
    arm, where = trajectory_arm(path, traj)
    assert arm.urdf_path == urdf and where == "the trajectory file"
    task = trajectory_task(path, traj)[0]
    frames = list(render_frames(traj, task, 160, 120, arm))
    assert len(frames) == len(drawn) == 4
    for replayed, own in zip(frames, drawn, strict=True):
        assert np.abs(replayed.astype(float) - own).mean() < 1.0
    if "ur5" in name:  # the shipped UR5e at the same angles draws another picture
        ur5e, where = trajectory_arm(path, traj, "ur5e")
        assert where == "--arm" and ur5e.urdf_path.name == "ur5e.urdf"
        other = next(iter(render_frames(traj, task, 160, 120, ur5e)))
        assert np.abs(other.astype(float) - drawn[0]).mean() > 5.0
    else:  # the 7-joint arm's file on a 6-joint arm: a named error, not a traceback
        assert main([*argv, "--arm", "ur5e"]) == EXIT_INVALID
        err = capsys.readouterr().err
        assert "recorded on an arm of 7 joints; ur5e.urdf has 6" in err and "--arm" in err
