"""Single-env speed of the CPU envs beside the raw physics of the same model, Gymnasium's own
``Pusher-v5`` beside its raw physics, and ``gymnasium.make_vec`` sync against async.

For each case (Reach, Touch and Lift on CPU MuJoCo; Touch on PyBullet) this measures, side by
side and repeated (every repeat times every unit once, so a busy phase of the machine hits all
of them alike):

* ``env``: control steps/s of the env itself (``env.unwrapped.step``), one 150-step episode of
  seeded random actions per repeat, reset untimed;
* ``gym.make``: the same through ``gymnasium.make``'s wrappers (TimeLimit, order enforcing,
  passive checker);
* ``raw``: the physics alone on the same trajectory (same reset, same commands). MuJoCo: the
  env's ``ctrl`` of each action (recorded through ``apply_action``), then
  ``mujoco.mj_step(model, data, nstep=substeps)``. PyBullet: the same Bullet calls per substep
  as the env's servo (``getJointStates``, ``calculateInverseDynamics``, ``calculateMassMatrix``,
  ``setJointMotorControlArray`` with the torques the env applied, recorded, and
  ``stepSimulation``), without the servo law's Python or any read-out. ``ratio`` = env
  steps/s / raw control steps/s, the median of the per-repeat ratios: the share of an env step
  spent in physics;
* where each env's time goes: apply_action, ``_physics_step``, ``_physics_read`` and the
  engine-neutral rest (observation, reward, success, info), in microseconds per control step;
* reset time, and for Touch the resident memory of one env (fresh subprocesses).

Beside them: Gymnasium's ``Pusher-v5`` (its own MuJoCo env) against ``mj_step`` of its model
with its frame skip, and ``gymnasium.make_vec(id, num_envs=2, vectorization_mode="sync" |
"async")`` per case, in env steps/s, also with what a user can pass (``vector_kwargs``
``copy=False, context="fork"``; a wrapper dropping ``reward_terms`` from the info); Touch on
MuJoCo at ``num_envs`` 2, 4 and 8; and what the vector env costs by itself per vector step
(a physics-free env with Touch's spaces, with Touch's info and with an empty one).

Goals: env / raw >= 0.6 (Reach, Touch on MuJoCo; Touch on PyBullet), >= 0.5 (Lift); async
with 2 workers >= 1.6 x sync.

Run from the repository root: ``python -m benchmarks.bench_cpu_envs`` (``--repeats``,
``--quick`` for a smoke run, ``--label`` to name the code measured). Results:
``benchmarks/results/cpu/cpu_envs.{json,md}``; the JSON keeps the summaries of the earlier runs
under ``history``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

try:
    from benchmarks.common import (
        RESULTS_DIR,
        environment_metadata,
        markdown_table,
        rss_mb,
        save_results,
        summarize,
        time_interleaved,
    )
except ImportError:  # run as a file: benchmarks/ is on sys.path, the repository root is not
    from common import (  # type: ignore[no-redef]
        RESULTS_DIR,
        environment_metadata,
        markdown_table,
        rss_mb,
        save_results,
        summarize,
        time_interleaved,
    )

import mjx_arm  # noqa: F401  (registers the ids)

# (task, engine) and the least env / raw ratio it should reach
GOALS = {
    ("reach", "mujoco"): 0.6,
    ("touch", "mujoco"): 0.6,
    ("lift", "mujoco"): 0.5,
    ("touch", "pybullet"): 0.6,
}
ASYNC_GOAL = 1.6  # make_vec async / sync, 2 workers
VEC_ENVS = 2
VEC_STEPS = 200  # vector steps per timed unit
EPISODE = 150  # control steps per timed unit: one episode
RSS_REPEATS = 3
NAME = "cpu_envs"
PUSHER = "Pusher-v5"


def case_name(task: str, engine: str) -> str:
    """``"touch/mujoco"``."""
    return f"{task}/{engine}"


def env_id(task: str) -> str:
    """The Gymnasium id of a task, ``mjx_arm/Touch-v0``."""
    return f"mjx_arm/{task.capitalize()}-v0"


def episode_actions(seed: int, size: int, n: int = EPISODE) -> np.ndarray:
    """Random actions of one episode, uniform in [-1, 1], float32 ``(n, size)``."""
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, size)).astype(np.float32)


# --------------------------------------------------------------------------- workloads


class CaseBench:
    """The timed units of one case: env episode, wrapped episode, raw physics episode.

    Every unit replays the same actions from the same seeded reset, so env and raw physics
    simulate the same trajectory.

    Args:
        task: "reach", "touch" or "lift".
        engine: "mujoco" or "pybullet".
        seed: seed of the resets and actions.
    """

    def __init__(self, task: str, engine: str, seed: int = 0) -> None:
        self.task, self.engine, self.seed = task, engine, seed
        self.wrapped = gym.make(env_id(task), engine=engine)
        self.env = self.wrapped.unwrapped
        self.actions = episode_actions(seed, self.env.action_space.shape[0])
        self.substeps = self.env.task.n_substeps
        if engine == "mujoco":
            self.commands, self.raw_episode = self._mujoco_ctrl(), self._raw_mujoco
        else:
            self.commands, self.raw_episode = self._bullet_torques(), self._raw_pybullet

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

    def _mujoco_ctrl(self) -> np.ndarray:
        """The ``ctrl`` the env writes for each action, ``(EPISODE, nu)``."""
        self.reset()
        rows = []
        for action in self.actions:
            self.env.apply_action(action)
            rows.append(self.env.data.ctrl.copy())
        return np.array(rows)

    def _raw_mujoco(self) -> None:
        import mujoco

        model, data, nstep = self.env.model, self.env.data, self.substeps
        ctrl = data.ctrl
        for row in self.commands:
            ctrl[:] = row
            mujoco.mj_step(model, data, nstep=nstep)

    def _bullet_torques(self) -> list[list[list[float]]]:
        """The joint torques the env applies at each substep of one episode (recorded)."""
        env, torques = self.env, []
        calls = env._calls

        def record(body: int, joints: Any, mode: int, forces: list[float]) -> None:
            torques.append(list(forces))
            calls.set_motors(body, joints, mode, forces=forces)

        env._calls = calls._replace(set_motors=record)
        try:
            self.env_episode_from_reset()
        finally:
            env._calls = calls
        n = self.substeps
        return [torques[i : i + n] for i in range(0, len(torques), n)]

    def env_episode_from_reset(self) -> None:
        """A seeded reset, then one env episode."""
        self.reset()
        self.env_episode()

    def _raw_pybullet(self) -> None:
        import pybullet

        env = self.env
        client, body, dofs, joints = env.client, env.body, env.ids.dofs, env.ids.joints
        get_states, gravity = client.getJointStates, client.calculateInverseDynamics
        mass, motors = client.calculateMassMatrix, client.setJointMotorControlArray
        step, zeros, torque = client.stepSimulation, env._dof_zeros, pybullet.TORQUE_CONTROL
        for substeps in self.commands:
            for forces in substeps:
                states = get_states(body, dofs)
                q = [s[0] for s in states]
                gravity(body, q, zeros, zeros)
                mass(body, q)  # the drive's mass matrix
                motors(body, joints, torque, forces=forces)
                step()

    def close(self) -> None:
        """Close the env."""
        self.wrapped.close()


class PusherBench:
    """Gymnasium's ``Pusher-v5`` and ``mj_step`` of its model with its frame skip, on the same
    seeded actions (its ``do_simulation`` also runs ``mj_rnePostConstraint``: part of the
    env here)."""

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self.env = gym.make(PUSHER).unwrapped
        low, high = self.env.action_space.low, self.env.action_space.high
        rng = np.random.default_rng(seed)
        self.actions = rng.uniform(low, high, (EPISODE, len(low))).astype(np.float32)

    def reset(self) -> None:
        """Seeded reset."""
        self.env.reset(seed=self.seed)

    def env_episode(self) -> None:
        """One episode of ``env.unwrapped.step``."""
        step = self.env.step
        for action in self.actions:
            step(action)

    def raw_episode(self) -> None:
        """The physics of one episode."""
        import mujoco

        model, data, nstep = self.env.model, self.env.data, self.env.frame_skip
        ctrl = data.ctrl
        for action in self.actions:
            ctrl[:] = action
            mujoco.mj_step(model, data, nstep=nstep)

    def close(self) -> None:
        """Close the env."""
        self.env.close()


HOOKS = ("_command", "_physics_step", "_physics_read")


def step_breakdown(bench: CaseBench, episodes: int = 4) -> dict[str, float]:
    """Microseconds per control step spent in each part of ``BaseRobotEnv.step``: sending the
    action (``_command``), stepping the physics, reading it, and the rest.

    Runs real episodes (same actions as the timed units) with the engine hooks wrapped in timers;
    ``rest`` = the whole step minus the hooks: observation, reward, success and info (the
    engine-neutral code of ``mjx_arm.task`` and ``BaseRobotEnv``).
    """
    env = bench.env
    spent = dict.fromkeys([*HOOKS, "step"], 0.0)

    def timed(name: str, fn: Any) -> Any:
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


# --------------------------------------------------------------------------- make_vec


class SlimInfo(gym.Wrapper):
    """Drops ``reward_terms`` from each step's info (the user's choice where a vector env's
    learner reads no term): 14 fewer entries for the vector env to batch per env and step."""

    def step(self, action: Any):
        """The env's step, its info without ``reward_terms``."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.pop("reward_terms", None)
        return obs, reward, terminated, truncated, info


