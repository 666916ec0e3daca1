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
import numpy as np

from mjx_arm.train.config import load_config
from mjx_arm.train.ppo import train
from mjx_arm.train.rundir import RunDir

# One training step of a small Reach batch: 32 envs x 4 unrolls x 5 steps = 640 env steps.
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


def _params(run_dir: Path) -> list[np.ndarray]:
    latest = RunDir(run_dir).latest_checkpoint()
    return [np.asarray(x) for x in jax.tree.leaves(RunDir.load_params(latest))]


def one_step_difference(out: Path) -> float:
    """Largest difference of any parameter array after one training step, 1 device vs 2,
    relative to the array's largest magnitude."""
    runs = []
    for devices in (1, 2):
        sets = {**ONE_STEP, "devices": str(devices)}
        config = load_config("cpu", None, [f"{k}={v}" for k, v in sets.items()])
        runs.append(_params(train(config, out / f"one_step_{devices}", quiet=True).run_dir))
    return max(
        float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-12))
        for a, b in zip(*runs, strict=True)
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
        "one_step_max_rel": one_step_difference(out),
        **learn_and_resume(out, steps),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
