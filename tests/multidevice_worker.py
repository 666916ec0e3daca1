"""Multi-device training checks, run by ``test_multidevice.py`` in a fresh process.

The process must start with ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` (JAX reads it
once, at start-up), so the checks run here and print their figures as one JSON line.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from mjx_arm.task import OBS_SIZE
from mjx_arm.train.learner import ENV_AXIS, Learner, make_mesh
from mjx_arm.train.ppo import train
from mjx_arm.train.presets import load_config
from mjx_arm.train.resume import has_resume_state
from mjx_arm.train.rundir import RunDir

# The PPO settings of the gradient comparison (a small Reach config; no env is stepped). The
# entropy term is left out: Brax estimates it from random samples, which float64 draws
# differently, and the float64 evaluation must compute the same maths as the float32 ones.
ONE_STEP = {
    "task": "reach",
    "backend": "mujoco",
    "num_timesteps": "640",
    "num_envs": "32",
    "batch_size": "32",
    "num_minibatches": "4",
    "unroll_length": "5",
    "num_updates_per_batch": "2",
    "num_evals": "2",
    "num_eval_envs": "16",
    "policy_hidden": "32,32",
    "value_hidden": "32,32",
    "entropy_cost": "0",
}
ENVS, STEPS = 64, 5  # the minibatch: the gradient is a mean over ENVS * STEPS transitions


def _transitions(learner: Learner, state, batch: int, length: int, key: jax.Array):
    """A batch of PPO transitions ``(batch, length, ...)``: random observations and rewards,
    the actions and extras of the initial policy."""
    from brax.training.types import Transition

    keys = jax.random.split(key, 4)
    obs = jax.random.normal(keys[0], (batch * length, learner.observation_size))
    params = (state.normalizer_params, state.params.policy, state.params.value)
    action, extras = learner.make_policy(params)(obs, keys[1])
    shape = lambda x: x.reshape((batch, length, *x.shape[1:]))  # noqa: E731
    zeros = jnp.zeros((batch, length))
    return Transition(
        observation=shape(obs),
        action=shape(action),
        reward=jax.random.normal(keys[2], (batch, length)),
        discount=jnp.ones((batch, length)),
        next_observation=shape(jax.random.normal(keys[3], obs.shape)),
        extras={
            "policy_extras": jax.tree.map(shape, extras),
            "state_extras": {"truncation": zeros, "episode_done": zeros},
        },
    )


def _max_rel(arrays: list[np.ndarray], reference: list[np.ndarray]) -> float:
    """Largest ``|a - r|`` over each pair of arrays, relative to ``max |r|`` of that array."""
    return max(
        float(np.abs(a.astype(np.float64) - r).max() / max(np.abs(r).max(), 1e-30))
        for a, r in zip(arrays, reference, strict=True)
        if r.size
    )


def _wide(tree):
    """``tree`` on the host with its floating arrays as float64."""
    return jax.tree.map(
        lambda x: np.asarray(x, np.float64) if jnp.issubdtype(x.dtype, jnp.floating) else x,
        jax.device_get(tree),
    )


def gradient_errors() -> dict[str, float]:
    """The PPO loss gradient of one minibatch in float32 on 1 device and split over 2, and in
    float64 on 1 device.

    Returns:
        ``gradient_max_rel``: the largest difference of the two float32 gradients, relative
        to each gradient array's largest entry; ``gradient_float32_error``: the larger of the
        two float32 gradients' differences from the float64 one, relative alike.
    """
    config = load_config("cpu", None, [f"{k}={v}" for k, v in ONE_STEP.items()])
    grads = {}
    for count in (1, 2):
        mesh = make_mesh(jax.local_devices()[:count])
        learner = Learner(config, OBS_SIZE, 6, mesh)
        state = learner.init(jax.random.PRNGKey(0), jax.random.PRNGKey(1))
        data = _transitions(learner, state, ENVS, STEPS, jax.random.PRNGKey(2))
        inputs = (state.params, state.normalizer_params, data)

        def grad(params, normalizer, batch, learner=learner):
            return learner._loss_and_grad(params, normalizer, batch, jax.random.PRNGKey(3))[1]

        split = (*inputs[:2], jax.device_put(data, NamedSharding(mesh, P(ENV_AXIS))))
        grads[count] = [np.asarray(g) for g in jax.tree.leaves(jax.jit(grad)(*split))]
        if count == 1:
            with jax.enable_x64(True):
                wide = jax.jit(grad)(*_wide(inputs))
            grads["float64"] = [np.asarray(g) for g in jax.tree.leaves(wide)]
    exact = grads["float64"]
    assert all(g.dtype == np.float64 for g in exact), "the reference is not float64"
    return {
        "gradient_max_rel": _max_rel(grads[2], grads[1]),
        "gradient_float32_error": max(_max_rel(grads[c], exact) for c in (1, 2)),
    }


def learn_and_resume(out: Path, steps: int) -> dict:
    """Reach on 2 devices; then drop its last checkpoint and resume that run on 1 device (from
    the training state, optimiser included, saved on 2)."""
    config = load_config(
        "cpu", None, ["task=reach", "backend=mujoco", f"num_timesteps={steps}", "devices=2"]
    )
    run_dir = out / "learn"
    result = train(config, run_dir, quiet=True)
    run = RunDir(run_dir)
    rows = run.read_metrics()
    figures = {
        "success": result.metrics["eval/episode_success"],
        "steps": result.steps,
        "rows": len(rows),
        "columns": sorted(rows[-1]),
        "partition": json.loads((run_dir / "config.json").read_text())["partition"],
    }
    shutil.rmtree(run.latest_checkpoint())
    kept = run.latest_checkpoint()
    resumed = train(config.replace(devices=1), run_dir, resume=True, quiet=True)
    figures.update(
        kept_step=int(RunDir.load_meta(kept)["step"]),
        kept_training_state=has_resume_state(kept),
        resumed_steps=resumed.steps,
        resumed_success=resumed.metrics["eval/episode_success"],
    )
    return figures


def main() -> None:
    out = Path(sys.argv[1])
    steps = int(sys.argv[2])
    figures = {
        "device_count": jax.local_device_count(),
        **gradient_errors(),
        **learn_and_resume(out, steps),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
