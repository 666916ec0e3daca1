"""Batched env throughput on MJX beside the raw ``mjx.step`` rate of the same model.

For each batch size, one process (so peak device memory is its own) times:

* env: ``jit(vmap(env.step))`` of the task env, K control steps inside one ``lax.scan``,
* raw: ``jit(vmap(8 x mjx.step))`` of the same model and batch, same K,

and reports control steps/s, physics steps/s (8 per control step), the env's overhead against
raw, compile times and peak device memory, for each MJX implementation given (``--impls jax
warp``: both in one run, so the Warp/JAX ratio is measured side by side). Run on a GPU::

    python benchmarks/bench_mjx_throughput.py --batches 1024 8192 32768 131072 --impls jax warp
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import (
    RESULTS_DIR,
    compile_and_time,
    environment_metadata,
    markdown_table,
    save_results,
)


def _peak_bytes() -> int | None:
    import jax

    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def _env(task_name: str, backend: str, convert: list[str], physics, batch: int, arm: str = ""):
    """The batched env of ``arm`` (a URDF or arm file; "" the shipped arm), its model converted
    with ``key=value`` overrides of ConvertConfig."""
    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.task import task_config

    task = task_config(task_name)
    if not convert:
        return make_batched_env(task, backend, physics, batch, arm=arm or None)
    if arm:
        raise SystemExit("--convert is for the shipped arm only")
    import dataclasses

    from mjx_arm.arm.model_io import task_convert_config
    from mjx_arm.envs.mjx_env import MjxArmEnv
    from mjx_arm.paths import default_arm_urdf
    from mjx_arm.urdf import load_model

    base = task_convert_config(task)
    kinds = {f.name: f.type for f in dataclasses.fields(base)}
    changes = {}
    for item in convert:
        key, _, value = item.partition("=")
        changes[key] = {"int": int, "float": float, "bool": lambda v: v == "true"}.get(
            str(kinds[key]), str
        )(value)
    model = load_model(default_arm_urdf(), base.replace(**changes))
    return MjxArmEnv(task, mj_model=model, physics=physics, batch_size=batch)


def measure(
    task_name: str,
    batch: int,
    steps: int,
    backend: str,
    convert: list[str] | None = None,
    physics=None,
    arm: str = "",
) -> dict:
    """Time env and raw stepping for one batch size (in this process)."""
    import jax
    import jax.numpy as jnp

    env = _env(task_name, backend, convert or [], physics, batch, arm)
    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    shape = (batch, env.action_size)
    actions = jax.random.uniform(jax.random.PRNGKey(1), shape, minval=-1, maxval=1)

    def env_rollout(state):
        def body(s, _):
            return jax.vmap(env.step)(s, actions), None

        return jax.lax.scan(body, state, None, length=steps)[0]

    state = jax.jit(jax.vmap(env.reset))(keys)
    out, env_compile, env_time = compile_and_time(jax.jit(env_rollout), state)
    env_peak = _peak_bytes()
    result = {
        "batch": batch,
        "control_steps": steps,
        "env_compile_s": env_compile,
        "env_run_s": env_time,
        "env_control_steps_per_s": batch * steps / env_time,
        "env_physics_steps_per_s": batch * steps * env.task.n_substeps / env_time,
        "env_peak_bytes": env_peak,
        "finite": bool(jnp.all(jnp.isfinite(out.obs))),
        "physics": env.physics.describe(),
        "overflowed_envs": int(jnp.sum(out.metrics["physics_overflow"] > 0)),
    }
    if backend == "mjx":
        result.update(_raw(env, out.pipeline_state, steps))
        result["env_overhead"] = (
            1.0 - result["env_physics_steps_per_s"] / result["raw_physics_steps_per_s"]
        )
    return result


def _raw(env, data, steps: int) -> dict:
    """Plain ``mjx.step`` substeps on the same model, batch and control."""
    import jax
    from mujoco import mjx

    model = env.physics.model
    n_sub = env.task.n_substeps

    def raw_rollout(d):
        def body(d, _):
            return jax.vmap(mjx.step, in_axes=(None, 0))(model, d), None

        return jax.lax.scan(body, d, None, length=steps * n_sub)[0]

    _, compile_s, run_s = compile_and_time(jax.jit(raw_rollout), data)
    batch = data.qpos.shape[0]
    return {
        "raw_compile_s": compile_s,
        "raw_run_s": run_s,
        "raw_physics_steps_per_s": batch * steps * n_sub / run_s,
        "peak_bytes_after_raw": _peak_bytes(),
    }


def _child(args: argparse.Namespace) -> None:
    from mjx_arm.envs.physics_config import PhysicsConfig

    physics = PhysicsConfig(
        impl=args.child_impl, naconmax_per_env=args.naconmax_per_env, njmax=args.njmax
    )
    row = measure(
        args.task, args.child_batch, args.steps, args.backend, args.convert, physics, args.arm
    )
    row["convert"] = args.convert
    row["arm"] = args.arm or "shipped"
    row["impl"] = row["physics"].get("impl", args.backend)
    print(json.dumps(row))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="touch", choices=["reach", "touch"])
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 8192, 32768, 131072])
    parser.add_argument("--steps", type=int, default=50, help="control steps timed per batch")
    parser.add_argument("--backend", default="mjx", choices=["mjx", "mujoco"])
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "throughput")
    parser.add_argument("--name", default=None, help="result file stem")
    parser.add_argument(
        "--convert",
        nargs="*",
        default=[],
        help="ConvertConfig overrides key=value (e.g. solver_iterations=2)",
    )
    parser.add_argument(
        "--impls", nargs="+", default=["auto"], help="MJX implementations: auto, jax, warp"
    )
    parser.add_argument("--naconmax-per-env", type=int, default=0, help="Warp contacts per env")
    parser.add_argument("--njmax", type=int, default=0, help="Warp constraint rows per env")
    parser.add_argument(
        "--arm", default="", help="the arm: a URDF or an arm file (default: shipped)"
    )
    parser.add_argument("--child-batch", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--child-impl", default="auto", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child_batch:
        _child(args)
        return
    rows = []
    for batch, impl in [(b, i) for b in args.batches for i in args.impls]:
        cmd = [
            sys.executable,
            __file__,
            "--task",
            args.task,
            "--steps",
            str(args.steps),
            "--backend",
            args.backend,
            "--child-batch",
            str(batch),
            "--child-impl",
            impl,
            "--naconmax-per-env",
            str(args.naconmax_per_env),
            "--njmax",
            str(args.njmax),
            "--arm",
            args.arm,
        ]
        if args.convert:
            cmd += ["--convert", *args.convert]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            print(proc.stderr[-3000:], file=sys.stderr)
            rows.append({"batch": batch, "impl": impl, "error": proc.stderr[-500:]})
            continue
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append(row)
        print(json.dumps(row), flush=True)
    meta = environment_metadata(accelerator=True)
    table = _table(rows, args.backend)
    print(table)
    name = args.name or f"mjx_throughput_{args.task}_{args.backend}_{'_'.join(args.impls)}"
    save_results(
        name,
        {
            "meta": meta,
            "task": args.task,
            "arm": args.arm or "shipped",
            "backend": args.backend,
            "rows": rows,
            "warp_over_jax": _ratios(rows),
            "goals": GOALS,
        },
        table,
        args.results_dir,
    )


GOALS = {
    "env_overhead_max": 0.10,
    "physics_steps_per_s_min": 3_000_000,
    "memory_128k_envs_max_gib": 20,
    "warp_over_jax_min": 4.0,
}


def _ratios(rows: list[dict]) -> dict[str, float]:
    """Warp over JAX env control steps/s, per batch where both ran."""
    rate = {
        (r["batch"], r.get("impl")): r["env_control_steps_per_s"] for r in rows if "error" not in r
    }
    return {
        str(b): rate[(b, "warp")] / rate[(b, "jax")]
        for b, impl in rate
        if impl == "warp" and (b, "jax") in rate
    }


def _table(rows: list[dict], backend: str) -> str:
    ratios = _ratios(rows)
    headers = [
        "envs",
        "impl",
        "control steps/s",
        "physics steps/s",
        "raw physics steps/s",
        "overhead",
        "env compile s",
        "peak GiB",
        "warp / jax",
    ]
    out = []
    for r in rows:
        impl = r.get("impl", backend)
        if "error" in r:
            out.append([r["batch"], impl, "error", "", "", "", "", "", ""])
            continue
        peak = r.get("env_peak_bytes")
        ratio = ratios.get(str(r["batch"])) if impl == "warp" else None
        out.append(
            [
                r["batch"],
                impl,
                f"{r['env_control_steps_per_s']:,.0f}",
                f"{r['env_physics_steps_per_s']:,.0f}",
                f"{r.get('raw_physics_steps_per_s', float('nan')):,.0f}",
                f"{100 * r.get('env_overhead', float('nan')):.1f}%",
                f"{r['env_compile_s']:.1f}",
                f"{peak / 2**30:.2f}" if peak else "n/a",
                f"{ratio:.2f}x" if ratio else "",
            ]
        )
    return markdown_table(headers, out)


if __name__ == "__main__":
    main()
