"""A training run small enough to run several times in a test: three epochs of the C MuJoCo
batch with tiny networks, each epoch checkpointed with the envs' state."""

from __future__ import annotations

EPOCH_STEPS = 640  # one training step: 32 envs x 4 minibatches x 5 unrolls
EPOCHS = 3
SETTINGS = {
    "task": "reach",
    "backend": "mujoco",
    "num_timesteps": EPOCHS * EPOCH_STEPS,
    "num_evals": EPOCHS + 1,
    "num_envs": 32,
    "batch_size": 32,
    "num_minibatches": 4,
    "unroll_length": 5,
    "num_updates_per_batch": 2,
    "num_eval_envs": 16,
    "policy_hidden": "32,32",
    "value_hidden": "32,32",
    "checkpoint_every": 1,
    "env_state_every": 1,  # every checkpoint takes the envs' state (the newest keeps it)
}
