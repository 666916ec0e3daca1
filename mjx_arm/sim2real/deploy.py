"""``mjx-arm deploy-sim``: the whole command chain closed around a position-controlled sim arm.

policy -> action -> joint velocity targets -> :class:`VelocityToPositionAdapter` ->
:class:`SafetyLimiter` -> position targets -> position-controlled env (the sim stand-in for the
robot) -> observation -> policy. The same policy also runs on the normal, velocity-controlled
env with the same episode seeds, and the two are compared.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mjx_arm.envs.base import check_action
from mjx_arm.evaluate import EvalRun, Policy, eval_task, make_env, run_episodes, summarize
from mjx_arm.sim2real.adapter import VelocityToPositionAdapter
from mjx_arm.sim2real.commands import ServojConfig, joint_trajectory_msg, urscript_program
from mjx_arm.sim2real.limiter import JointLimits, LimiterConfig, SafetyLimiter
from mjx_arm.sim2real.position_env import ServoConfig, make_position_env
from mjx_arm.task.config import TaskConfig


@dataclass(frozen=True)
class DeployConfig:
    """Settings of the command chain.

    Attributes:
        tau: time constant (s) of the adapter's low-pass filter. 0.02 s (0.6 control periods)
            smooths the 30 Hz staircase of targets and a policy's bang-bang switches while
            adding only 20 ms of lag.
        limiter: how the limiter's limits are derived from the URDF.
        servo: the position servo of the simulated arm.
        lookahead_time, gain: the ``servoj`` arguments of the written URScript.
    """

    tau: float = 0.02
    limiter: LimiterConfig = field(default_factory=LimiterConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    lookahead_time: float = 0.1
    gain: float = 300.0

    def __post_init__(self) -> None:
        if not self.tau >= 0:
            raise ValueError(f"tau must be >= 0, got {self.tau}")
        ServojConfig(t=1.0, lookahead_time=self.lookahead_time, gain=self.gain)  # range checks


@dataclass
class EpisodeCommands:
    """What the chain sent in one episode and what the arm did.

    Attributes:
        commands: the limiter's position commands (rad), ``(T, 6)``.
        velocities: their velocities (rad/s), ``(T, 6)``.
        measured: joint angles (rad) one control period after each command, ``(T, 6)``.
    """

    commands: list[np.ndarray] = field(default_factory=list)
    velocities: list[np.ndarray] = field(default_factory=list)
    measured: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        """The three lists as ``(T, 6)`` arrays."""
        return {k: np.array(getattr(self, k)).reshape(-1, 6) for k in asdict(self)}


class VelocityCommandChain(gym.Wrapper):
    """A position-controlled env driven through the adapter and the limiter.

    The wrapper takes the contract's action (``Box(-1, 1, (6,))``: joint velocity targets
    ``a * action_scale * v_max``), so any policy of the contract runs on it unchanged. At each
    reset the adapter and the limiter start from the measured joint angles.

    Args:
        env: a position-controlled env (:func:`make_position_env`).
        tau: the adapter's filter time constant (s).
        limits: the limiter's joint limits.
    """

    def __init__(self, env: gym.Env, tau: float, limits: JointLimits) -> None:
        super().__init__(env)
        base = env.unwrapped
        self.task: TaskConfig = base.task
        self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)
        self._qdot_scale = self.task.action_scale * base.arm.v_max
        q0 = np.asarray(self.task.home_qpos, dtype=np.float64)
        dt = self.task.ctrl_dt
        self.adapter = VelocityToPositionAdapter(dt, tau, q0, limits.lower, limits.upper)
        self.limiter = SafetyLimiter(limits, dt, q0)
        self.episodes: list[EpisodeCommands] = []

    def reset(self, **kwargs):
        """Reset the env, then the adapter and the limiter at the measured joint angles."""
        obs, info = self.env.reset(**kwargs)
        q = self.env.unwrapped.measured_qpos()
        self.adapter.reset(q)
        self.limiter.reset(q)
        self.episodes.append(EpisodeCommands())
        return obs, info

    def step(self, action):
        """One contract action through adapter and limiter into the position servo."""
        qdot = check_action(action) * self._qdot_scale
        command = self.limiter(self.adapter.step(qdot))
        result = self.env.step(command)
        log = self.episodes[-1]
        log.commands.append(command)
        log.velocities.append(self.limiter.velocity)
        log.measured.append(self.env.unwrapped.measured_qpos())
        return result


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


def deploy_sim(
    policy: Policy,
    engine: str = "mujoco",
    episodes: int = 20,
    seed: int = 0,
    config: DeployConfig | None = None,
    task: TaskConfig | None = None,
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
    velocity_env = make_env(task, engine)
    try:
        velocity_run = run_episodes(policy, velocity_env, episodes, seed)
    finally:
        velocity_env.close()
    limits = JointLimits.from_urdf(None, config.limiter)
    chain = VelocityCommandChain(make_position_env(task, engine, config.servo), config.tau, limits)
    try:
        position_run = run_episodes(policy, chain, episodes, seed)
    finally:
        chain.close()
    base = chain.unwrapped
    longest = max(range(episodes), key=lambda i: len(chain.episodes[i].commands))
    return {
        "engine": engine,
        "task": task.task,
        "episodes": episodes,
        "seed": seed,
        "velocity_control": summarize(velocity_run.episodes),
        "position_control": summarize(position_run.episodes),
        "tracking_error_rad": tracking_error(chain.episodes),
        "ee_deviation_m": ee_deviation(velocity_run, position_run),
        "limiter_clips": chain.limiter.clip_summary(),
        "servo_gains": base.gains.to_dict(base.arm.joint_names),
        "settings": asdict(config),
        "commands": {
            "index": longest,
            "seed": seed + longest,
            **chain.episodes[longest].arrays(),
        },
        "joint_names": list(base.arm.joint_names),
        "ctrl_dt": task.ctrl_dt,
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
        Path(script_path).write_text(urscript_program(episode["commands"], servoj, names))
    if trajectory_path is not None:
        msg = joint_trajectory_msg(episode["commands"], dt, names, episode["velocities"])
        Path(trajectory_path).write_text(json.dumps(msg, indent=1))
