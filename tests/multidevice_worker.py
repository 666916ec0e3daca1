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

from mjx_arm.train.config import load_config
from mjx_arm.train.learner import ENV_AXIS, Learner, make_mesh
from mjx_arm.train.ppo import train
from mjx_arm.train.rundir import RunDir

# The PPO settings of the gradient comparison (a small Reach config; no env is stepped).
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
}


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


def gradient_difference() -> float:
    """Largest difference of the PPO loss gradient on one minibatch, computed on 1 device and
    split over 2, relative to each gradient array's largest magnitude.

    The two differ only in the order of the float32 sums over the minibatch (each device sums
    its half, then the halves are added), so the difference is a few ulps of the largest
    partial sums: well under 1e-5 of the largest entry for 64 x 5 transitions.
    """
    config = load_config("cpu", None, [f"{k}={v}" for k, v in ONE_STEP.items()])
    grads = []
    for count in (1, 2):
        mesh = make_mesh(jax.local_devices()[:count])
        learner = Learner(config, 22, 6, mesh)
        state = learner.init(jax.random.PRNGKey(0), jax.random.PRNGKey(1))
        data = _transitions(learner, state, 64, 5, jax.random.PRNGKey(2))
        data = jax.device_put(data, NamedSharding(mesh, P(ENV_AXIS)))

        @jax.jit
        def grad(params, normalizer, batch, learner=learner):
            return learner._loss_and_grad(params, normalizer, batch, jax.random.PRNGKey(3))[1]

        grads.append(
            [
                np.asarray(g)
                for g in jax.tree.leaves(grad(state.params, state.normalizer_params, data))
            ]
        )
    return max(
        float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-30))
        for a, b in zip(*grads, strict=True)
        if a.size
    )


def learn_and_resume(out: Path, steps: int) -> dict:
    """Reach on 2 devices; then drop its last checkpoint and resume that run on 1 device."""
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
    kept = int(RunDir.load_meta(run.latest_checkpoint())["step"])
    resumed = train(config.replace(devices=1), run_dir, resume=True, quiet=True)
    figures.update(
        kept_step=kept,
        resumed_steps=resumed.steps,
        resumed_success=resumed.metrics["eval/episode_success"],
    )
    return figures


def main() -> None:
    out = Path(sys.argv[1])
    steps = int(sys.argv[2])
    figures = {
        "device_count": jax.local_device_count(),
        "gradient_max_rel": gradient_difference(),
        **learn_and_resume(out, steps),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