# What a user can pass to ``make_vec``: each mode's ``(vectorization_mode, vector_kwargs,
# wrappers)``. ``shared_memory`` is already AsyncVectorEnv's default; ``copy=False`` skips the
# copy of the batched observation (the next step overwrites it); ``context="fork"`` is Linux's
# default start method, named; :class:`SlimInfo` leaves the vector env less info to batch.
TUNED = "async, copy=False, fork"
VEC_MODES = {
    "sync": ("sync", {}, ()),
    "async": ("async", {}, ()),
    TUNED: ("async", {"shared_memory": True, "copy": False, "context": "fork"}, ()),
    "sync, no reward_terms": ("sync", {}, (SlimInfo,)),
    "async, no reward_terms": ("async", {}, (SlimInfo,)),
}
VEC_SIZES = (2, 4, 8)  # num_envs of the scaling rows (Touch on MuJoCo)


def vector_rates(
    task: str, engine: str, repeats: int, num_envs: int = VEC_ENVS, modes: Any = VEC_MODES
) -> dict[str, Any]:
    """Env steps/s of ``gymnasium.make_vec(..., num_envs)`` in each of ``modes`` (name ->
    ``(vectorization_mode, vector_kwargs)``), side by side, :data:`VEC_STEPS` vector steps of
    seeded random actions per repeat (the workers started and reset untimed; episodes end and
    restart inside the timed steps). ``async_over_sync``: the plain async mode against sync."""
    envs = {
        name: gym.make_vec(
            env_id(task),
            num_envs=num_envs,
            vectorization_mode=mode,
            vector_kwargs=kwargs,
            wrappers=list(wrappers),
            engine=engine,
        )
        for name, (mode, kwargs, wrappers) in modes.items()
    }
    try:
        seconds = _time_vectors(envs, repeats, num_envs)
    finally:
        for vec in envs.values():
            vec.close()
    rates = {m: summarize([num_envs * VEC_STEPS / t for t in s]) for m, s in seconds.items()}
    speedup = {
        name: statistics.median(b / a for a, b in zip(s, seconds["sync"], strict=True))
        for name, s in seconds.items()
        if name != "sync"
    }
    return {
        "num_envs": num_envs,
        "sync_env_steps_per_s": rates["sync"],
        "async_env_steps_per_s": rates["async"],
        "env_steps_per_s": rates,
        "over_sync": speedup,
        "async_over_sync": speedup["async"],
        "passed": speedup["async"] >= ASYNC_GOAL,
    }


