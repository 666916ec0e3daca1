"""A reference point for Lift: MuJoCo Playground's own PandaPickCube PPO, on the same machine.

Playground's PandaPickCube (menagerie's MJX Panda with its hand; bring a 4x4x6 cm box from the
floor to a random point 20-40 cm up) trained with Playground's tuned Brax PPO config
(``manipulation_params.brax_ppo_config``), unchanged except ``num_evals`` (16 instead of 4, so
that the success curve has points between start and end). Playground reports rewards only; this
script also measures, at every evaluation, a success rate on 256 episodes of the deterministic
policy under two criteria:

- ``lift``: this project's Lift criterion on the box: its centre 10 cm or more above its start
  for 10 control steps running (Playground's control step is 20 ms, so 0.2 s);
- ``target``: Playground's own goal: the box's centre within 5 cm of its target at the end.

Times are wall seconds from the start of ``ppo.train`` (compiles included), with the seconds
spent in these success evaluations taken out. Run ``mjx-arm bench seeds --task lift --arm
panda.urdf`` beside it for this project's side.

Playground finds its robot in ``mujoco_playground/external_deps/mujoco_menagerie``; the machine
may have no network to clone it. ``--menagerie-panda DIR`` names a folder that holds menagerie's
``mjx_panda.xml`` (its ``assets/`` may be absent). Mesh files it lacks are written as small
placeholder tetrahedra: every mesh geom of that model is visual or collision-disabled
(contype = conaffinity = 0) and every body states its inertia, so the physics is the same; the
script checks both before it trains.

    python -m benchmarks.bench_playground_pick --menagerie-panda DIR --name playground_pick_cube
"""

from __future__ import annotations

import argparse
import ast
import shutil
import struct
import time
from pathlib import Path
from typing import Any

from benchmarks.common import (
    DEFAULT_PACKAGES,
    environment_metadata,
    markdown_table,
    save_results,
)

ENV_NAME = "PandaPickCube"
LIFT_HEIGHT = 0.10  # m, as mjx_arm.task.lift.LIFT_HEIGHT
HOLD_STEPS = 10  # control steps, as Lift's success_hold_steps
TARGET_RADIUS = 0.05  # m
EVAL_ENVS = 256
THRESHOLD = 0.9


# --------------------------------------------------------------------------- the robot's files


def _tetrahedron_obj() -> bytes:
    return b"v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nv 0 0 0.01\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _tetrahedron_stl() -> bytes:
    """A binary STL of the tetrahedron of :func:`_tetrahedron_obj`."""
    v = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    out = bytearray(b"\0" * 80) + struct.pack("<I", len(faces))
    for face in faces:
        out += struct.pack("<3f", 0, 0, 0)
        for i in face:
            out += struct.pack("<3f", *v[i])
        out += struct.pack("<H", 0)
    return bytes(out)


def prepare_menagerie(panda_dir: Path, menagerie: Path) -> list[str]:
    """Lay menagerie's Panda where Playground looks for it; returns the placeholder files made.

    Args:
        panda_dir: a folder with menagerie's ``mjx_panda.xml`` (and maybe ``assets/``).
        menagerie: Playground's ``MENAGERIE_PATH``.
    """
    import xml.etree.ElementTree as ET

    target = menagerie / "franka_emika_panda"
    if not (target / "mjx_panda.xml").exists():
        shutil.copytree(panda_dir, target, dirs_exist_ok=True)
    assets = target / "assets"
    assets.mkdir(exist_ok=True)
    made = []
    for mesh in ET.parse(target / "mjx_panda.xml").getroot().iter("mesh"):
        path = assets / mesh.get("file", "")
        placeholder = _tetrahedron_stl() if path.suffix == ".stl" else _tetrahedron_obj()
        if not path.exists():
            path.write_bytes(placeholder)
        if path.read_bytes() == placeholder:
            made.append(path.name)
    return made


