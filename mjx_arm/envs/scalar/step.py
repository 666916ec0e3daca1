"""One env's step as the rules score it: what goes in, what comes out, in Python floats.

:func:`~mjx_arm.task.rules.score_step` takes the progress of the episode, the step's measures
and the arm's joints; a CPU env hands them over as one :class:`StepInput` and reads one
:class:`StepOutcome` back, whether the rules run through
:data:`~mjx_arm.envs.scalar.xp.SCALAR_XP` (:func:`score_generic`) or as the one function traced
from them (:func:`mjx_arm.envs.scalar.codegen.compile_score`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from mjx_arm.envs.scalar.xp import SCALAR_XP
from mjx_arm.task import reward as reward_lib
from mjx_arm.task import rules
from mjx_arm.task.config import TaskConfig


class StepInput(NamedTuple):
    """What the rules score one env's step on (Python scalars and lists of floats).

    Attributes:
        progress: the success rule's hold count (a float) and strike flag before the step.
        prev_distance: the distance (m) from the ee point to the target before the step.
        change: the sum of the squared action change since the previous step.
        distance: the distance (m) after the step.
        force: the contact force norm (N) after the step.
        qpos, qvel: joint angles (rad) and velocities (rad/s), lists of n floats.
        measures: the task's measures in the order of its keys
            (:meth:`mjx_arm.task.spec.Task.measures`), ``(k,)`` floats; empty: none.
    """

    progress: reward_lib.Progress
    prev_distance: float
    change: float
    distance: float
    force: float
    qpos: list[float]
    qvel: list[float]
    measures: tuple[float, ...] = ()


class StepOutcome(NamedTuple):
    """The rules' verdict on one env's step (:class:`~mjx_arm.task.rules.StepScore`'s values as
    Python scalars).

    Attributes:
        progress: the hold count (a float) and strike flag after the step.
        success: whether the episode has succeeded (a bool).
        over_now: whether this step's force was over the limit (a bool).
        terms: the reward terms by name (Python floats, a new dict).
        reward: the weighted total (a float).
        done: whether the episode ends (a bool).
    """

    progress: reward_lib.Progress
    success: bool
    over_now: bool
    terms: dict[str, float]
    reward: float
    done: bool


def score_generic(
    cfg: TaskConfig,
    band: reward_lib.JointBand,
    diverged: bool,
    keys: Sequence[str],
    step: StepInput,
) -> StepOutcome:
    """:func:`~mjx_arm.task.rules.score_step` of one env's step through
    :data:`~mjx_arm.envs.scalar.xp.SCALAR_XP`.

    Args:
        cfg: the task configuration.
        band: the joint-limit band as lists of n floats.
        diverged: score a step whose physics diverged (only the penalty, the episode ends).
        keys: the names of the task's measures, in the order of ``step.measures``.
        step: the step.

    Returns:
        The outcome, each value the type a traced scorer gives.
    """
    extra = dict(zip(keys, step.measures, strict=True)) or None
    score = rules.score_step(
        SCALAR_XP, cfg, step.progress, step.prev_distance, step.change, step.distance,
        step.force, step.qpos, step.qvel, band, diverged, extra,
    )  # fmt: skip
    return StepOutcome(
        reward_lib.Progress(*score.progress),
        bool(score.success),
        bool(score.over),
        score.terms,
        float(score.reward),
        bool(score.done),
    )