def _time_vectors(envs: dict[str, Any], repeats: int, num_envs: int) -> dict[str, list[float]]:
    """Seconds per :data:`VEC_STEPS` vector steps of each vector env, side by side."""
    size = next(iter(envs.values())).single_action_space.shape[0]
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, (VEC_STEPS, num_envs, size)).astype(np.float32)
    for vec in envs.values():
        vec.reset(seed=0)

    def unit(vec: Any) -> Any:
        def run() -> None:
            for action in actions:
                vec.step(action)

        return run

    return time_interleaved({m: unit(v) for m, v in envs.items()}, repeats, warmup=1)


class NullEnv(gym.Env):
    """An env without physics: Touch's spaces, a fixed observation and either Touch's info (the
    keys and the nested reward terms of a real step) or an empty one. Through ``make_vec`` it
    times what a vector env costs per step beside the env's own work: the pipe round trip to
    each worker, the batched observation and the per-key batching of the info."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, info: bool = True) -> None:
        env = gym.make(env_id("touch")).unwrapped
        self.observation_space, self.action_space = env.observation_space, env.action_space
        self._obs, _ = env.reset(seed=0)
        self._info = env.step(np.zeros(6, np.float32))[4] if info else {}
        env.close()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """The fixed observation."""
        super().reset(seed=seed)
        return self._obs, dict(self._info)

    def step(self, action: Any):
        """The fixed observation, reward 0, never done."""
        return self._obs, 0.0, False, False, dict(self._info)


NULL_ID = "mjx_arm_bench/Null-v0"
if NULL_ID not in gym.registry:
    gym.register(NULL_ID, entry_point=NullEnv)


def vector_overhead(repeats: int) -> dict[str, Any]:
    """Microseconds per vector step (``num_envs=2``) of :class:`NullEnv` with Touch's info and
    with none, sync and async: what the vector env itself costs, the floor under any env."""
    out: dict[str, Any] = {}
    for name, info in (("touch_info", True), ("no_info", False)):
        envs = {
            mode: gym.make_vec(
                NULL_ID, num_envs=VEC_ENVS, vectorization_mode=m, vector_kwargs=kw, info=info
            )
            for mode, (m, kw, _) in VEC_MODES.items()
            if mode in ("sync", "async", TUNED)
        }
        try:
            seconds = _time_vectors(envs, repeats, VEC_ENVS)
        finally:
            for vec in envs.values():
                vec.close()
        out[name] = {m: summarize([t / VEC_STEPS * 1e6 for t in s]) for m, s in seconds.items()}
    return out


def async_break_even(overhead: dict[str, Any], goal: float = ASYNC_GOAL) -> dict[str, float]:
    """The least env step (microseconds) at which async can be ``goal`` times sync, per info
    row of :func:`vector_overhead`.

    With ``N`` workers on ``N`` free cores, a sync vector step takes ``N s + o_sync`` and an
    async one at best ``s + o_async`` (the workers step at once), so async / sync >= ``goal``
    needs ``s >= (goal o_async - o_sync) / (N - goal)``.
    """
    out = {}
    for info, r in overhead.items():
        o_sync, o_async = r["sync"]["median"], r["async"]["median"]
        out[info] = (goal * o_async - o_sync) / (VEC_ENVS - goal)
    return out


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
        for action in episode_actions(0, 6):
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


def median_rss(engine: str) -> dict[str, Any]:
    """:func:`rss_in_subprocess`, :data:`RSS_REPEATS` times: medians and every repeat."""
    rss = [rss_in_subprocess(engine) for _ in range(RSS_REPEATS)]
    out: dict[str, Any] = {k: statistics.median(r[k] for r in rss) for k in rss[0]}
    out["repeats"] = rss
    return out


# --------------------------------------------------------------------------- run


def time_cases(
    benches: dict[str, CaseBench], pusher: PusherBench, repeats: int
) -> dict[str, list[float]]:
    """Seconds per unit, every case's env, wrapped env, raw physics and reset, and Pusher's
    env and raw physics, side by side."""
    fns: dict[str, Any] = {}
    setups: dict[str, Any] = {}
    for name, b in benches.items():
        fns[f"{name}/env"], setups[f"{name}/env"] = b.env_episode, b.reset
        fns[f"{name}/gym.make"], setups[f"{name}/gym.make"] = b.wrapped_episode, b.reset_wrapped
        fns[f"{name}/raw"], setups[f"{name}/raw"] = b.raw_episode, b.reset
        fns[f"{name}/reset"] = b.reset
    fns["pusher/env"], setups["pusher/env"] = pusher.env_episode, pusher.reset
    fns["pusher/raw"], setups["pusher/raw"] = pusher.raw_episode, pusher.reset
    cpu: dict[str, list[float]] = {name: [] for name in fns}
    seconds = time_interleaved(
        {name: _cpu_timed(fn, cpu[name]) for name, fn in fns.items()}, repeats, 1, setups
    )
    # the CPU time of this thread per unit, the warm-up's dropped: on a machine that other
    # processes share, the work done, where wall time also counts the waits for a core
    seconds.update({f"{name}/cpu": times[1:] for name, times in cpu.items()})
    return seconds


def _cpu_timed(fn: Any, out: list[float]) -> Any:
    """``fn``, appending the thread's CPU time of each call to ``out``."""

    def run() -> None:
        start = time.thread_time()
        fn()
        out.append(time.thread_time() - start)

    return run