def check_meshes_inert(mj_model: Any) -> None:
    """Raise unless no mesh geom can collide and every body has a stated, non-zero mass.

    Then the mesh files change nothing in the dynamics (placeholders are safe).
    """
    import mujoco

    for g in range(mj_model.ngeom):
        if mj_model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH and (
            mj_model.geom_contype[g] or mj_model.geom_conaffinity[g]
        ):
            raise RuntimeError(f"mesh geom {mj_model.geom(g).name!r} collides")
    massless = [
        mj_model.body(b).name for b in range(1, mj_model.nbody) if mj_model.body_mass[b] <= 0
    ]
    if massless:
        raise RuntimeError(f"bodies without mass: {massless}")


# --------------------------------------------------------------------------- success of a policy


def make_success_eval(env: Any, episode_length: int, num_envs: int = EVAL_ENVS):
    """A rollout of the deterministic policy: success rates under both criteria.

    Returns:
        ``evaluate(make_policy, params, key) -> (lift_rate, target_rate)``, floats in [0, 1];
        the rollout is compiled once, on the first call (Brax's ``make_policy`` stays the same).
    """
    import jax
    import jax.numpy as jnp

    body = env._obj_body  # Playground keeps the box's body id here
    compiled: dict[str, Any] = {}

    def rollout(make_policy, params, key):
        policy = make_policy(params, deterministic=True)
        state = jax.vmap(env.reset)(jax.random.split(key, num_envs))
        start_z = state.data.xpos[:, body, 2]

        def step(carry, step_key):
            state, run, best = carry
            action, _ = policy(state.obs, step_key)
            state = jax.vmap(env.step)(state, action)
            up = state.data.xpos[:, body, 2] >= start_z + LIFT_HEIGHT
            run = jnp.where(up, run + 1, 0)
            return (state, run, jnp.maximum(best, run)), None

        zeros = jnp.zeros(num_envs, jnp.int32)
        step_keys = jax.random.split(jax.random.fold_in(key, 1), episode_length)
        (state, _, best), _ = jax.lax.scan(step, (state, zeros, zeros), step_keys)
        error = jnp.linalg.norm(state.data.xpos[:, body] - state.info["target_pos"], axis=-1)
        return jnp.mean(best >= HOLD_STEPS), jnp.mean(error < TARGET_RADIUS)

    def evaluate(make_policy, params, key) -> tuple[float, float]:
        if "fn" not in compiled:
            compiled["fn"] = jax.jit(lambda p, k: rollout(make_policy, p, k))
        lift, target = compiled["fn"](params, key)
        return float(lift), float(target)

    return evaluate


# --------------------------------------------------------------------------- training


def _replicate_shim() -> None:
    """brax 0.14.2 calls ``jax.device_put_replicated``, which jax 0.10 removed
    (google/brax#671): give it one that stacks a copy per device."""
    import jax
    import jax.numpy as jnp

    if not hasattr(jax, "device_put_replicated"):

        def device_put_replicated(tree, devices):
            n = len(devices)
            return jax.tree.map(lambda a: jnp.stack([jnp.asarray(a)] * n), tree)

        jax.device_put_replicated = device_put_replicated


