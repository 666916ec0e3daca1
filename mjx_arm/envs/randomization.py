"""Domain randomisation of the batched env: per-episode dynamics, sensor errors, latency.

A policy trained in one engine meets another engine's contact model, solver and servo in
evaluation (and a real arm after that). Randomising what differs between them during training
makes the policy robust to it; the robustness benchmark (:mod:`mjx_arm.bench.robustness`) uses
the same draw with fixed values to measure what each difference costs. Each episode of each env
draws its own (:class:`~mjx_arm.envs.physics_config.RandomizationConfig` gives the ranges):

- dynamics (:class:`mjx_arm.envs.mjx_physics.Dynamics`): geom friction, joint damping, rotor
  inertia (armature) and velocity-servo gain multipliers, joint dry friction, a payload at the
  flange and the table's height;
- a box (or cube) offset: it stands up to ``box_offset`` (m, in x and y) from where the
  observation says, as a real box would from its estimated pose, and ``table_height`` lower or
  higher with the table;
- an action delay of ``latency_steps`` control steps with probability ``latency_prob``;
- a bias of the observed joint angles and of the observed force;
- a gripper task's cube mass and friction multipliers (on top of the task's own draw).

Every step adds Gaussian noise to the observed joint angles and F/T reading and, under
``ctrl_jitter``, draws the length of the control period. The reward and success use the true
state. The box is welded to the world (a mocap body) in every engine, so its mass has no
effect and is not randomised. Everything is off unless ``enabled``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from mjx_arm.envs.mjx_physics import Dynamics
from mjx_arm.envs.physics_config import MAX_LATENCY, RandomizationConfig, Range

__all__ = [
    "MAX_LATENCY",
    "Episode",
    "RandomizationConfig",
    "delayed_action",
    "ft_noise",
    "joint_noise",
    "nominal_episode",
    "push_action",
    "sample_episode",
    "step_dynamics",
]


@struct.dataclass
class Episode:
    """One env's draw for one episode.

    Attributes:
        dynamics: the dynamics changes.
        box_offset: true minus observed box position (m), ``(3,)`` (z: the table's offset).
        latency: the action delay (control steps, a whole number), ``()``.
        joint_bias: offset of the observed joint angles (rad), ``(n,)``.
        ft_bias: offset of the observed wrench (N, then N m), ``(6,)``.
        object_scale: multipliers of a gripper task's cube mass and friction, ``(2,)``.
        ft_noise: standard deviation of the per-step noise on the observed wrench, ``(6,)``.
        joint_noise: standard deviation of the per-step noise on the joint angles (rad),
            ``(n,)``.
        jitter: half-width of the per-step control-period jitter (fraction), ``()``.

    The per-step scales live here (not only in the config) so that one batch can hold
    episodes of different settings (the robustness benchmark's sweep in one batch).
    """

    dynamics: Dynamics
    box_offset: jax.Array
    latency: jax.Array
    joint_bias: jax.Array
    ft_bias: jax.Array
    object_scale: jax.Array
    ft_noise: jax.Array
    joint_noise: jax.Array
    jitter: jax.Array


def nominal_episode(n_joints: int = 6) -> Episode:
    """No randomisation: nominal dynamics of ``n_joints``, no offset, bias or delay."""
    zeros, n = jnp.zeros, n_joints
    return Episode(
        Dynamics.nominal(n), zeros(3), zeros(()), zeros(n), zeros(6), jnp.ones(2), zeros(6),
        zeros(n), zeros(()),
    )  # fmt: skip


def _uniform(key: jax.Array, bounds: Range | tuple[int, int], shape: tuple[int, ...]):
    return jax.random.uniform(key, shape, minval=bounds[0], maxval=bounds[1])


def sample_episode(rng: jax.Array, cfg: RandomizationConfig, n_joints: int = 6) -> Episode:
    """Draw one env's episode randomisation from ``rng`` (nominal when disabled); the joint
    entries are ``(n_joints,)``."""
    if not cfg.enabled:
        return nominal_episode(n_joints)
    keys = iter(jax.random.split(rng, 16))
    n = n_joints
    table = _uniform(next(keys), cfg.table_height, ())
    dynamics = Dynamics(
        friction=_uniform(next(keys), cfg.friction, ()),
        damping=_uniform(next(keys), cfg.damping, (n,)),
        armature=_uniform(next(keys), cfg.armature, (n,)),
        gain=_uniform(next(keys), cfg.gain, (n,)),
        frictionloss=_uniform(next(keys), cfg.frictionloss, (n,)),
        payload=_uniform(next(keys), cfg.payload, ()),
        table=table,
        timestep=jnp.ones(()),
    )
    offset = cfg.box_offset * jax.random.uniform(next(keys), (2,), minval=-1.0, maxval=1.0)
    late = jax.random.uniform(next(keys), ()) < cfg.latency_prob
    low, high = cfg.latency_steps
    steps = jax.random.randint(next(keys), (), low, high + 1).astype(jnp.float32)
    force_bias = _uniform(next(keys), cfg.ft_force_bias, (3,))
    object_scale = jnp.stack(
        [_uniform(next(keys), cfg.cube_mass, ()), _uniform(next(keys), cfg.cube_friction, ())]
    )
    return Episode(
        dynamics=dynamics,
        box_offset=jnp.concatenate([offset, table[None]]),
        latency=jnp.where(late, steps, 0.0),
        joint_bias=_uniform(next(keys), cfg.joint_bias, (n,)),
        ft_bias=jnp.concatenate([force_bias, jnp.zeros(3)]),
        object_scale=object_scale,
        ft_noise=jnp.array([cfg.ft_force_noise] * 3 + [cfg.ft_torque_noise] * 3),
        joint_noise=jnp.full((n,), cfg.joint_noise),
        jitter=jnp.asarray(cfg.ctrl_jitter, jnp.float32),
    )


def step_dynamics(rng: jax.Array, episode: Episode) -> Dynamics:
    """The dynamics of one control step: the episode's, with this step's period drawn under
    its jitter (the physics step scaled by ``1 + u``, ``u`` uniform in +-jitter)."""
    u = jax.random.uniform(rng, (), minval=-1.0, maxval=1.0) * episode.jitter
    return episode.dynamics.replace(timestep=1.0 + u)


def ft_noise(rng: jax.Array, episode: Episode) -> jax.Array:
    """Noise to add to the observed wrench at the episode's scale, ``(6,)``."""
    return episode.ft_noise * jax.random.normal(rng, (6,))


def joint_noise(rng: jax.Array, episode: Episode) -> jax.Array:
    """Noise to add to the observed joint angles at the episode's scale, ``(n,)``."""
    return episode.joint_noise * jax.random.normal(rng, episode.joint_noise.shape)


def delayed_action(action: jax.Array, past: jax.Array, latency: jax.Array) -> jax.Array:
    """The action applied under a delay of ``latency`` steps.

    Args:
        action: this step's action, ``(m,)``.
        past: the previous actions, newest first, ``(MAX_LATENCY, m)`` (zeros before the
            episode's first step).
        latency: the delay in control steps, ``()`` (0 applies ``action``).
    """
    history = jnp.concatenate([action[None], past], axis=0)
    index = jnp.clip(latency.astype(jnp.int32), 0, past.shape[0])
    return history[index]


def push_action(action: jax.Array, past: jax.Array) -> jax.Array:
    """``past (MAX_LATENCY, m)`` with ``action (m,)`` added as the newest entry."""
    return jnp.concatenate([action[None], past[:-1]], axis=0)