def env_and_raw(seconds: dict[str, list[float]], name: str) -> dict[str, Any]:
    """Env and raw control steps/s of ``name`` and the median of their per-repeat ratio."""
    env, raw = seconds[f"{name}/env"], seconds[f"{name}/raw"]
    return {
        "env_steps_per_s": summarize([EPISODE / s for s in env]),
        "raw_steps_per_s": summarize([EPISODE / s for s in raw]),
        # env steps/s / raw steps/s of the same repeat: the share of a step spent in physics
        "ratio": statistics.median(r / e for e, r in zip(env, raw, strict=True)),
        # the same in CPU time (what the wall-clock ratio is where no other process runs)
        "ratio_cpu_time": statistics.median(
            r / e
            for e, r in zip(seconds[f"{name}/env/cpu"], seconds[f"{name}/raw/cpu"], strict=True)
        ),
    }


def case_result(name: str, b: CaseBench, seconds: dict[str, list[float]]) -> dict[str, Any]:
    """The JSON entry of one case."""
    goal = GOALS[(b.task, b.engine)]
    result = env_and_raw(seconds, name)
    result.update(
        gym_make_steps_per_s=summarize([EPISODE / s for s in seconds[f"{name}/gym.make"]]),
        substeps=b.substeps,
        raw_physics_steps_per_s=result["raw_steps_per_s"]["median"] * b.substeps,
        reset_ms=summarize([s * 1e3 for s in seconds[f"{name}/reset"]]),
        goal=f"env / raw >= {goal}",
        passed=result["ratio"] >= goal,
        step_breakdown_us=step_breakdown(b),
    )
    return result


