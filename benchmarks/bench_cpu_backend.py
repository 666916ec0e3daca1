"""The C MuJoCo backend on a CPU: env throughput inside a jitted rollout, beside MJX on the CPU.

The rollout is what Brax PPO runs between updates: a ``lax.scan`` over control steps in which a
policy network picks the actions and the wrapped batch env (vmap + episode limit + auto-reset)
steps. For each batch size it reports compile time, control steps/s and physics steps/s. With
``--mjx`` the same rollout runs on MJX (the JAX implementation) for comparison (slow to compile).

    python benchmarks/bench_cpu_backend.py --batches 64 128 256 512 --mjx
"""

from __future__ import annotations

import argparse
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

GOALS = {"control_steps_per_s_min": 15_000, "train_compile_s_max": 20}


def rollout_rate(backend: str, task_name: str, batch: int, steps: int) -> dict:
    """Compile and time a policy-driven rollout of ``steps`` control steps."""
    import jax
    from brax.training.agents.ppo import networks as ppo_networks

    from mjx_arm.envs.backend import make_batched_env
    from mjx_arm.envs.wrappers import wrap_for_training
    from mjx_arm.task import task_config

    task = task_config(task_name)
    env = wrap_for_training(make_batched_env(task, backend), episode_length=task.episode_steps)
    nets = ppo_networks.make_ppo_networks(22, 6)
    params = nets.policy_network.init(jax.random.PRNGKey(0))
    dist = nets.parametric_action_distribution

    def rollout(carry):
        """``steps`` policy-driven control steps from carry = (state, key)."""

        def body(carry, _):
            s, k = carry
            k, sub = jax.random.split(k)
            logits = nets.policy_network.apply(None, params, s.obs)
            action = dist.sample(logits, sub)
            return (env.step(s, action), k), None

        return jax.lax.scan(body, carry, None, length=steps)[0]

    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(1), batch))
    _, compile_s, run_s = compile_and_time(jax.jit(rollout), (state, jax.random.PRNGKey(2)))
    return {
        "backend": backend,
        "batch": batch,
        "control_steps": steps,
        "compile_s": compile_s,
        "run_s": run_s,
        "control_steps_per_s": batch * steps / run_s,
        "physics_steps_per_s": batch * steps * task.n_substeps / run_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="touch", choices=["reach", "touch"])
    parser.add_argument("--batches", type=int, nargs="+", default=[64, 128, 256, 512])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--mjx", action="store_true", help="also time MJX on the CPU (batch 64)")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR / "throughput")
    args = parser.parse_args()
    rows = [rollout_rate("mujoco", args.task, b, args.steps) for b in args.batches]
    for r in rows:
        print(r, flush=True)
    if args.mjx:
        rows.append(rollout_rate("mjx", args.task, 64, 10))
        print(rows[-1], flush=True)
    table = markdown_table(
        ["backend", "envs", "compile (s)", "control steps/s", "physics steps/s"],
        [
            [
                r["backend"],
                r["batch"],
                f"{r['compile_s']:.1f}",
                f"{r['control_steps_per_s']:,.0f}",
                f"{r['physics_steps_per_s']:,.0f}",
            ]
            for r in rows
        ],
    )
    print(table)
    save_results(
        f"cpu_backend_{args.task}",
        {"meta": environment_metadata(accelerator=True), "rows": rows, "goals": GOALS},
        table,
        args.results_dir,
    )


if __name__ == "__main__":
    main()
