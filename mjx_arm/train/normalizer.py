"""The running observation normaliser's settings: a floor under each dimension's std, and a
bound on the normalised value.

Brax's normaliser divides by each observation dimension's running std, floored at 1e-6, and
leaves the result unbounded. A dimension that is constant in the first rollouts (the wrist
force of Touch reads exactly 0 until the tool first touches something) then gets a std of 1e-6,
and the first reading of a few newtons enters the policy as millions: the rollout's actions
saturate and the measured KL between the rollout's policy and the updated one reaches 1e13
(measured on the C MuJoCo backend), which also drives a KL-adaptive learning rate to its floor.
A std floor and a clip bound the damage; the policy file records the clip so that exported
policies normalise exactly as training did. ``force_scale`` removes the cause for the wrist
wrench: its entries are divided by a fixed scale in newtons instead of by running statistics.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mjx_arm.settings import check_range, check_types, config_fields

# Brax's own floor: what a run without these settings used.
BRAX_STD_FLOOR = 1e-6


@dataclass(frozen=True)
class NormalizerConfig:
    """Observation normalisation. Saved with every run (``config.json``).

    Attributes:
        std_floor: the smallest std a dimension is divided by (Brax: 1e-6).
        clip: normalised values are clipped to ``[-clip, clip]``; 0 leaves them unbounded.
        after_update: the update's losses read the statistics the rollout acted with, and the
            statistics take in the rollout's observations after the update's gradient steps
            (except the first update's: the statistics are empty until then). False (Brax's
            order): they take them in first, so the update starts from a policy that already
            differs from the rollout's (``training/kl_before_update``).
        force_scale: the ``contact_force`` entries (N and N m) are divided by this fixed scale,
            their mean held at 0, instead of by their running statistics; 0 (Brax): running
            statistics like every other entry. The wrench reads exactly 0 until the tool first
            touches something, so its running std starts at the floor and its first readings
            reach the policy as huge values; a fixed scale (the force band's top, 50 N, for
            Touch) keeps a press in the band under 1 from the first contact on.
    """

    std_floor: float = BRAX_STD_FLOOR
    clip: float = 0.0
    after_update: bool = False
    force_scale: float = 0.0

    def __post_init__(self) -> None:
        check_types(self, "normalizer.")
        check_range(self, ("std_floor",), above=0, prefix="normalizer.")
        check_range(self, ("clip", "force_scale"), low=0, prefix="normalizer.")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NormalizerConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        return cls(**config_fields(cls, data, "normalizer config"))


def normalize_fn(config: NormalizerConfig) -> Callable:
    """Brax's ``running_statistics.normalize`` with this config's clip (none when 0)."""
    from brax.training.acme import running_statistics

    return functools.partial(running_statistics.normalize, max_abs_value=config.clip or None)


def update(
    state: Any, observations: Any, config: NormalizerConfig, force_dims: slice | None = None
) -> Any:
    """The normaliser's state after ``observations`` ``(..., obs_size)``, its std floored and
    the ``force_dims`` of the flat observation at their fixed scale (:func:`fix_force_scale`)."""
    from brax.training.acme import running_statistics

    state = running_statistics.update(state, observations, std_min_value=config.std_floor)
    return fix_force_scale(state, config, force_dims)


def fix_force_scale(state: Any, config: NormalizerConfig, force_dims: slice | None) -> Any:
    """``state`` (Brax's running statistics of the flat observation, mean and std
    ``(obs_size,)``) with mean 0 and std ``config.force_scale`` on ``force_dims`` (where the
    ``contact_force`` entries sit); unchanged when the scale is 0 or the dims are None."""
    if not config.force_scale or force_dims is None:
        return state
    mean = state.mean.at[..., force_dims].set(0.0)
    std = state.std.at[..., force_dims].set(config.force_scale)
    return state.replace(mean=mean, std=std)
