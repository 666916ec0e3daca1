"""Domain randomisation of the batched env: per-episode dynamics, target offset, F/T noise, latency.

A policy trained in one engine meets another engine's contact model, solver and servo in
evaluation (and a real arm after that). Randomising what differs between them during training
makes the policy robust to it. Each episode of each env draws its own:

- dynamics multipliers (:class:`mjx_arm.envs.mjx_physics.Dynamics`): geom friction, joint damping,
  rotor inertia (armature) and velocity-servo gain, uniform in configured ranges;
- a box offset: the box stands up to ``box_offset`` (m, in x and y) from where the observation
  says, as a real box would from its estimated pose;
- a one-step action delay with probability ``latency_prob``;

and every step adds Gaussian noise to the F/T observation (the reward and success still use the
true reading). The box is welded to the world (a mocap body) in every engine, so its mass has no
effect and is not randomised. Everything is off unless ``enabled``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from mjx_arm.envs.mjx_physics import Dynamics

Range = tuple[float, float]


@dataclass(frozen=True)
class RandomizationConfig:
    """Ranges of the domain randomisation (multipliers are uniform in ``(low, high)``).

    Attributes:
        enabled: randomise at all (off: every env steps the nominal model, no noise or delay).
        friction: multiplier of every geom's friction.
        damping: multiplier of each joint's damping (drawn per joint).
        armature: multiplier of each joint's rotor inertia (per joint).
        gain: multiplier of each velocity servo's gain (per joint).
        box_offset: half-width (m) of the uniform x/y offset of the box from its observed place.
        ft_force_noise: standard deviation (N) of the noise on the observed force.
        ft_torque_noise: standard deviation (N m) of the noise on the observed torque.
        latency_prob: probability that an episode applies each action one control step late.
    """

    enabled: bool = False
    friction: Range = (0.7, 1.3)
    damping: Range = (0.7, 1.3)
    armature: Range = (0.7, 1.3)
    gain: Range = (0.8, 1.2)
    box_offset: float = 0.005
    ft_force_noise: float = 0.5
    ft_torque_noise: float = 0.02
    latency_prob: float = 0.3

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RandomizationConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown randomization config keys: {sorted(unknown)}")
        data = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**data)


@struct.dataclass
class Episode:
    """One env's draw for one episode.

    Attributes:
        dynamics: the dynamics multipliers.
        box_offset: true minus observed box position (m), ``(3,)`` (z = 0).
        latency: 1.0 when actions apply one step late, else 0.0, ``()``.
    """

    dynamics: Dynamics
    box_offset: jax.Array
    latency: jax.Array


def nominal_episode() -> Episode:
    """No randomisation: nominal dynamics, no offset, no delay."""
    return Episode(Dynamics.nominal(), jnp.zeros(3), jnp.zeros(()))


def sample_episode(rng: jax.Array, cfg: RandomizationConfig) -> Episode:
    """Draw one env's episode randomisation from ``rng`` (nominal when disabled)."""
    if not cfg.enabled:
        return nominal_episode()
    keys = jax.random.split(rng, 7)

    def uniform(key: jax.Array, bounds: Range, shape: tuple[int, ...]) -> jax.Array:
        return jax.random.uniform(key, shape, minval=bounds[0], maxval=bounds[1])

    dynamics = Dynamics(
        friction=uniform(keys[0], cfg.friction, ()),
        damping=uniform(keys[1], cfg.damping, (6,)),
        armature=uniform(keys[2], cfg.armature, (6,)),
        gain=uniform(keys[3], cfg.gain, (6,)),
    )
    offset = cfg.box_offset * jax.random.uniform(keys[4], (2,), minval=-1.0, maxval=1.0)
    latency = (jax.random.uniform(keys[5], ()) < cfg.latency_prob).astype(jnp.float32)
    return Episode(dynamics, jnp.concatenate([offset, jnp.zeros(1)]), latency)


def ft_noise(rng: jax.Array, cfg: RandomizationConfig) -> jax.Array:
    """Noise to add to the observed wrench, ``(6,)`` (zeros when disabled)."""
    if not cfg.enabled:
        return jnp.zeros(6)
    scale = jnp.array([cfg.ft_force_noise] * 3 + [cfg.ft_torque_noise] * 3)
    return scale * jax.random.normal(rng, (6,))
