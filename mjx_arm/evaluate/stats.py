"""What an evaluation counts: per-episode numbers, their summary and the 95 % Wilson interval
of the success rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Z95 = 1.959963984540054


@dataclass
class EpisodeStats:
    """One episode's numbers.

    Attributes:
        episode_return: sum of rewards. steps: control steps taken.
        success: the success rule held at some step.
        steps_to_success: the first step (1-based) it held, else None.
        peak_contact_force: largest contact force norm (N) over the episode.
        final_distance: ee-to-target distance (m) at the last step.
    """

    episode_return: float
    steps: int
    success: bool
    steps_to_success: int | None
    peak_contact_force: float
    final_distance: float


@dataclass
class EvalRun:
    """What :func:`run_episodes` / :func:`run_batched` return.

    Attributes:
        episodes: per-episode numbers.
        trajectories: each episode's arrays (see :mod:`mjx_arm.replay`), ``T_i`` rows; the
            batched runner records env 0's only.
        frames: frames written to the video (0 without one).
        notes: what was skipped and why (e.g. no renderer).
        filmed: episodes in the video, the first ones (0 without one).
    """

    episodes: list[EpisodeStats]
    trajectories: list[dict[str, np.ndarray]]
    frames: int = 0
    notes: list[str] = field(default_factory=list)
    filmed: int = 0

    @property
    def trajectory(self) -> dict[str, np.ndarray]:
        """The first episode's trajectory."""
        return self.trajectories[0]

    def longest_trajectory(self) -> dict[str, np.ndarray]:
        """The trajectory with the most steps (the first of equals)."""
        return max(self.trajectories, key=lambda t: len(t["reward"]))


# --------------------------------------------------------------------------- statistics


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Returns:
        ``(low, high)`` in [0, 1]; ``(0, 1)`` when ``n`` is 0.
    """
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def summarize(episodes: list[EpisodeStats]) -> dict[str, Any]:
    """Success rate, its Wilson 95 % interval and the means of the episodes' numbers."""
    n = len(episodes)
    successes = sum(e.success for e in episodes)
    low, high = wilson_interval(successes, n)
    returns = [e.episode_return for e in episodes]
    return {
        "episodes": n,
        "successes": successes,
        "success_rate": successes / n if n else None,
        "success_ci95": [low, high],
        "mean_return": _mean(returns),
        "std_return": float(np.std(returns)) if returns else None,
        "mean_steps_to_success": _mean(
            [e.steps_to_success for e in episodes if e.steps_to_success is not None]
        ),
        "mean_episode_steps": _mean([e.steps for e in episodes]),
        "mean_peak_contact_force": _mean([e.peak_contact_force for e in episodes]),
        "mean_final_distance": _mean([e.final_distance for e in episodes]),
    }
