"""MuJoCo Warp's kernel compiles of one task model, module by module, at Warp's optimisation
levels, beside the physics speed each level gives.

Each level runs in a new process with empty caches (Warp's kernels, JAX, the CUDA driver's). It
builds the batched env without precompiling, lists the modules the step launches
(:func:`mjx_arm.envs.warp_compile.step_loads`), sets the level on the modules that ``--scope``
names (``all``, or ``ccd``: the convex-collision kernels only) and compiles them on a thread pool,
timing each module. Then it steps the batch with random actions and reports control steps/s
(each control step is the task's substeps of ``mjx.step``).

GPU only (MuJoCo Warp on CUDA)::

    python benchmarks/bench_warp_kernels.py --arm $ROBOTS/ur_description/urdf/ur5_robot.urdf \\
        --task reach --levels 3 1 --scope ccd
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import (
    RESULTS_DIR,
    empty_cache_env,
    environment_metadata,
    markdown_table,
    save_results,
)

RESULTS = RESULTS_DIR / "cold_start"


def _in_scope(name: str, scope: str) -> bool:
    return scope == "all" or (scope == "ccd" and "ccd_kernel" in name)


def _compile(loads: dict, device, level: int | None, scope: str, threads: int) -> dict:
    """Compile ``loads`` on ``device`` at ``level`` (None: Warp's default), timing each module."""

    def load(module, block_dim: int) -> tuple[str, float]:
        start = time.perf_counter()
        module.load(device, block_dim)
        return module.name, time.perf_counter() - start

    jobs = []
    for block_dim, modules in loads.items():
        for module in modules:
            if level is not None and _in_scope(module.name, scope):
                module.options["optimization_level"] = level
            jobs.append((module, block_dim))
    start = time.perf_counter()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        times = list(pool.map(lambda job: load(*job), jobs))
    wall = time.perf_counter() - start
    slowest = dict(sorted(times, key=lambda item: -item[1])[:6])
    return {"modules": len(jobs), "compile_wall_s": wall, "slowest_s": slowest}


def _steps_per_second(env, batch: int, steps: int) -> float:
    """Control steps/s of ``batch`` envs stepped with random actions (after one warm-up)."""
    import jax

    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step))
    state = reset(jax.random.split(jax.random.PRNGKey(0), batch))
    actions = jax.random.uniform(jax.random.PRNGKey(1), (steps, batch, env.action_size), minval=-1)
    state = jax.block_until_ready(step(state, actions[0]))
    start = time.perf_counter()
    for k in range(steps):
        state = step(state, actions[k])
    jax.block_until_ready(state)
    return steps * batch / (time.perf_counter() - start)


def _child(args: argparse.Namespace) -> dict:
    from mjx_arm.envs import warp_compile
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.physics_config import PhysicsConfig
    from mjx_arm.envs.warp_buffers import warp_compatible
    from mjx_arm.task import task_config

    task = task_config(args.task)
    physics = PhysicsConfig(impl="warp", compile_threads=0)
    env = make_batched_env(task, "mjx", physics, args.batch, arm=args.arm or None)
    device = (warp_compile.cuda_devices() or ["cpu"])[0]  # the CPU: a slow smoke test
    buffers = env.physics.buffers
    model = warp_compatible(env.physics.mj_model)
    start = time.perf_counter()
    loads = warp_compile.step_loads(model, buffers["naconmax"], buffers["njmax"], device)
    listed = time.perf_counter() - start
    row = _compile(loads, device, args.level, args.scope, args.threads)
    row["list_s"] = listed
    row["steps_per_s"] = _steps_per_second(env, args.batch, args.steps)
    return row


def _run_level(args: argparse.Namespace, level: int | None) -> dict:
    cmd = [sys.executable, __file__, "--child", "--task", args.task, "--arm", args.arm or ""]
    cmd += ["--batch", str(args.batch), "--steps", str(args.steps), "--scope", args.scope]
    cmd += ["--threads", str(args.threads)] + (["--level", str(level)] if level is not None else [])
    env = {**os.environ, **empty_cache_env(), "PYTHONUNBUFFERED": "1"}
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.timeout)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode or not lines:
        return {"level": level, "error": done.stderr[-2000:]}
    return {"level": level, **json.loads(lines[-1])}


def _short(name: str) -> str:
    """A module's name without its package and its hash."""
    return name.split("__locals__")[0].rsplit(".", 1)[-1]


def table(rows: list[dict]) -> str:
    head = ["level", "scope", "modules", "list (s)", "compile wall (s)", "slowest module (s)"]
    head += ["control steps/s"]
    body = []
    for r in rows:
        if "error" in r:
            body.append([str(r["level"]), "-", "error", "-", "-", "-", "-"])
            continue
        name, secs = next(iter(r["slowest_s"].items()))
        body.append(
            [
                "default" if r["level"] is None else str(r["level"]),
                r["scope"],
                str(r["modules"]),
                f"{r['list_s']:.2f}",
                f"{r['compile_wall_s']:.1f}",
                f"{secs:.1f} ({_short(name)})",
                f"{r['steps_per_s']:,.0f}",
            ]
        )
    return markdown_table(head, body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="reach")
    parser.add_argument("--arm", default="", help="a URDF (default: the shipped arm)")
    parser.add_argument("--levels", nargs="+", default=["default", "1"])
    parser.add_argument("--scope", choices=("all", "ccd"), default="ccd")
    parser.add_argument("--batch", type=int, default=8192)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--threads", type=int, default=16)
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--results-dir", type=Path, default=RESULTS)
    parser.add_argument("--name", default="warp_kernels")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--level", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_child(args)), flush=True)
        return
    rows = []
    for text in args.levels:
        level = None if text == "default" else int(text)
        rows.append({"scope": args.scope, **_run_level(args, level)})
        print(table(rows[-1:]).splitlines()[-1], flush=True)
    payload = {
        "meta": environment_metadata(accelerator=True),
        "task": args.task,
        "arm": args.arm or "shipped",
        "batch_size": args.batch,
        "threads": args.threads,
        "rows": rows,
    }
    md = f"# MuJoCo Warp kernel compiles by optimisation level ({args.task}, {payload['arm']})\n\n"
    print(table(rows))
    save_results(args.name, payload, md + table(rows) + "\n", args.results_dir)


if __name__ == "__main__":
    main()
