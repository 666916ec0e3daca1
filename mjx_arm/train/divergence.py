"""A diverged training run stops with a named error before its params reach a checkpoint.

After each epoch the run checks that every floating-point leaf of its training state (policy and
value params, optimiser moments, observation normaliser) and every loss of the epoch is finite.
A NaN or an infinity there never recovers: the next checkpoint would hold it, and the policy it
exports would act NaN. :class:`TrainingDivergedError` names the settings that drive the step size
(``learning_rate`` first, with its value and default) so that the one-line error says what to
change; nothing of the diverged epoch is saved.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from mjx_arm.envs.base import InvalidActionError
from mjx_arm.inputs import ConfigError
from mjx_arm.train.config import TrainConfig

# Settings that scale the update or its gradients, in the order a message names them.
STEP_SETTINGS = ("learning_rate", "reward_scaling", "max_grad_norm", "entropy_cost")
# Epoch metrics that are settings, not results (the learner logs its learning rate).
SETTING_METRICS = ("learning_rate",)


class TrainingDivergedError(ConfigError):
    """Training produced non-finite params or losses: a setting makes the updates blow up."""


@jax.jit
def _all_finite(tree: Any) -> jax.Array:
    """Whether every floating-point leaf of ``tree`` is finite (a scalar bool)."""
    leaves = [jnp.asarray(x) for x in jax.tree.leaves(tree)]
    leaves = [x for x in leaves if jnp.issubdtype(x.dtype, jnp.floating)]
    return jnp.all(jnp.asarray([jnp.all(jnp.isfinite(x)) for x in leaves] or [True]))


def _defaults() -> dict[str, Any]:
    return {f.name: f.default for f in dataclasses.fields(TrainConfig) if f.name in STEP_SETTINGS}


def advice(config: TrainConfig) -> str:
    """Which settings to change: ``learning_rate`` with its value and default, then each other
    step setting that differs from its default."""
    defaults = _defaults()
    rate, default_rate = config.learning_rate, defaults["learning_rate"]
    suggested = default_rate if rate > default_rate else rate / 10
    text = (
        f"Lower learning_rate (now {rate:g}, default {default_rate:g}), e.g. "
        f"--set learning_rate={suggested:g}"
    )
    changed = [
        f"{name} = {getattr(config, name):g} (default {defaults[name]:g})"
        for name in STEP_SETTINGS[1:]
        if getattr(config, name) != defaults[name]
    ]
    if changed:
        text += ", or set back to the default " + ", ".join(changed)
    return text


def non_finite_metrics(metrics: dict[str, Any]) -> list[str]:
    """Names of the epoch's losses ``metrics`` (arrays of any shape) holding NaN or inf."""
    bad = []
    for name, value in metrics.items():
        if name in SETTING_METRICS:
            continue
        values = np.asarray(value)
        if values.dtype.kind == "f" and not np.all(np.isfinite(values)):
            bad.append(name)
    return sorted(bad)


@contextlib.contextmanager
def rollout_guard(config: TrainConfig, step: int) -> Iterator[None]:
    """Turn a non-finite action of the policy in a checkpoint's rollout (the env's
    :class:`~mjx_arm.envs.base.InvalidActionError`, raised before anything is written) into a
    :class:`TrainingDivergedError` that names the setting to change.

    Raises:
        TrainingDivergedError: the policy of ``step`` acted NaN or inf.
    """
    try:
        yield
    except InvalidActionError as err:
        if "NaN or inf" not in str(err):
            raise
        raise TrainingDivergedError(
            f"training diverged at step {step}: the policy acted NaN or inf in the checkpoint's "
            f"rollout; no checkpoint of this epoch was written. {advice(config)}"
        ) from err


def check_epoch(config: TrainConfig, step: int, state: Any, metrics: dict[str, Any]) -> None:
    """Stop a run whose training ``state`` or epoch ``metrics`` hold NaN or inf at ``step``.

    Raises:
        TrainingDivergedError: what is non-finite, at which step, and which setting to change.
    """
    bad = non_finite_metrics(metrics)
    params_ok = bool(_all_finite(state))
    if params_ok and not bad:
        return
    losses = [n for n in bad if n.endswith("loss")] or bad
    what = [] if params_ok else ["params"]
    if bad:
        shown = ", ".join(losses[:2]) + (", ..." if len(losses) > 2 else "")
        what.append(f"{len(bad)} metrics ({shown})")
    raise TrainingDivergedError(
        f"training diverged at step {step}: non-finite {' and '.join(what)}; no checkpoint of "
        f"this epoch was written. {advice(config)}"
    )
