"""Engine parity: C MuJoCo, MJX (JAX or Warp) and PyBullet on the same states and actions.

Four checks, every engine pair compared (:func:`run_parity`; the figures and goals are
:mod:`~mjx_arm.bench.parity_figures`'s):

- **Forward kinematics**: the ee point at random joint angles inside the limits.
- **Open-loop divergence**: piecewise-constant random actions played open loop from the same
  start (the Reach scene); the largest joint-angle difference of a pair at every control step,
  its median and 95th percentile over the sequences as a function of time.
- **Pressing**: the tool driven into the box (the Touch scene) by commands recorded once from a
  Jacobian controller in C MuJoCo and replayed in every engine; the tared F/T reading over time.
- **Jitter**: the arm held still (zero command), under a constant command (both in free
  space) and pressing the box, each with the joint damping as converted and zeroed; the spread
  of the joint acceleration and the velocity's content above the control rate over the end of
  each run, read at every physics step.

C MuJoCo runs in float64, MJX in float32, PyBullet in float64.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.arm.info import ArmInfo, arm_info
from mjx_arm.arm.resolve import task_for_arm
from mjx_arm.bench.engines import Engine, Inputs, MujocoEngine, Trace, make_engine
from mjx_arm.bench.parity_config import (
    BOX_POSITIONS,
    DAMPING,
    FREE_SCENARIOS,
    JITTER_SCENARIOS,
    PRESS_GAIN,
    ParityConfig,
)
from mjx_arm.bench.parity_figures import (
    check_goals,
    fk_figures,
    jitter_figures,
    open_loop_figures,
    press_figures,
)
from mjx_arm.engines import REFERENCE_ENGINE
from mjx_arm.engines import engine as engine_row
from mjx_arm.envs.physics_config import resolve_impl
from mjx_arm.task import reach_config, sampling, touch_config
from mjx_arm.task.config import TaskConfig

# --------------------------------------------------------------------------- inputs


def random_joint_angles(arm: ArmInfo, n: int, seed: int) -> np.ndarray:
    """``(n, 6)`` joint angles uniform inside the limits (clipped to +-pi)."""
    rng = np.random.default_rng(seed)
    low, high = np.maximum(arm.lower, -np.pi), np.minimum(arm.upper, np.pi)
    return rng.uniform(low, high, (n, len(low)))


def per_physics_step(actions: np.ndarray, substeps: int) -> np.ndarray:
    """Control-step actions ``(B, T, 6)`` held for ``substeps`` physics steps, ``(B, T*s, 6)``."""
    return np.repeat(actions, substeps, axis=1)


def open_loop_inputs(task: TaskConfig, config: ParityConfig, steps: int) -> Inputs:
    """Start poses around home, Reach targets and piecewise-constant uniform actions.

    A new action level every ``config.hold_steps`` control steps, each entry uniform in
    ``+-config.amplitude``; ``steps`` control steps. Damping as converted.
    """
    n, rng = config.sequences, np.random.default_rng(config.seed)
    joints = len(task.home_qpos)
    qpos0 = sampling.initial_qpos(np, rng.uniform(size=(n, joints)), task)
    targets = sampling.target_body_pos(np, rng.uniform(size=(n, 3)), task)
    shape = (n, -(-steps // config.hold_steps), joints)
    levels = config.amplitude * rng.uniform(-1.0, 1.0, shape)
    actions = np.repeat(levels, config.hold_steps, axis=1)[:, :steps]
    return Inputs(qpos0, targets, per_physics_step(actions, task.n_substeps), np.ones(n))


def jitter_inputs(task: TaskConfig, config: ParityConfig, steps: int) -> Inputs:
    """From the home pose: zero action and the constant command, each with the damping as
    converted and zeroed (:data:`FREE_SCENARIOS` x :data:`DAMPING`, in that order)."""
    home = np.asarray(task.home_qpos)
    constant = np.resize(np.asarray(config.jitter_command), len(home))
    commands = {"hold": np.zeros(len(home)), "constant": constant}
    runs = list(itertools.product(FREE_SCENARIOS, DAMPING))
    actions = np.array([np.tile(commands[s], (steps * task.n_substeps, 1)) for s, _ in runs])
    n = len(runs)
    target = sampling.target_body_pos(np, np.full(3, 0.5), task)
    return Inputs(
        np.tile(home, (n, 1)),
        np.tile(target, (n, 1)),
        actions,
        np.array([DAMPING[d] for _, d in runs]),
    )


def press_inputs(engine: MujocoEngine, boxes: np.ndarray, steps: int, depth: float) -> Inputs:
    """Press commands recorded in C MuJoCo: drive the ee ``depth`` below each box's top centre.

    The controller: ee velocity ``PRESS_GAIN * error`` through the Jacobian's least squares,
    scaled to actions and clipped; one action per control step, ``steps`` steps, from the home
    pose.

    Returns:
        Inputs with one action per physics step, ``(len(boxes), steps * substeps, 6)``.
    """
    env, task = engine.env, engine.env.task
    qpos0 = np.tile(np.asarray(task.home_qpos), (len(boxes), 1))
    recorded = []
    for q, box in zip(qpos0, boxes, strict=True):
        env._physics_reset(q, box)
        target = sampling.target_point(np, box, task) + np.array([0.0, 0.0, -depth])
        actions = []
        for _ in range(steps):
            reading = env._physics_read()
            v = np.linalg.lstsq(
                engine.jacobian(reading.qpos), PRESS_GAIN * (target - reading.ee_pos), rcond=None
            )[0]
            actions.append(np.clip(v / engine.scale, -1.0, 1.0))
            env._physics_set_velocity_targets(actions[-1] * engine.scale)
            env._physics_step(task.n_substeps)
        recorded.append(actions)
    actions = per_physics_step(np.asarray(recorded), task.n_substeps)
    return Inputs(qpos0, np.asarray(boxes, np.float64), actions, np.ones(len(boxes)))


# --------------------------------------------------------------------------- run


@dataclass
class EngineResult:
    """One engine's raw results.

    Attributes:
        ee: ee points at the FK poses (m), ``(P, 3)``.
        reach: the Reach-scene runs (open loop, then free-space jitter), every physics step.
        press: the press runs (damping as converted, then zeroed), every physics step.
        seconds: wall time per phase (``build``, ``fk``, ``reach``, ``press``), and for MJX the
            compilation inside them (``compile``).
    """

    ee: np.ndarray
    reach: Trace
    press: Trace
    seconds: dict[str, float]


@dataclass
class ParityInputs:
    """Everything the engines play: FK poses ``(P, n)``, the Reach batch (open loop, then
    free-space jitter) and the press batch (damping as converted, then zeroed), with the two
    tasks and the arm."""

    reach_task: TaskConfig
    touch_task: TaskConfig
    fk_qpos: np.ndarray
    reach: Inputs
    press: Inputs
    arm: ArmInfo


def engine_specs(config: ParityConfig) -> list[tuple[str, str]]:
    """``(engine, MJX implementation)`` of every engine run, in the configured order; ``auto``
    is resolved, so an implementation runs once."""
    out = []
    for name in config.engines:
        impls = ["auto"]
        if engine_row(name).impl_choice:
            impls = list(dict.fromkeys(resolve_impl(i) for i in config.impls))
        out += [(name, impl) for impl in impls]
    return out


def parity_inputs(config: ParityConfig, arm: ArmInfo) -> ParityInputs:
    """Draw the poses and actions and record the press commands.

    The presses use the seed Touch variant's joint speed (action scale 0.5, as Reach): the
    engines are compared at the speeds the URDF allows, and the tool is on the box well before
    the averaging and jitter windows. The gentle variant's slower joints change neither the
    controller's steady force nor the contact model.
    """
    reach = task_for_arm(reach_config(terminate_on_success=False), arm)
    touch = task_for_arm(touch_config("seed", terminate_on_success=False), arm)
    steps = round(config.seconds / reach.ctrl_dt)
    reach_inputs = Inputs.concat(
        [open_loop_inputs(reach, config, steps), jitter_inputs(reach, config, steps)]
    )
    recorder = make_engine(REFERENCE_ENGINE, touch, arm=arm)
    try:
        # the boxes move out with the arm's reach, as the tasks' targets do
        boxes = np.asarray(BOX_POSITIONS[: config.press_boxes]) * touch.workspace_scale
        press_steps = round(config.press_seconds / touch.ctrl_dt)
        press = press_inputs(recorder, boxes, press_steps, config.press_depth)
    finally:
        recorder.close()
    fk_qpos = random_joint_angles(arm, config.fk_poses, config.seed)
    zeroed = dataclasses.replace(press, damping=np.full(len(press), DAMPING["zeroed"]))
    return ParityInputs(reach, touch, fk_qpos, reach_inputs, Inputs.concat([press, zeroed]), arm)


def jitter_runs(result: EngineResult, n_open: int, n_boxes: int) -> dict[str, dict[str, Trace]]:
    """An engine's jitter runs: scenario -> damping -> trace (see :func:`parity_inputs`)."""
    free = itertools.product(FREE_SCENARIOS, DAMPING)
    out: dict[str, dict[str, Trace]] = {s: {} for s in JITTER_SCENARIOS}
    for i, (scenario, damping) in enumerate(free):
        out[scenario][damping] = result.reach.runs(slice(n_open + i, n_open + i + 1))
    for i, damping in enumerate(DAMPING):
        out["press"][damping] = result.press.runs(slice(i * n_boxes, (i + 1) * n_boxes))
    return out


