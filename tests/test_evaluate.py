"""Evaluation of an exported policy (:mod:`mjx_arm.evaluate`, ``mjx-arm eval``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_policy import trained_run_dir

from mjx_arm.cli import EXIT_OK, main
from mjx_arm.evaluate import (
    EpisodeStats,
    eval_task,
    evaluate,
    make_eval_env,
    run_batched,
    run_episodes,
    summarize,
    wilson_interval,
)
from mjx_arm.policy import export_policy, load
from mjx_arm.replay import rendering_available


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return trained_run_dir(tmp_path_factory)


@pytest.fixture(scope="module")
def policy_path(run_dir: Path, tmp_path_factory) -> Path:
    return export_policy(run_dir, tmp_path_factory.mktemp("eval") / "policy.npz")


# reading a video back starts ffmpeg: JAX warns about any fork, harmless here (exec follows)
pytestmark = pytest.mark.filterwarnings("ignore:os.fork")
needs_render = pytest.mark.skipif(not rendering_available()[0], reason=rendering_available()[1])


def _check_sane(result: dict, episodes: int) -> None:
    low, high = result["success_ci95"]
    assert result["episodes"] == episodes
    assert 0.0 <= low <= result["success_rate"] <= high <= 1.0
    assert math.isfinite(result["mean_return"]) and result["mean_return"] < 0
    assert result["mean_peak_contact_force"] >= 0.0
    steps = result["mean_steps_to_success"]
    assert steps is None or 1 <= steps <= 150
    assert len(result["per_episode"]) == episodes


# --------------------------------------------------------------------------- statistics


@pytest.mark.parametrize(
    ("successes", "n", "expected"),
    [(5, 10, (0.2366, 0.7634)), (0, 10, (0.0, 0.2775)), (10, 10, (0.7225, 1.0)), (0, 0, (0, 1))],
)
def test_wilson_interval_worked_values(successes, n, expected):
    np.testing.assert_allclose(wilson_interval(successes, n), expected, atol=1e-4)


def test_summarize_hand_worked():
    episodes = [
        EpisodeStats(-10.0, 5, True, 5, 2.0, 0.01),
        EpisodeStats(-30.0, 150, False, None, 4.0, 0.2),
    ]
    s = summarize(episodes)
    assert s["success_rate"] == 0.5 and s["successes"] == 1
    assert s["mean_return"] == -20.0 and s["mean_steps_to_success"] == 5.0
    assert s["mean_peak_contact_force"] == 3.0 and s["mean_episode_steps"] == 77.5


# --------------------------------------------------------------------------- CPU engines


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_cli_eval_on_cpu_engines(policy_path: Path, tmp_path: Path, engine: str, capsys):
    output = tmp_path / f"{engine}.json"
    argv = ["eval", str(policy_path), "--engine", engine, "--episodes", "12", "-o", str(output)]
    assert main(argv) == EXIT_OK
    result = json.loads(output.read_text())
    _check_sane(result, 12)
    assert result["engine"] == engine and result["task"] == "reach"
    assert "success rate" in capsys.readouterr().out


def test_engines_see_the_same_episodes(policy_path: Path):
    policy = load(policy_path)
    task, _ = eval_task(policy)
    starts = []
    for engine in ("mujoco", "pybullet"):
        env = make_eval_env(task, engine)
        starts.append(run_episodes(policy, env, 2, seed=7).trajectories[1]["obs"][0])
        env.close()
    # same seed: same start pose and target (joint angles and target_rel exactly)
    np.testing.assert_allclose(starts[0][7:16], starts[1][7:16], atol=1e-6)


def test_eval_accepts_a_run_directory(run_dir: Path, tmp_path: Path):
    output = tmp_path / "run.json"
    argv = ["eval", str(run_dir), "--episodes", "3", "--task", "touch", "-o", str(output)]
    assert main(argv) == EXIT_OK
    result = json.loads(output.read_text())
    assert "checkpoint step" in result["policy"]
    assert result["task"] == "touch"
    assert any("trained on reach" in note for note in result["notes"])


@needs_render
def test_runner_films_the_first_episodes(policy_path: Path, tmp_path: Path):
    import imageio.v3 as iio

    policy = load(policy_path)
    task, _ = eval_task(policy)
    env = make_eval_env(task, "mujoco", render=True, width=160, height=120)
    run = run_episodes(policy, env, 3, seed=0, video=tmp_path / "v.mp4", video_episodes=2)
    env.close()
    expected = sum(e.steps + 1 for e in run.episodes[:2])  # the reset frame, then one per step
    assert run.frames == expected
    frames = iio.imread(tmp_path / "v.mp4")
    assert frames.shape == (expected, 120, 160, 3)


def test_runner_notes_an_env_without_render_mode(policy_path: Path, tmp_path: Path):
    policy = load(policy_path)
    env = make_eval_env(eval_task(policy)[0], "mujoco")
    run = run_episodes(policy, env, 1, video=tmp_path / "v.mp4")
    env.close()
    assert run.frames == 0 and "render_mode" in run.notes[0]


# --------------------------------------------------------------------------- batched env


def test_batched_runner_on_the_c_mujoco_backend(policy_path: Path):
    """The JAX batch (C MuJoCo backend: MJX's stand-in on a CPU) gives sane numbers."""
    policy = load(policy_path)
    task, _ = eval_task(policy)
    run = run_batched(policy, task, 8, seed=0, backend="mujoco")
    assert len(run.episodes) == 8
    assert all(1 <= e.steps <= task.episode_steps for e in run.episodes)
    for e in run.episodes:
        assert e.success == (e.steps_to_success is not None)
    traj = run.trajectory
    assert traj["obs"].shape == (run.episodes[0].steps, 22)
    assert np.isclose(traj["reward"].sum(), run.episodes[0].episode_return, rtol=1e-5)


def test_evaluate_rejects_unknown_engines(policy_path: Path):
    with pytest.raises(ValueError, match="engine"):
        evaluate(load(policy_path), "gazebo", eval_task(load(policy_path))[0], 1)


def test_eval_without_a_renderer_notes_the_skipped_video(policy_path: Path, tmp_path, monkeypatch):
    import mjx_arm.replay

    monkeypatch.setattr(mjx_arm.replay, "rendering_available", lambda: (False, "no EGL (test)"))
    policy = load(policy_path)
    result, run = evaluate(policy, "mujoco", eval_task(policy)[0], 2, video=tmp_path / "v.mp4")
    assert result["video"] is None and run.frames == 0
    assert result["notes"] == ["video skipped: no EGL (test)"]
    assert not (tmp_path / "v.mp4").exists()


# --------------------------------------------------------------------------- the eval command


def test_cli_eval_prints_a_table_and_json_only_when_asked(policy_path: Path, capsys):
    argv = ["eval", str(policy_path), "--episodes", "3"]
    assert main(argv) == EXIT_OK
    out = capsys.readouterr().out
    assert "success rate" in out and not any(line.startswith("{") for line in out.splitlines())
    assert main([*argv, "--json"]) == EXIT_OK
    (line,) = capsys.readouterr().out.splitlines()  # one JSON line, nothing else
    result = json.loads(line)
    assert result["episodes"] == 3 and "per_episode" not in result


@needs_render
def test_cli_eval_films_the_first_episodes_and_says_which(
    policy_path: Path, tmp_path: Path, capsys
):
    import imageio.v3 as iio

    video, output = tmp_path / "v.mp4", tmp_path / "r.json"
    argv = ["eval", str(policy_path), "--episodes", "3", "--seed", "4", "--video", str(video)]
    argv += ["--width", "160", "--height", "120", "-o", str(output)]
    for extra, filmed in (([], 3), (["--video-episodes", "1"], 1)):  # default: every one of 3
        assert main([*argv, *extra]) == EXIT_OK
        result = json.loads(output.read_text())
        frames = sum(e["steps"] + 1 for e in result["per_episode"][:filmed])  # reset + steps
        assert result["video_frames"] == frames == len(iio.imread(video))
        assert result["video_episodes"] == filmed
        seeds = "seeds 4-6" if filmed == 3 else "seed 4"
        shown = f"video: {video} (the first {filmed} of 3 episodes ({seeds}), {frames} frames)"
        assert shown in capsys.readouterr().out


def test_cli_eval_of_the_batched_env_takes_a_backend_and_shows_its_compile(
    policy_path: Path, tmp_path: Path, capsys
):
    output = tmp_path / "mjx.json"
    argv = ["eval", str(policy_path), "--engine", "mjx", "--backend", "mujoco"]
    assert main([*argv, "--episodes", "4", "-o", str(output)]) == EXIT_OK
    result = json.loads(output.read_text())
    assert result["engine"] == "mjx" and result["backend"] == "mujoco"
    captured = capsys.readouterr()
    assert "mjx (backend mujoco), task reach: 4 episodes" in captured.out
    err = captured.err.splitlines()
    assert err[0] == "compiling the batched env (4 envs, backend mujoco) ..."
    assert any(
        line.startswith("compiled the batched env (4 envs, backend mujoco) in ") for line in err
    )


def test_compile_clock_speaks_while_it_waits() -> None:
    import io
    import time

    from mjx_arm.jax_cache import CompileClock

    stream = io.StringIO()
    clock = CompileClock("a program", "hint", every=0.05, stream=stream)
    time.sleep(0.3)
    seconds = clock.stop()
    assert clock.stop() >= seconds  # a second stop says nothing more
    lines = stream.getvalue().splitlines()
    assert lines[0] == "compiling a program (hint) ..."
    assert sum(line.startswith("  still compiling a program: ") for line in lines) >= 2
    assert lines[-1] == f"compiled a program in {seconds:.0f} s"
    assert sum(line.startswith("compiled") for line in lines) == 1


def test_eval_on_another_task_names_what_it_kept_in_words(policy_path: Path) -> None:
    _, notes = eval_task(load(policy_path), "touch")
    assert notes and "{" not in notes[0] and "with ctrl_dt " in notes[0]


def test_cli_eval_writes_a_250_byte_file_name(policy_path: Path, tmp_path: Path) -> None:
    output = tmp_path / ("r" * 245 + ".json")
    assert main(["eval", str(policy_path), "--episodes", "1", "-o", str(output)]) == EXIT_OK
    assert json.loads(output.read_text())["episodes"] == 1
