"""Compatibility shim between brax 0.14.2 and jax >= 0.10.

brax 0.14.2 (the newest release) calls ``jax.device_put_replicated``, which jax 0.10 removed
(google/brax#671). :func:`install` puts back an equivalent built on ``jax.pmap``: the value is
replicated onto each device with a leading device axis, which is what brax's pmapped training
step expects. Delete this module once a brax release stops calling the removed function.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp

# brax pmaps its training step over an axis of this name; replicated values must match its mesh
BRAX_AXIS_NAME = "i"


def _device_put_replicated(value: Any, devices: Sequence[jax.Device]) -> Any:
    """Replicate a pytree onto ``devices``; every leaf gains a leading axis of len(devices)."""
    leaves, treedef = jax.tree.flatten(value)
    leaves = [jnp.asarray(leaf) for leaf in leaves]

    def replicate(_: jax.Array) -> list[jax.Array]:
        return leaves

    out = jax.pmap(replicate, axis_name=BRAX_AXIS_NAME, devices=list(devices))(
        jnp.arange(len(devices))
    )
    return jax.tree.unflatten(treedef, out)


def install() -> None:
    """Provide ``jax.device_put_replicated`` where this jax lacks it (idempotent)."""
    if not hasattr(jax, "device_put_replicated"):
        jax.device_put_replicated = _device_put_replicated
