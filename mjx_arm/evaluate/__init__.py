"""Evaluate an exported policy in any engine of the contract, with numbers and a video.

- :func:`run_episodes` is the Gymnasium-side runner: any env of the contract (``gymnasium.make
  ("mjx_arm/Reach-v0", engine="mujoco" | "pybullet")`` or your own), any number of episodes,
  an optional video from the env's ``render()``.
- :func:`run_batched` runs the episodes at once on :class:`~mjx_arm.envs.vector.ArmVectorEnv`
  (MJX, or C MuJoCo behind the same JAX interface).
- :func:`evaluate` is what ``mjx-arm eval`` calls: success rate with its 95 % Wilson interval,
  mean return, mean steps to success, mean peak contact force, as a JSON-ready dict.

Episode ``i`` of a CPU engine is reset with ``seed + i``, so MuJoCo and PyBullet see the same
start poses and targets. The batched env draws its episodes from JAX's generator instead.
"""

from mjx_arm.evaluate.core import (
    DYNAMICS_FIELDS,
    check_policy_fits,
    eval_arm,
    eval_task,
    evaluate,
    format_summary,
    make_eval_env,
    resolve_policy,
)
from mjx_arm.evaluate.runners import Policy, run_batched, run_episode, run_episodes
from mjx_arm.evaluate.stats import EpisodeStats, EvalRun, summarize, wilson_interval

__all__ = [
    "DYNAMICS_FIELDS",
    "EpisodeStats",
    "EvalRun",
    "Policy",
    "check_policy_fits",
    "eval_arm",
    "eval_task",
    "evaluate",
    "format_summary",
    "make_eval_env",
    "resolve_policy",
    "run_batched",
    "run_episode",
    "run_episodes",
    "summarize",
    "wilson_interval",
]
