"""Single-env speed of the CPU envs beside the raw physics rate of the same model.

For each engine (MuJoCo, PyBullet) on the Touch task this measures, side by side and repeated:

* ``env``: control steps/s of the env itself (``env.unwrapped.step``), one 150-step episode per
  repeat, reset untimed;
* ``gym.make``: the same through ``gymnasium.make``'s wrappers (TimeLimit, order enforcing,
  passive checker);
* ``raw``: physics steps/s of the same model on the same trajectory (same reset, same actions):
  ``mujoco.mj_step(model, data, nstep=8)`` per control step, or 8 ``stepSimulation()`` calls after
  one ``setJointMotorControlArray``. ``env x substeps / raw`` is the share of time spent in
  physics; the rest is Python overhead;
* where each env's time goes: apply_action, ``_physics_step``, ``_physics_read`` and the
  engine-neutral rest (observation, reward, success, info), in microseconds per control step;
* reset time, and the resident memory of one env (RSS after building it, resetting it and
  running an episode, minus RSS after the imports), each engine in a fresh subprocess.

Goals: MuJoCo env steps/s x substeps >= 0.7 x raw mj_step/s; PyBullet env >= 2000 steps/s.

Run from the repository root: ``python -m benchmarks.bench_cpu_envs`` (``--repeats``,
``--quick`` for a smoke run). Results: ``benchmarks/results/cpu_envs.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

try:
    from benchmarks.common import (
        environment_metadata,
        markdown_table,
        rss_mb,
        save_results,
        summarize,
        time_interleaved,
    )
except ImportError:  # run as a file: benchmarks/ is on sys.path, the repository root is not
    from common import (  # type: ignore[no-redef]
        environment_metadata,
        markdown_table,
        rss_mb,
        save_results,
        summarize,
        time_interleaved,
    )

import mjx_arm  # noqa: F401  (registers the ids)

ENV_ID = "mjx_arm/Touch-v0"
ENGINES = ("mujoco", "pybullet")
EPISODE = 150  # control steps per timed unit: one full episode
MUJOCO_MIN_RATIO = 0.7  # env steps/s x substeps >= 0.7 x raw mj_step/s
PYBULLET_MIN_RATE = 2000.0  # env steps/s
RSS_REPEATS = 3
NAME = "cpu_envs"


# --------------------------------------------------------------------------- workloads


def episode_actions(seed: int, n: int = EPISODE) -> np.ndarray:
    """Random actions of one episode, uniform in [-1, 1], float32 ``(n, 6)``."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 6)).astype(np.float32)


class EngineBench:
    """The timed units of one engine: env episode, wrapped episode, raw physics episode.

    Every unit replays the same actions from the same seeded reset, so env and raw physics
    simulate the same trajectory.

    Args:
        engine: "mujoco" or "pybullet".
        seed: seed of the resets and actions.
    """

    def __init__(self, engine: str, seed: int = 0) -> None:
        self.engine = engine
        self.seed = seed
        self.wrapped = gym.make(ENV_ID, engine=engine)
        self.env = self.wrapped.unwrapped
        self.actions = episode_actions(seed)
        self.substeps = self.env.task.n_substeps
        qdot = self.actions.astype(np.float64) * self.env.task.action_scale * self.env.arm.v_max
        self.qdot = qdot
        self.raw_episode = self._raw_mujoco if engine == "mujoco" else self._raw_pybullet

    def reset(self) -> None:
        """Seeded reset of the env (untimed setup of every unit)."""
        self.env.reset(seed=self.seed)

    def reset_wrapped(self) -> None:
        """Seeded reset through the wrappers."""
        self.wrapped.reset(seed=self.seed)

    def env_episode(self) -> None:
        """One episode of ``env.unwrapped.step``."""
        step = self.env.step
        for action in self.actions:
            step(action)

    def wrapped_episode(self) -> None:
        """One episode through ``gymnasium.make``'s wrappers."""
        step = self.wrapped.step
        for action in self.actions:
            step(action)

    def _raw_mujoco(self) -> None:
        import mujoco

        model, data, actuators = self.env.model, self.env.data, self.env.ids.actuators
        for qdot in self.qdot:
            data.ctrl[actuators] = qdot
            mujoco.mj_step(model, data, nstep=self.substeps)

    def _raw_pybullet(self) -> None:
        import pybullet

        client, body, joints = self.env.client, self.env.body, list(self.env.ids.joints)
        forces = [float(e) for e in self.env.arm.effort]
        for qdot in self.qdot:
            client.setJointMotorControlArray(
                body,
                joints,
                pybullet.VELOCITY_CONTROL,
                targetVelocities=qdot.tolist(),
                forces=forces,
            )
            for _ in range(self.substeps):
                client.stepSimulation()

    def close(self) -> None:
        """Close the env."""
        self.wrapped.close()