def run(repeats: int, vec_repeats: int, label: str | None = None) -> dict[str, Any]:
    """Measure every case, Pusher and make_vec; return the JSON payload."""
    meta = environment_metadata(packages=("mujoco", "pybullet", "gymnasium", "numpy"))
    benches = {case_name(*case): CaseBench(*case) for case in GOALS}
    pusher = PusherBench()
    seconds = time_cases(benches, pusher, repeats)
    cases = {name: case_result(name, b, seconds) for name, b in benches.items()}
    for b in benches.values():
        b.close()
    pusher.close()
    vectors = {case_name(*case): vector_rates(*case, vec_repeats) for case in GOALS}
    scaling = {
        str(n): vector_rates(
            "touch",
            "mujoco",
            vec_repeats,
            n,
            {"sync": VEC_MODES["sync"], "async": VEC_MODES["async"]},
        )
        for n in VEC_SIZES
    }
    overhead = vector_overhead(vec_repeats)
    memory = {engine: median_rss(engine) for engine in ("mujoco", "pybullet")}
    meta["load_average_1min_end"] = _load_average()
    return {
        "benchmark": NAME,
        "label": label,
        "episode_steps_per_repeat": EPISODE,
        "repeats": repeats,
        "meta": meta,
        "cases": cases,
        "pusher_v5": env_and_raw(seconds, "pusher"),
        "make_vec": {"num_envs": VEC_ENVS, "vector_steps_per_repeat": VEC_STEPS, **vectors},
        "make_vec_scaling_touch_mujoco": scaling,
        "make_vec_overhead_us": overhead,
        "async_goal_least_step_us": async_break_even(overhead),
        "rss_mb_touch": memory,
    }


def _load_average() -> float | None:
    import os

    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


# --------------------------------------------------------------------------- history


def summary(payload: dict[str, Any]) -> dict[str, Any]:
    """The key figures of a payload (this script's or the earlier Touch-only one's)."""
    meta = payload.get("meta", {})
    out = {
        "date": meta.get("date"),
        "git_commit": meta.get("git_commit"),
        "label": payload.get("label"),
        "load_average_1min": meta.get("load_average_1min"),
    }
    if "cases" in payload:
        out["cases"] = {
            name: {
                "env_steps_per_s": r["env_steps_per_s"]["median"],
                "raw_steps_per_s": r["raw_steps_per_s"]["median"],
                "ratio": r["ratio"],
                "ratio_cpu_time": r.get("ratio_cpu_time"),
            }
            for name, r in payload["cases"].items()
        }
        out["pusher_v5_ratio"] = payload["pusher_v5"]["ratio"]
        out["async_over_sync"] = {
            name: r["async_over_sync"]
            for name, r in payload["make_vec"].items()
            if isinstance(r, dict)
        }
    else:  # the earlier layout: Touch on each engine, raw in physics steps/s
        out["cases"] = {
            f"touch/{engine}": {
                "env_steps_per_s": r["env_steps_per_s"]["median"],
                "raw_steps_per_s": r["raw_physics_steps_per_s"]["median"] / r["substeps"],
                "ratio": r["ratio"],
                "raw": "mj_step / stepSimulation after one velocity-motor call per control step",
            }
            for engine, r in payload["engines"].items()
        }
    return out