def train(args: argparse.Namespace) -> dict[str, Any]:
    """Train PandaPickCube with Playground's config; returns the curve and the timings."""
    import functools

    import jax
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo
    from mujoco_playground import registry, wrapper
    from mujoco_playground._src import mjx_env
    from mujoco_playground.config import manipulation_params

    _replicate_shim()
    made = prepare_menagerie(Path(args.menagerie_panda), Path(mjx_env.MENAGERIE_PATH))
    env_cfg = registry.get_default_config(ENV_NAME)
    if args.impl:
        env_cfg.impl = args.impl
    env = registry.load(ENV_NAME, config=env_cfg)
    check_meshes_inert(env.mj_model)
    ppo_cfg = manipulation_params.brax_ppo_config(ENV_NAME)
    shipped = ppo_cfg.to_dict()
    ppo_cfg.num_evals = args.num_evals
    ppo_cfg.seed = args.seed
    for item in args.set:
        key, value = item.split("=", 1)
        ppo_cfg[key] = ast.literal_eval(value)
    params = ppo_cfg.to_dict()
    factory = functools.partial(ppo_networks.make_ppo_networks, **params.pop("network_factory"))
    evaluate = make_success_eval(env, env_cfg.episode_length)

    curve: list[dict[str, Any]] = []
    clock = {"start": 0.0, "eval_s": 0.0}

    def policy_params_fn(step: int, make_policy, policy_params) -> None:
        t0 = time.perf_counter()
        wall = t0 - clock["start"] - clock["eval_s"]  # training time so far, evaluations out
        lift, target = evaluate(make_policy, policy_params, jax.random.PRNGKey(1000 + len(curve)))
        clock["eval_s"] += time.perf_counter() - t0
        curve.append({"steps": int(step), "wall_s": wall, "lift": lift, "target": target})
        print(
            f"  {step:>11,d} steps  {wall:7.1f} s  lift {lift:.3f}  target {target:.3f}", flush=True
        )

    def progress_fn(step: int, metrics: dict[str, Any]) -> None:
        reward = float(metrics.get("eval/episode_reward", float("nan")))
        if curve and curve[-1]["steps"] == int(step):
            curve[-1]["eval_reward"] = reward

    print(
        f"{ENV_NAME}: {params['num_timesteps']:,} steps, {params['num_envs']} envs, "
        f"impl {env_cfg.impl}, seed {args.seed}; placeholder meshes: {len(made)}",
        flush=True,
    )
    clock["start"] = time.perf_counter()
    ppo.train(
        environment=env,
        wrap_env_fn=wrapper.wrap_for_brax_training,
        network_factory=factory,
        progress_fn=progress_fn,
        policy_params_fn=policy_params_fn,
        **params,
    )
    total = time.perf_counter() - clock["start"] - clock["eval_s"]
    first = {k: next((p for p in curve if p[k] >= THRESHOLD), None) for k in ("lift", "target")}
    return {
        "env": ENV_NAME,
        "impl": env_cfg.impl,
        "seed": args.seed,
        "shipped_ppo_config": shipped,
        "ppo_config": ppo_cfg.to_dict(),
        "placeholder_meshes": made,
        "total_steps": curve[-1]["steps"] if curve else 0,
        "train_s": total,
        "success_eval_s": clock["eval_s"],
        "steps_per_s": (curve[-1]["steps"] / total) if curve and total > 0 else None,
        "curve": curve,
        "final": curve[-1] if curve else None,
        "time_to_threshold_s": {k: (p["wall_s"] if p else None) for k, p in first.items()},
        "steps_to_threshold": {k: (p["steps"] if p else None) for k, p in first.items()},
        "threshold": THRESHOLD,
    }


def main() -> None:
    """Command line: train, print the table, save JSON and markdown."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--menagerie-panda", required=True, help="folder with mjx_panda.xml")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-evals", type=int, default=16)
    parser.add_argument("--impl", default="", help="jax or warp (default: Playground's)")
    parser.add_argument("--set", nargs="*", default=[], help="PPO config overrides key=value")
    parser.add_argument("--name", default="playground_pick_cube")
    parser.add_argument("--results-dir", default="")
    args = parser.parse_args()
    result = train(args)
    rows = [
        [
            f"{p['steps']:,}",
            f"{p['wall_s']:.1f}",
            f"{p.get('eval_reward', float('nan')):.1f}",
            f"{p['lift']:.3f}",
            f"{p['target']:.3f}",
        ]
        for p in result["curve"]
    ]
    table = markdown_table(
        ["steps", "wall s", "eval reward", "lift success", "target success"], rows
    )
    tts = result["time_to_threshold_s"]
    summary = (
        f"{ENV_NAME} (MuJoCo Playground, its PPO config; num_evals {args.num_evals}), seed "
        f"{args.seed}: {result['total_steps']:,} steps in {result['train_s']:.1f} s; time to "
        f"{THRESHOLD} lift success: {tts['lift']}; to {THRESHOLD} target success: {tts['target']}"
    )
    print(table + "\n\n" + summary)
    payload = {
        "meta": environment_metadata((*DEFAULT_PACKAGES, "playground"), accelerator=True),
        **result,
    }
    save_results(
        args.name,
        payload,
        summary + "\n\n" + table,
        Path(args.results_dir) if args.results_dir else None,
    )


if __name__ == "__main__":
    main()