HOOKS = ("apply_action", "_physics_step", "_physics_read")


def step_breakdown(bench: EngineBench, episodes: int = 4) -> dict[str, float]:
    """Microseconds per control step spent in each part of ``BaseRobotEnv.step``.

    Runs real episodes (same actions as the timed units) with the engine hooks wrapped in timers;
    ``rest`` = the whole step minus the hooks: observation, reward, success and info (the
    engine-neutral code of ``mjx_arm.task`` and ``BaseRobotEnv``).
    """
    env = bench.env
    spent = dict.fromkeys([*HOOKS, "step"], 0.0)

    def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] += time.perf_counter() - start

        return wrapper

    for _ in range(episodes):
        env.reset(seed=bench.seed)  # untimed, with the original hooks
        for name in HOOKS:
            setattr(env, name, timed(name, getattr(env, name)))
        step = timed("step", env.step)
        try:
            for action in bench.actions:
                step(action)
        finally:
            for name in HOOKS:
                delattr(env, name)  # back to the class's methods
    n = episodes * len(bench.actions)
    parts = {name.lstrip("_"): spent[name] / n * 1e6 for name in HOOKS}
    parts["rest (obs, reward, success, info)"] = spent["step"] / n * 1e6 - sum(parts.values())
    parts["step total"] = spent["step"] / n * 1e6
    return parts


# --------------------------------------------------------------------------- memory


def measure_rss(engine: str) -> dict[str, float]:
    """RSS (MiB) of a fresh process: interpreter (with gymnasium, numpy and mjx_arm imported),
    the engine's imports on top, the first env (built, reset, one episode run; includes the
    one-time URDF validation and model caches) and a second env beside it (the cost per extra
    env, e.g. in a vector env)."""
    base = rss_mb()
    from mjx_arm.envs.registration import make_env

    if engine == "mujoco":
        import mjx_arm.envs.mujoco_env  # noqa: F401
    else:
        import pybullet_ref.env  # noqa: F401
    imported = rss_mb()
    levels = [imported]
    envs = []
    for _ in range(2):
        env = make_env("touch", engine=engine)
        env.reset(seed=0)
        for action in episode_actions(0):
            env.step(action)
        envs.append(env)
        levels.append(rss_mb())
    for env in envs:
        env.close()
    return {
        "interpreter": base,
        "imports": imported - base,
        "env": levels[1] - levels[0],
        "extra_env": levels[2] - levels[1],
    }


def rss_in_subprocess(engine: str) -> dict[str, float]:
    """:func:`measure_rss` in a new interpreter (nothing cached from this one)."""
    root = Path(__file__).resolve().parent.parent
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_cpu_envs", "--rss-child", engine],
        cwd=root,
        capture_output=True,
        text=True,
        check=True,
    )
    # PyBullet's C code prints to the same stdout: take the one JSON line
    (line,) = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    return json.loads(line)


# --------------------------------------------------------------------------- report


