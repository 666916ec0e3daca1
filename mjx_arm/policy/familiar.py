"""Observation entries a policy never saw in training, found from its normaliser.

An exported policy divides each observation entry by the std its training measured. An entry that
training held still (Touch's target height: the box top, 0.05 m in every episode) has a std at
the normaliser's floor, 1e-6, so a target 1 mm higher reaches the network as 1,000 and its
actions mean nothing. On a real arm the target comes from the user, not from the task's
sampler: :func:`check_familiar` refuses an observation with an entry more than
:data:`UNFAMILIAR_STD` training stds from the training mean, and names each such entry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.inputs import InputError

# An entry this many training stds from the training mean lies outside anything the policy was
# trained on (its normalised inputs in training: mostly within +-3, rarely past 5).
UNFAMILIAR_STD = 10.0
# A training std at or under this: the entry was held still in training (the floor is 1e-6).
HELD_STILL_STD = 1e-4


class UnfamiliarObservationError(InputError):
    """An observation with entries far outside what the policy was trained on."""


@dataclass(frozen=True)
class Unfamiliar:
    """One observation entry outside the policy's training: its name (``target_rel[2]``), the
    observed value and the training mean and std."""

    name: str
    value: float
    mean: float
    std: float

    @property
    def distance(self) -> float:
        """How many training stds the value lies from the training mean."""
        return abs(self.value - self.mean) / self.std

    def line(self) -> str:
        """The entry in words."""
        text = (
            f"{self.name} = {self.value:.4g} is {self.distance:,.0f} training stds from what the "
            f"policy saw ({self.mean:.4g} +- {self.std:.2g})"
        )
        if self.std <= HELD_STILL_STD:
            text += f": training held it at {self.mean:.4g}, so the policy knows no other value"
        return text


def entry_names(layout: list[tuple[str, int]]) -> list[str]:
    """The flat observation's entry names from a policy's ``obs_layout``: ``key[i]``."""
    return [f"{key}[{i}]" for key, size in layout for i in range(size)]


def unfamiliar_inputs(policy: Any, obs: Any, bound: float = UNFAMILIAR_STD) -> list[Unfamiliar]:
    """The entries of one observation more than ``bound`` training stds from the training mean.

    Args:
        policy: a loaded policy with its normaliser as arrays (``mean``, ``std``: the numpy
            runtime's); a policy without them (ONNX: the normaliser is in its graph) gives [].
        obs: one observation, a Dict or the flat ``state (22,)``.
        bound: the distance in training stds past which an entry is unfamiliar.

    Returns:
        The unfamiliar entries, farthest first.
    """
    mean, std = getattr(policy, "mean", None), getattr(policy, "std", None)
    if mean is None or std is None:
        return []
    state = np.asarray(policy.flatten(obs), dtype=np.float64)
    if state.ndim != 1:
        raise ValueError(f"one observation at a time, got shape {state.shape}")
    distance = np.abs(state - mean) / std
    names = entry_names(policy.obs_layout)
    found = [
        Unfamiliar(names[i], float(state[i]), float(mean[i]), float(std[i]))
        for i in np.flatnonzero(~(distance <= bound))
    ]
    return sorted(found, key=lambda u: -u.distance)


def check_familiar(policy: Any, obs: Any, bound: float = UNFAMILIAR_STD) -> None:
    """Refuse an observation the policy was not trained on (see the module docstring).

    Raises:
        UnfamiliarObservationError: an entry more than ``bound`` training stds out, each named.
    """
    found = unfamiliar_inputs(policy, obs, bound)
    if found:
        raise UnfamiliarObservationError(
            "the observation lies outside what the policy was trained on, so its actions would "
            "mean nothing: "
            + "; ".join(u.line() for u in found)
            + ". Give inputs inside its training (a Touch target on the table top), or train a "
            "policy with these inputs varied"
        )
