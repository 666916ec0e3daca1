"""``mjx-arm deploy-sim``: the whole command chain closed around a position-controlled sim arm.

policy -> action -> joint velocity targets -> :class:`VelocityToPositionAdapter` ->
:class:`SafetyLimiter` -> position targets -> position servos of a copy of the sim arm (the
stand-in for the robot, :mod:`mjx_arm.sim2real.position_env`) -> observation -> policy. The same
policy also runs on the normal, velocity-controlled env with the same episode seeds, and the two
are compared.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.arm.info import arm_info
from mjx_arm.arm.resolve import resolve_task
from mjx_arm.evaluate import (
    EvalRun,
    Policy,
    check_policy_fits,
    eval_arm,
    eval_task,
    make_eval_env,
    run_episodes,
    summarize,
)
from mjx_arm.inputs import write_atomic
from mjx_arm.sim2real.commands import ServojConfig, joint_trajectory_msg, urscript_program
from mjx_arm.sim2real.position_env import EpisodeCommands, make_position_env
from mjx_arm.sim2real.settings import DeployConfig
from mjx_arm.task.config import TaskConfig

# Universal Robots' joint names, base to wrist: URScript's servoj drives these six joints.
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
# The first line of every URScript program mjx-arm writes (commands.urscript_program).
URSCRIPT_START = b"def mjx_arm_servo():"


def ur_like(joint_names: tuple[str, ...]) -> bool:
    """Whether an arm's joints are a Universal Robots arm's, the only arms URScript runs on:
    six, named as UR names them (a prefix such as ``robot_`` allowed)."""
    return len(joint_names) == len(UR_JOINTS) and all(
        name.endswith(ur) for name, ur in zip(joint_names, UR_JOINTS, strict=True)
    )


def written_urscript(path: Path) -> bool:
    """Whether the file ``path`` is a URScript program mjx-arm wrote (its first line)."""
    if not path.is_file():
        return False
    with path.open("rb") as f:
        return f.read(len(URSCRIPT_START)) == URSCRIPT_START


def _stats(values: list[np.ndarray]) -> dict[str, float | None]:
    flat = np.concatenate([np.ravel(v) for v in values]) if values else np.zeros(0)
    if flat.size == 0:
        return {"max": None, "mean": None}
    return {"max": float(flat.max()), "mean": float(flat.mean())}


def tracking_error(episodes: list[EpisodeCommands]) -> dict[str, float | None]:
    """Max and mean of ``|measured - command|`` (rad) over every joint and step."""
    errors = []
    for e in episodes:
        a = e.arrays()
        errors.append(np.abs(a["measured"] - a["commands"]))
    return _stats(errors)


def ee_deviation(velocity_run: EvalRun, position_run: EvalRun) -> dict[str, float | None]:
    """Max and mean distance (m) between the end-effector paths of the two runs, episode by
    episode, over the steps both ran (episodes stop at success)."""
    gaps = []
    for tv, tp in zip(velocity_run.trajectories, position_run.trajectories, strict=True):
        n = min(len(tv["ee_pos"]), len(tp["ee_pos"]))
        gaps.append(np.linalg.norm(tv["ee_pos"][:n] - tp["ee_pos"][:n], axis=1))
    return _stats(gaps)


def _run_closed(policy: Policy, env: Any, episodes: int, seed: int) -> tuple[EvalRun, Any]:
    """Run ``episodes`` episodes from ``seed`` on ``env``, close it; (the run, the bare env)."""
    try:
        return run_episodes(policy, env, episodes, seed), env.unwrapped
    finally:
        env.close()


def deploy_sim(
    policy: Policy,
    engine: str = "mujoco",
    episodes: int = 20,
    seed: int = 0,
    config: DeployConfig | None = None,
    task: TaskConfig | None = None,
    arm: Any = None,
) -> dict[str, Any]:
    """Run ``policy`` through the chain on a position-controlled arm and on the normal env.

    Episode ``i`` of both runs is reset with ``seed + i`` (same start pose and target).

    Args:
        policy: observation -> action, e.g. :func:`mjx_arm.policy.load`'s result.
        engine: "mujoco" or "pybullet".
        episodes: episodes per run.
        seed: seed of the first episode.
        config: the chain's settings.
        task: the task (default: the one the policy was trained on).
        arm: a URDF or an arm file (default: the arm the policy records; see
            :func:`mjx_arm.evaluate.eval_arm`).

    Returns:
        A JSON-ready report: ``velocity_control`` and ``position_control`` summaries (success
        rate with its 95 % interval, return, steps to success), ``tracking_error_rad``
        (position run: the arm against the commands), ``ee_deviation_m`` (position run against
        the velocity run), ``limiter_clips``, the servo gains, the settings, and
        ``"commands"``: the position run's longest episode (its ``index`` and ``seed``, and
        :meth:`EpisodeCommands.arrays`: numpy arrays, for :func:`write_commands`).
    """
    config = config or DeployConfig()
    task = task or eval_task(policy)[0]
    arm = eval_arm(policy, arm)
    check_policy_fits(policy, task, arm_info(arm))
    setup = resolve_task(task, arm)  # once: both envs take it as it is
    velocity_run, _ = _run_closed(policy, make_eval_env(setup, engine), episodes, seed)
    position_env = make_position_env(setup, engine, config.chain())
    position_run, base = _run_closed(policy, position_env, episodes, seed)
    head = {"engine": engine, "task": task.task, "episodes": episodes, "seed": seed}
    runs = _compare(velocity_run, position_run, base, config, range(seed, seed + episodes))
    return {**head, **runs, "ctrl_dt": task.ctrl_dt}


def _compare(
    velocity_run: EvalRun, position_run: EvalRun, base: Any, config: DeployConfig, seeds: range
) -> dict[str, Any]:
    """The two runs side by side: summaries, tracking, deviation, the longest episode's commands.

    ``base`` is the position env, unwrapped; ``seeds`` are the episodes' seeds; the keys are
    :func:`deploy_sim`'s.
    """
    longest = max(range(len(seeds)), key=lambda i: len(base.episodes[i].commands))
    return {
        "velocity_control": summarize(velocity_run.episodes),
        "position_control": summarize(position_run.episodes),
        "tracking_error_rad": tracking_error(base.episodes),
        "ee_deviation_m": ee_deviation(velocity_run, position_run),
        "limiter_clips": base.limiter.clip_summary(),
        "servo_gains": base.gains.to_dict(base.arm.joint_names),
        "settings": asdict(config),
        "commands": {
            "index": longest,
            "seed": seeds[longest],
            **base.episodes[longest].arrays(),
        },
        "joint_names": list(base.arm.joint_names),
    }


def write_commands(
    report: dict[str, Any],
    config: DeployConfig,
    script_path: str | Path | None,
    trajectory_path: str | Path | None,
) -> None:
    """Write one episode's commands as a URScript program and/or a JointTrajectory JSON.

    Args:
        report: :func:`deploy_sim`'s result.
        config: the chain's settings (the ``servoj`` arguments).
        script_path: ``.script`` file to write, or None.
        trajectory_path: ``.json`` file to write, or None.
    """
    episode, names, dt = report["commands"], report["joint_names"], report["ctrl_dt"]
    if script_path is not None:
        servoj = ServojConfig(t=dt, lookahead_time=config.lookahead_time, gain=config.gain)
        text = urscript_program(episode["commands"], servoj, names)
        write_atomic(text.encode(), Path(script_path))
    if trajectory_path is not None:
        msg = joint_trajectory_msg(episode["commands"], dt, names, episode["velocities"])
        write_atomic(json.dumps(msg, indent=1).encode(), Path(trajectory_path))