def run_engine(name: str, impl: str, inputs: ParityInputs) -> tuple[str, EngineResult]:
    """Play all inputs in one engine; returns its label (e.g. ``mjx-jax``) and results."""
    seconds: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(phase: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds[phase] = seconds.get(phase, 0.0) + now - clock
        clock = now

    batch = max(len(inputs.reach), len(inputs.fk_qpos))
    engine: Engine = make_engine(name, inputs.reach_task, impl, batch, inputs.arm)
    lap("build")
    ee = engine.fk(inputs.fk_qpos)
    lap("fk")
    reach = engine.rollout(inputs.reach)
    lap("reach")
    compile_s = getattr(engine, "compile_seconds", 0.0)
    label = engine.name
    engine.close()
    engine = make_engine(name, inputs.touch_task, impl, len(inputs.press), inputs.arm)
    lap("build")
    press = engine.rollout(inputs.press)
    lap("press")
    seconds["compile"] = compile_s + getattr(engine, "compile_seconds", 0.0)
    engine.close()
    return label, EngineResult(ee, reach, press, seconds)


def parity_figures(
    results: dict[str, EngineResult], inputs: ParityInputs, config: ParityConfig
) -> dict[str, Any]:
    """The four checks' figures from the engines' raw results."""
    reach, touch = inputs.reach_task, inputs.touch_task
    n_open, boxes = config.sequences, slice(0, config.press_boxes)
    open_loop = {k: r.reach.runs(slice(0, n_open)) for k, r in results.items()}
    press = {k: r.press.runs(boxes).every(touch.n_substeps) for k, r in results.items()}
    jitter = {
        k: {
            scenario: {
                damping: jitter_figures(t, reach.sim_dt, config.jitter_window, reach.n_substeps)
                for damping, t in runs.items()
            }
            for scenario, runs in jitter_runs(r, n_open, config.press_boxes).items()
        }
        for k, r in results.items()
    }
    return {
        "fk_m": fk_figures({k: r.ee for k, r in results.items()}),
        "open_loop": open_loop_figures(
            {k: t.every(reach.n_substeps) for k, t in open_loop.items()},
            reach.ctrl_dt,
            config.goal_time,
        ),
        "press": press_figures(press, touch.ctrl_dt, config.press_average_steps),
        "jitter": jitter,
    }


def run_parity(config: ParityConfig, log=print) -> dict[str, Any]:
    """Run every check in every configured engine.

    Args:
        config: the settings.
        log: progress lines go here (``print``, or ``lambda _: None`` for silence).

    Returns:
        JSON-ready (after numpy conversion): ``config``, ``engines`` (labels), ``seconds``
        (per engine and phase), ``figures`` (see :func:`parity_figures`) and ``goals``
        (see :func:`check_goals`).
    """
    inputs = parity_inputs(config, arm_info(config.arm or None))
    results = {}
    for name, impl in engine_specs(config):
        log(f"parity: running {name} ({len(inputs.reach)} Reach runs, {len(inputs.press)} presses)")
        label, result = run_engine(name, impl, inputs)
        results[label] = result
        wall = sum(v for k, v in result.seconds.items() if k != "compile")
        log(f"parity: {label} done in {wall:.1f} s (compilation {result.seconds['compile']:.1f} s)")
    figures = parity_figures(results, inputs, config)
    return {
        "config": config.to_dict(),
        "engines": list(results),
        "seconds": {k: r.seconds for k, r in results.items()},
        "figures": figures,
        "goals": check_goals(figures, config, inputs.touch_task.force_band),
    }