def run(repeats: int) -> dict[str, Any]:
    """Measure both engines; return the JSON payload."""
    benches = {engine: EngineBench(engine) for engine in ENGINES}
    fns, setups = {}, {}
    for engine, b in benches.items():
        fns[f"{engine}/env"], setups[f"{engine}/env"] = b.env_episode, b.reset
        fns[f"{engine}/gym.make"], setups[f"{engine}/gym.make"] = b.wrapped_episode, b.reset_wrapped
        fns[f"{engine}/raw"], setups[f"{engine}/raw"] = b.raw_episode, b.reset
        fns[f"{engine}/reset"] = b.reset
    seconds = time_interleaved(fns, repeats, warmup=1, setups=setups)

    engines: dict[str, Any] = {}
    for engine, b in benches.items():
        env_rate = summarize([EPISODE / s for s in seconds[f"{engine}/env"]])
        wrapped_rate = summarize([EPISODE / s for s in seconds[f"{engine}/gym.make"]])
        raw_rate = summarize([EPISODE * b.substeps / s for s in seconds[f"{engine}/raw"]])
        ratios = [
            e * b.substeps / r
            for e, r in zip(env_rate["repeats"], raw_rate["repeats"], strict=True)
        ]
        rss = [rss_in_subprocess(engine) for _ in range(RSS_REPEATS)]
        result = {
            "env_steps_per_s": env_rate,
            "gym_make_steps_per_s": wrapped_rate,
            "raw_physics_steps_per_s": raw_rate,
            "substeps": b.substeps,
            # env steps/s x substeps / raw physics steps/s: the share of time in physics;
            # median of the per-repeat ratios (each repeat times env and raw side by side)
            "ratio": statistics.median(ratios),
            "ratio_repeats": ratios,
            "reset_ms": summarize([s * 1e3 for s in seconds[f"{engine}/reset"]]),
            "rss_mb": {
                "env": statistics.median(r["env"] for r in rss),
                "extra_env": statistics.median(r["extra_env"] for r in rss),
                "imports": statistics.median(r["imports"] for r in rss),
                "interpreter": statistics.median(r["interpreter"] for r in rss),
                "repeats": rss,
            },
        }
        if engine == "mujoco":
            result["goal"] = f"env steps/s x substeps >= {MUJOCO_MIN_RATIO} x raw mj_step/s"
            result["passed"] = result["ratio"] >= MUJOCO_MIN_RATIO
        else:
            result["goal"] = f"env steps/s >= {PYBULLET_MIN_RATE:.0f}"
            result["passed"] = env_rate["median"] >= PYBULLET_MIN_RATE
        result["step_breakdown_us"] = step_breakdown(b)
        engines[engine] = result
    for b in benches.values():
        b.close()
    return {
        "benchmark": NAME,
        "task": ENV_ID,
        "episode_steps_per_repeat": EPISODE,
        "repeats": repeats,
        "meta": environment_metadata(packages=("mujoco", "pybullet", "gymnasium", "numpy")),
        "engines": engines,
    }


def table(payload: dict[str, Any]) -> str:
    """The markdown summary of a payload."""
    meta = payload["meta"]
    rows = []
    for engine, r in payload["engines"].items():
        env, raw = r["env_steps_per_s"], r["raw_physics_steps_per_s"]
        rows.append(
            [
                engine,
                f"{env['median']:,.0f} ({env['min']:,.0f}-{env['max']:,.0f})",
                f"{r['gym_make_steps_per_s']['median']:,.0f}",
                f"{env['median'] * r['substeps']:,.0f}",
                f"{raw['median']:,.0f} ({raw['min']:,.0f}-{raw['max']:,.0f})",
                f"{r['ratio']:.2f}",
                f"{r['reset_ms']['median']:.2f}",
                f"{r['rss_mb']['env']:.1f} / {r['rss_mb']['extra_env']:.1f}",
                r["goal"],
                "PASS" if r["passed"] else "FAIL",
            ]
        )
    headers = [
        "engine",
        "env steps/s (min-max)",
        "via gym.make",
        "env physics steps/s",
        "raw physics steps/s (min-max)",
        "env x substeps / raw",
        "reset ms",
        "RSS MiB: first env / one more",
        "goal",
        "",
    ]
    versions = ", ".join(f"{k} {v}" for k, v in meta["packages"].items())
    head = (
        f"CPU envs, {payload['task']}, medians of {payload['repeats']} side-by-side repeats of "
        f"one {payload['episode_steps_per_repeat']}-step episode (random actions).\n"
        f"{meta['device']['cpu_model']}, {meta['device']['cores']} cores, Python "
        f"{meta['python']}, {versions}; {meta['date']}, load average "
        f"{meta['load_average_1min']:.2f} at the start.\n\n"
    )
    text = head + markdown_table(headers, rows)
    parts = {name: r["step_breakdown_us"] for name, r in payload["engines"].items()}
    names = list(next(iter(parts.values())))
    text += "\nWhere a control step's time goes (microseconds per step, over real episodes):\n\n"
    text += markdown_table(
        ["part", *parts], [[n, *(f"{p[n]:.1f}" for p in parts.values())] for n in names]
    )
    return text


def main(argv: list[str] | None = None) -> None:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--repeats", type=int, default=15, help="side-by-side repeats")
    parser.add_argument("--quick", action="store_true", help="3 repeats, results not saved")
    parser.add_argument("--rss-child", choices=ENGINES, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.rss_child:
        print(json.dumps(measure_rss(args.rss_child)))
        return
    payload = run(3 if args.quick else args.repeats)
    text = table(payload)
    print(text)
    if not args.quick:
        json_path, md_path = save_results(NAME, payload, text)
        print(f"saved {json_path} and {md_path}")


if __name__ == "__main__":
    main()