def with_history(payload: dict[str, Any], path: Path) -> dict[str, Any]:
    """``payload`` with ``history``: the earlier runs' summaries, oldest first, the run saved
    at ``path`` (if any) last."""
    history: list[dict[str, Any]] = []
    if path.exists():
        previous = json.loads(path.read_text())
        history = [*previous.get("history", []), summary(previous)]
    return {**payload, "history": history}


# --------------------------------------------------------------------------- report


def _rate(r: dict[str, Any]) -> str:
    return f"{r['median']:,.0f} ({r['min']:,.0f}-{r['max']:,.0f})"


def case_table(payload: dict[str, Any]) -> str:
    """Env against raw physics per case, and Pusher-v5."""
    rows = []
    for name, r in payload["cases"].items():
        rows.append(
            [
                name,
                _rate(r["env_steps_per_s"]),
                f"{r['gym_make_steps_per_s']['median']:,.0f}",
                _rate(r["raw_steps_per_s"]),
                f"{r['ratio']:.2f}",
                f"{r['ratio_cpu_time']:.2f}",
                f"{r['reset_ms']['median']:.2f}",
                r["goal"],
                "PASS" if r["passed"] else "FAIL",
            ]
        )
    p = payload["pusher_v5"]
    rows.append(
        [
            f"{PUSHER} (Gymnasium)",
            _rate(p["env_steps_per_s"]),
            "",
            _rate(p["raw_steps_per_s"]),
            f"{p['ratio']:.2f}",
            f"{p['ratio_cpu_time']:.2f}",
            "",
            "",
            "",
        ]
    )
    headers = [
        "case",
        "env steps/s (min-max)",
        "via gym.make",
        "raw physics, control steps/s (min-max)",
        "env / raw",
        "env / raw, CPU time",
        "reset ms",
        "goal",
        "",
    ]
    return markdown_table(headers, rows)


def vector_table(payload: dict[str, Any]) -> str:
    """make_vec sync and async per case, and with the options a user can pass (medians; the
    ratios are medians of side-by-side repeats against plain sync)."""
    rows = []
    for name, r in payload["make_vec"].items():
        if not isinstance(r, dict):
            continue
        rates, over = r.get("env_steps_per_s", {}), r.get("over_sync", {})
        cells = [
            f"{rates[m]['median']:,.0f}" if m in rates else "" for m in VEC_MODES if m != "sync"
        ]
        ratios = [f"{over[m]:.2f}" if m in over else "" for m in VEC_MODES if m != "sync"]
        rows.append(
            [
                name,
                _rate(r["sync_env_steps_per_s"]),
                *(f"{c} ({q})" for c, q in zip(cells, ratios, strict=True)),
                f">= {ASYNC_GOAL}",
                "PASS" if r["passed"] else "FAIL",
            ]
        )
    modes = [m for m in VEC_MODES if m != "sync"]
    headers = ["case", "sync", *(f"{m} (/ sync)" for m in modes), "goal: async / sync", ""]
    return markdown_table(headers, rows)


def scaling_table(payload: dict[str, Any]) -> str:
    """Touch on MuJoCo through make_vec at several num_envs."""
    rows = [
        [
            n,
            _rate(r["sync_env_steps_per_s"]),
            _rate(r["async_env_steps_per_s"]),
            f"{r['async_over_sync']:.2f}",
        ]
        for n, r in payload.get("make_vec_scaling_touch_mujoco", {}).items()
    ]
    return markdown_table(["num_envs", "sync env steps/s", "async env steps/s", "async / sync"],
                          rows)  # fmt: skip


