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

import jax
import jax.numpy as jnp
from flax import struct

from mjx_arm.envs.mjx_physics import Dynamics
from mjx_arm.envs.physics_config import RandomizationConfig, Range

__all__ = ["Episode", "RandomizationConfig", "ft_noise", "nominal_episode", "sample_episode"]


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


def nominal_episode(n_joints: int = 6) -> Episode:
    """No randomisation: nominal dynamics of ``n_joints``, no offset, no delay."""
    return Episode(Dynamics.nominal(n_joints), jnp.zeros(3), jnp.zeros(()))


def sample_episode(rng: jax.Array, cfg: RandomizationConfig, n_joints: int = 6) -> Episode:
    """Draw one env's episode randomisation from ``rng`` (nominal when disabled); the joint
    multipliers are ``(n_joints,)``."""
    if not cfg.enabled:
        return nominal_episode(n_joints)
    keys = jax.random.split(rng, 7)

    def uniform(key: jax.Array, bounds: Range, shape: tuple[int, ...]) -> jax.Array:
        return jax.random.uniform(key, shape, minval=bounds[0], maxval=bounds[1])

    dynamics = Dynamics(
        friction=uniform(keys[0], cfg.friction, ()),
        damping=uniform(keys[1], cfg.damping, (n_joints,)),
        armature=uniform(keys[2], cfg.armature, (n_joints,)),
        gain=uniform(keys[3], cfg.gain, (n_joints,)),
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
