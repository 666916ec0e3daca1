"""The learning rate of PPO's optimiser: constant, or adapted to a KL target.

The adaptive rule is the one robot-learning PPO trainers use for manipulation (RSL-RL, rl_games):
after each minibatch's gradient is computed, the KL divergence between the policy that collected
the rollout and the current one is measured; above ``2 * desired_kl`` the rate is divided by
``factor``, below ``desired_kl / 2`` it is multiplied by it, always within ``[minimum,
maximum]``. The rate then lives in the optimiser's state (``optax.inject_hyperparams``), so it is
checkpointed with the Adam moments and a resumed run goes on with the rate it had.

Everything here runs inside the jitted update: pure functions of arrays, no host state.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from mjx_arm.inputs import ConfigError
from mjx_arm.settings import check_range, check_types, config_fields

if TYPE_CHECKING:
    import optax

SCHEDULES = ("constant", "adaptive")


@dataclass(frozen=True)
class ScheduleConfig:
    """How the learning rate moves during a run. Saved with every run (``config.json``).

    Attributes:
        kind: "constant" (``learning_rate`` throughout) or "adaptive" (starts at
            ``learning_rate``, then follows the KL rule above).
        desired_kl: the KL target of the adaptive rule (per minibatch, mean over its
            transitions, of the Gaussian before the tanh).
        factor: what the rate is multiplied or divided by when the KL leaves the band.
        minimum, maximum: bounds of the adaptive rate.
    """

    kind: str = "constant"
    desired_kl: float = 0.01
    factor: float = 1.5
    minimum: float = 1e-5
    maximum: float = 1e-2

    def __post_init__(self) -> None:
        check_types(self, "schedule.")
        if self.kind not in SCHEDULES:
            raise ConfigError(f"schedule.kind must be one of {SCHEDULES}, got {self.kind!r}")
        check_range(self, ("desired_kl", "minimum", "maximum"), above=0, prefix="schedule.")
        check_range(self, ("factor",), above=1, prefix="schedule.")
        if self.minimum > self.maximum:
            raise ConfigError(
                f"schedule.minimum ({self.minimum:g}) must not exceed schedule.maximum "
                f"({self.maximum:g})"
            )

    @property
    def adaptive(self) -> bool:
        """Whether the rate follows the KL rule."""
        return self.kind == "adaptive"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ScheduleConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        return cls(**config_fields(cls, data, "schedule config"))


def make_optimizer(
    learning_rate: float,
    max_grad_norm: float,
    schedule: ScheduleConfig,
    per_network: bool = False,
) -> optax.GradientTransformation:
    """Adam after global-norm clipping; with an adaptive schedule the rate is a hyperparameter
    held in the optimiser's state (read and set with :func:`current_rate`, :func:`with_rate`).
    ``per_network``: the policy's and the value's gradients are clipped to ``max_grad_norm``
    each (:func:`clip_each_network`), instead of one norm over both.

    A constant schedule builds the same optimiser (and state layout) as runs before schedules
    existed, so their checkpoints resume unchanged; so does either clip.
    """
    import optax

    global_clip = optax.clip_by_global_norm
    clip = (clip_each_network if per_network else global_clip)(max_grad_norm)
    if not schedule.adaptive:
        return optax.chain(clip, optax.adam(learning_rate))
    adam = optax.inject_hyperparams(optax.adam)(learning_rate=learning_rate)
    return optax.chain(clip, adam)


def clip_each_network(max_norm: float) -> optax.GradientTransformation:
    """Global-norm clipping applied to the ``policy`` and the ``value`` part of the updates
    apart (Brax's PPO params), so that a value gradient thousands of times the policy's does not
    shrink the policy's step with it. Its state is the global clip's (empty)."""
    import optax

    clip = optax.clip_by_global_norm(max_norm)

    def update(updates: Any, state: Any, params: Any = None) -> tuple[Any, Any]:
        policy, _ = clip.update(updates.policy, state)
        value, _ = clip.update(updates.value, state)
        return updates.replace(policy=policy, value=value), state

    return optax.GradientTransformation(clip.init, update)


def current_rate(optimizer_state: Any, learning_rate: float) -> Any:
    """The rate the next update takes: the state's (adaptive) or ``learning_rate`` (constant).

    Returns:
        A float32 scalar array.
    """
    import jax.numpy as jnp

    inner = optimizer_state[1]
    if hasattr(inner, "hyperparams"):
        return jnp.asarray(inner.hyperparams["learning_rate"], jnp.float32)
    return jnp.asarray(learning_rate, jnp.float32)


def adapted_rate(rate: Any, kl: Any, schedule: ScheduleConfig) -> Any:
    """The KL rule: ``rate`` divided by ``factor`` above ``2 * desired_kl``, multiplied by it
    below ``desired_kl / 2`` (a KL of exactly 0, nothing measured, leaves it), clipped to the
    bounds.

    Args:
        rate: the current rate, a scalar.
        kl: the minibatch's mean KL between the rollout's policy and the current one, a scalar.
        schedule: the rule's settings.
    """
    import jax.numpy as jnp

    high, low = kl > 2.0 * schedule.desired_kl, (kl < 0.5 * schedule.desired_kl) & (kl > 0.0)
    rate = jnp.where(high, rate / schedule.factor, jnp.where(low, rate * schedule.factor, rate))
    return jnp.clip(rate, schedule.minimum, schedule.maximum).astype(jnp.float32)


def with_rate(optimizer_state: Any, rate: Any) -> Any:
    """``optimizer_state`` (an adaptive schedule's) with its learning rate set to ``rate``."""
    import jax.numpy as jnp

    clip_state, inner = optimizer_state
    hyperparams = {**inner.hyperparams, "learning_rate": jnp.asarray(rate, jnp.float32)}
    return (clip_state, inner._replace(hyperparams=hyperparams))