def overhead_table(payload: dict[str, Any]) -> str:
    """Microseconds per vector step of the physics-free env, per info and mode."""
    over = payload.get("make_vec_overhead_us", {})
    modes = ["sync", "async", TUNED]
    rows = [[info, *(f"{r[m]['median']:.0f}" for m in modes)] for info, r in over.items()]
    return markdown_table(["info", *(f"{m}, us per vector step" for m in modes)], rows)


def table(payload: dict[str, Any]) -> str:
    """The markdown summary of a payload."""
    meta = payload["meta"]
    versions = ", ".join(f"{k} {v}" for k, v in meta["packages"].items())
    label = f" Code: {payload['label']}." if payload.get("label") else ""
    text = (
        f"CPU envs: medians of {payload['repeats']} side-by-side repeats of one "
        f"{payload['episode_steps_per_repeat']}-step episode (random actions).{label}\n"
        f"{meta['device']['cpu_model']}, {meta['device']['cores']} cores, Python "
        f"{meta['python']}, {versions}; {meta['date']}, load average "
        f"{meta['load_average_1min']:.2f} at the start, {meta['load_average_1min_end']:.2f} "
        "at the end.\n\n"
    )
    text += case_table(payload)
    text += (
        "\n`env / raw, CPU time`: the same ratio in this process's CPU time, which other "
        "processes on the machine do not stretch (a load average above the 2 cores means "
        "the wall-clock figures also count waits for a core).\n"
    )
    text += (
        f"\n`gymnasium.make_vec(id, num_envs={VEC_ENVS}, vectorization_mode=...)`, env steps/s "
        f"({payload['make_vec']['vector_steps_per_repeat']} vector steps per repeat):\n\n"
    )
    text += vector_table(payload)
    if "make_vec_scaling_touch_mujoco" in payload:
        text += "\nTouch on MuJoCo through `make_vec` at more envs than cores (env steps/s):\n\n"
        text += scaling_table(payload)
        text += (
            f"\nWhat the vector env costs itself: a physics-free env with Touch's spaces "
            f"(`num_envs={VEC_ENVS}`), microseconds per vector step, with Touch's info and with "
            "an empty one:\n\n"
        )
        text += overhead_table(payload)
        least = payload.get("async_goal_least_step_us") or async_break_even(
            payload["make_vec_overhead_us"]
        )
        steps = [r["step_breakdown_us"]["step total"] for r in payload["cases"].values()]
        text += (
            f"\nAsync with {VEC_ENVS} workers reaches {ASYNC_GOAL} x sync only where one env "
            f"step takes at least {least['no_info']:,.0f} us with an empty info "
            f"({least['touch_info']:,.0f} us with Touch's), even with every worker on a core "
            f"of its own (`async_break_even`); these envs' steps take {min(steps):.0f}-"
            f"{max(steps):.0f} us.\n"
        )
    parts = {name: r["step_breakdown_us"] for name, r in payload["cases"].items()}
    names = list(next(iter(parts.values())))
    text += "\nWhere a control step's time goes (microseconds per step, over real episodes):\n\n"
    text += markdown_table(
        ["part", *parts], [[n, *(f"{p[n]:.1f}" for p in parts.values())] for n in names]
    )
    rss = payload["rss_mb_touch"]
    text += "\nResident memory of Touch envs (MiB, fresh processes):\n\n"
    text += markdown_table(
        ["engine", "first env", "one more"],
        [[e, f"{r['env']:.1f}", f"{r['extra_env']:.1f}"] for e, r in rss.items()],
    )
    return text


def main(argv: list[str] | None = None) -> None:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--repeats", type=int, default=15, help="side-by-side repeats")
    parser.add_argument("--vec-repeats", type=int, default=5, help="make_vec repeats")
    parser.add_argument("--quick", action="store_true", help="3 repeats, results not saved")
    parser.add_argument("--label", help="what code the run measures (kept in the history)")
    parser.add_argument("--rss-child", choices=("mujoco", "pybullet"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.rss_child:
        print(json.dumps(measure_rss(args.rss_child)))
        return
    quick = args.quick
    payload = run(3 if quick else args.repeats, 2 if quick else args.vec_repeats, args.label)
    text = table(payload)
    print(text)
    if not quick:
        payload = with_history(payload, RESULTS_DIR / "cpu" / f"{NAME}.json")
        json_path, md_path = save_results(NAME, payload, text, RESULTS_DIR / "cpu")
        print(f"saved {json_path} and {md_path}")


if __name__ == "__main__":
    main()
