"""Seconds from process start to the first trained evaluation of a tiny Touch run (C MuJoCo).

Run with PYTHONPATH at the code to measure and MJX_ARM_JAX_CACHE at its cache; argument: a label.
"""

import time

T0 = time.time()

import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

from mjx_arm.jax_cache import enable_compilation_cache  # noqa: E402

enable_compilation_cache()
from mjx_arm.train.config import load_config  # noqa: E402
from mjx_arm.train.ppo import train  # noqa: E402
from mjx_arm.train.rundir import RunDir  # noqa: E402

SETS = ["task=touch", "backend=mujoco", "num_envs=16", "batch_size=16", "num_minibatches=2"]
SETS += ["unroll_length=4", "num_updates_per_batch=1", "num_eval_envs=16", "num_evals=3"]
SETS += ["num_timesteps=2000"]
run = Path(tempfile.mkdtemp()) / "run"
train(load_config("cpu", None, SETS), run, quiet=True)
first = next(r["time"] for r in RunDir(run).read_metrics() if r["step"] > 0)
end = time.time() - T0
print(json.dumps({"code": sys.argv[1], "first_epoch_done_s": first - T0, "end_s": end}))
