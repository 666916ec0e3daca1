"""Where a cold start's seconds go on MJX: import, env build, Warp's kernels, the first steps.

Each variant runs in a new process with empty Warp kernel, CUDA driver and JAX compilation
caches and times:

* import: ``import jax`` and the env modules (MuJoCo, MJX, Warp),
* build: the batched env (model conversion, ``put_model``, Warp's buffers), of which
  precompile is :func:`mjx_arm.envs.warp_compile.precompile` with the variant's threads,
* reset / step: the first ``jit(vmap(reset))`` and ``jit(vmap(step))`` calls (XLA compilation,
  Warp's first-use compilation, one run), then a second step call (the steady cost),

and lists the Warp modules that hold a binary afterwards (what :data:`STEP_MODULES` should
name). Variants: every pair of ``--threads`` and ``--xla-flags``. On a GPU::

    python benchmarks/bench_cold_start.py --task reach --threads 0 8 16
"""

from __future__ import annotations

import time

START = time.perf_counter()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import (  # noqa: E402
    empty_cache_env,
    environment_metadata,
    markdown_table,
    save_results,
)


def _child(args: argparse.Namespace) -> dict:
    """Time the phases in this (fresh) process; returns the row."""
    import jax

    from mjx_arm.envs import warp_compile
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.physics_config import PhysicsConfig
    from mjx_arm.task import task_config

    row = {"import_s": time.perf_counter() - START}
    physics = PhysicsConfig(impl=args.impl, compile_threads=args.child_threads)
    t = time.perf_counter()
    env = make_batched_env(task_config(args.task), "mjx", physics, args.batch)
    row["build_s"] = time.perf_counter() - t
    row["precompile_s"] = env.physics.precompile_seconds
    keys = jax.random.split(jax.random.PRNGKey(0), args.batch)
    action = jax.numpy.zeros((args.batch, 6))
    reset, step = jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))
    t = time.perf_counter()
    state = jax.block_until_ready(reset(keys))
    row["reset_s"] = time.perf_counter() - t
    for name in ("step_s", "second_step_s"):
        t = time.perf_counter()
        state = jax.block_until_ready(step(state, action))
        row[name] = time.perf_counter() - t
    row["total_s"] = time.perf_counter() - START
    row["physics"] = env.physics.describe()
    row["loaded_modules"] = warp_compile.loaded_modules() if env.physics.impl == "warp" else {}
    return row


def _run_variant(args: argparse.Namespace, threads: int, xla_flags: str) -> dict:
    """One variant in a new process with empty caches."""
    env = dict(os.environ)
    env.update(empty_cache_env())
    env["JAX_ENABLE_COMPILATION_CACHE"] = "false"
    if xla_flags:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {xla_flags}".strip()
    cmd = [sys.executable, __file__, "--task", args.task, "--batch", str(args.batch)]
    cmd += ["--impl", args.impl, "--child-threads", str(threads)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    row = {"threads": threads, "xla_flags": xla_flags}
    if proc.returncode != 0:
        print(proc.stderr[-3000:], file=sys.stderr)
        return {**row, "error": proc.stderr[-500:]}
    return {**row, **json.loads(proc.stdout.strip().splitlines()[-1])}


def _table(rows: list[dict]) -> str:
    cols = ["import_s", "build_s", "precompile_s", "reset_s", "step_s", "second_step_s", "total_s"]
    body = [
        [r["threads"], r["xla_flags"] or "-", *(f"{r[c]:.1f}" if c in r else "error" for c in cols)]
        for r in rows
    ]
    head = ["threads", "XLA flags", "import", "build", "of it precompile", "first reset"]
    return markdown_table([*head, "first step", "second step", "total (s)"], body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="reach", choices=["reach", "touch"])
    parser.add_argument("--batch", type=int, default=8192, help="envs (the fast preset's)")
    parser.add_argument("--impl", default="warp", choices=["auto", "jax", "warp"])
    parser.add_argument("--threads", type=int, nargs="+", default=[0, 8])
    parser.add_argument("--xla-flags", nargs="+", default=[""], help="'' for none")
    parser.add_argument("--results-dir", type=Path, default=None)
    parser.add_argument("--name", default=None, help="result file stem")
    parser.add_argument("--child-threads", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child_threads is not None:
        print(json.dumps(_child(args)))
        return
    rows = []
    for threads in args.threads:
        for flags in args.xla_flags:
            rows.append(_run_variant(args, threads, flags))
            print(json.dumps(rows[-1]), flush=True)
    table = _table(rows)
    print(table)
    payload = {"meta": environment_metadata(accelerator=True), "task": args.task}
    payload.update(batch_size=args.batch, impl=args.impl, rows=rows)
    save_results(args.name or f"cold_start_{args.task}", payload, table, args.results_dir)


if __name__ == "__main__":
    main()
