"""Engine parity: C MuJoCo, MJX (JAX or Warp) and PyBullet on the same states and actions.

Four checks, every engine pair compared (:func:`run_parity`):

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

from mjx_arm.bench.engines import Engine, Inputs, MujocoEngine, Trace, make_engine
from mjx_arm.bench.parity_config import (
    BOX_POSITIONS,
    CONTACT_N,
    DAMPING,
    FREE_SCENARIOS,
    JITTER_SCENARIOS,
    PRESS_GAIN,
    REFERENCE,
    ParityConfig,
)
from mjx_arm.engines import engine as engine_row
from mjx_arm.engines import engine_names
from mjx_arm.envs.arm import ArmInfo, arm_info
from mjx_arm.envs.base import task_for_arm
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


# --------------------------------------------------------------------------- figures


def pairs(names: list[str]) -> list[tuple[str, str]]:
    """Every pair of engines, in the order given."""
    return list(itertools.combinations(names, 2))


def pair_key(a: str, b: str) -> str:
    """The JSON key of a pair."""
    return f"{a} vs {b}"


def joint_divergence(a: Trace, b: Trace) -> np.ndarray:
    """Largest joint-angle difference (rad, wrapped to +-pi) per run and step, ``(B, T)``."""
    diff = np.angle(np.exp(1j * (a.qpos - b.qpos)))
    return np.abs(diff).max(axis=-1)


def curve_stats(values: np.ndarray, index: int) -> dict[str, Any]:
    """Median and 95th percentile over runs of ``values (B, T)``, whole curve and at ``index``."""
    median, p95 = np.median(values, axis=0), np.percentile(values, 95, axis=0)
    return {
        "median": median,
        "p95": p95,
        "at_goal_median": float(median[index]),
        "at_goal_p95": float(p95[index]),
        "final_median": float(median[-1]),
        "final_p95": float(p95[-1]),
        "max": float(values.max()),
    }


def fk_figures(ee: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest ee point distance (m) of each engine pair over the poses."""
    return {
        pair_key(a, b): float(np.linalg.norm(ee[a] - ee[b], axis=-1).max())
        for a, b in pairs(list(ee))
    }


def open_loop_figures(traces: dict[str, Trace], ctrl_dt: float, goal_time: float) -> dict:
    """Divergence curves of every pair, from control-step traces ``(B, T, ...)``."""
    steps = next(iter(traces.values())).qpos.shape[1]
    index = round(goal_time / ctrl_dt) - 1  # the read after the control step ending at goal_time
    touched = np.any([t.force().max(axis=1) > CONTACT_N for t in traces.values()], axis=0)
    out: dict[str, Any] = {
        "time_s": ctrl_dt * np.arange(1, steps + 1),
        "sequences": len(touched),
        "sequences_with_contact": int(touched.sum()),
        "free_motion_force_max_n": {
            name: float(t.force()[~touched].max(initial=0.0)) for name, t in traces.items()
        },
        "pairs": {},
    }
    for a, b in pairs(list(traces)):
        div = joint_divergence(traces[a], traces[b])
        stats = curve_stats(div, index)
        stats["at_goal_median_free_motion"] = float(np.median(div[~touched, index]))
        out["pairs"][pair_key(a, b)] = stats
    return out


def press_figures(traces: dict[str, Trace], ctrl_dt: float, average: int) -> dict:
    """The tared force over time per engine, its steady value and the gap to the reference."""
    force = {name: t.force() for name, t in traces.items()}
    steady = {name: f[:, -average:].mean(axis=1) for name, f in force.items()}
    reference = REFERENCE if REFERENCE in force else next(iter(force))
    steps = next(iter(force.values())).shape[1]
    out: dict[str, Any] = {"time_s": ctrl_dt * np.arange(1, steps + 1), "reference": reference}
    out["engines"] = {}
    for name, f in force.items():
        contact = f > CONTACT_N
        first = np.where(contact.any(axis=1), contact.argmax(axis=1) + 1, 0) * ctrl_dt
        rel = np.abs(steady[name] - steady[reference]) / steady[reference]
        out["engines"][name] = {
            "force_n": f,
            "force_median_n": np.median(f, axis=0),
            "steady_n": steady[name],
            "first_contact_s": first,
            "rel_to_reference": rel,
            "rel_to_reference_max": float(rel.max()),
        }
    return out


def jitter_figures(trace: Trace, sim_dt: float, window: float, smooth: int) -> dict[str, Any]:
    """Spread of the joint acceleration and the velocity's high-frequency content.

    Args:
        trace: runs read at every physics step, ``(R, T, ...)``.
        sim_dt: physics step (s).
        window: the end of each run used (s).
        smooth: physics steps per control step: the velocity minus its moving average over
            this many steps is the content above the control rate.

    Returns:
        ``acc_std`` (rad/s^2) and ``hf_vel_rms`` (rad/s), per run and joint ``(R, 6)``, and
        their ``_max``: the largest joint's, median over the runs.
    """
    qvel = trace.qvel[:, -round(window / sim_dt) :]
    acc_std = (np.diff(qvel, axis=1) / sim_dt).std(axis=1)
    kernel = np.ones(smooth) / smooth
    average = np.apply_along_axis(np.convolve, 1, qvel, kernel, mode="same")
    hf = np.sqrt(np.mean((qvel - average)[:, smooth:-smooth] ** 2, axis=1))
    return {
        "acc_std": acc_std,
        "acc_std_max": float(np.median(acc_std.max(axis=1))),
        "hf_vel_rms": hf,
        "hf_vel_rms_max": float(np.median(hf.max(axis=1))),
    }


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
        impls = dict.fromkeys(resolve_impl(i) for i in config.impls) if name == "mjx" else ["auto"]
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
    recorder = make_engine("mujoco", touch, arm=arm)
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


# --------------------------------------------------------------------------- goals


def divergence_goal(pair: tuple[str, str], config: ParityConfig) -> float:
    """The median divergence goal (rad) of a pair: that of the first engine in it whose registry
    row names one (``parity_goal``: PyBullet's), else MJX's."""
    for name in pair:
        if name in engine_names("parity_goal"):
            return getattr(config, engine_row(name).parity_goal)
    return config.goal_mjx_rad


def check_goals(
    figures: dict[str, Any], config: ParityConfig, band: tuple[float, float]
) -> list[dict[str, Any]]:
    """Each goal with its figure and whether it is met.

    Returns:
        Rows of ``check``, ``subject`` (pair or engine), ``value``, ``goal`` (text), ``met``
        and ``cause`` (why it is missed, from :data:`CAUSES`; None when met).
    """
    rows = [
        _goal("forward kinematics, max", key, value, value <= config.goal_fk_m, config.goal_fk_m)
        for key, value in figures["fk_m"].items()
    ]
    check = f"joint divergence at {config.goal_time:g} s, median"
    for key, stats in figures["open_loop"]["pairs"].items():
        limit = divergence_goal(tuple(key.split(" vs ")), config)
        value = stats["at_goal_median"]
        rows.append(_goal(check, key, value, value <= limit, limit))
    low, high = band
    for name, press in figures["press"]["engines"].items():
        steady = press["steady_n"]
        met = bool(np.all((steady >= low) & (steady <= high)))
        value = [float(steady.min()), float(steady.max())]
        rows.append(_goal("steady press force in the Touch band", name, value, met, band))
    return rows


def _goal(check: str, subject: str, value: Any, met: bool, goal: Any) -> dict[str, Any]:
    met = bool(met)
    return {
        "check": check,
        "subject": subject,
        "value": value,
        "goal": goal,
        "met": met,
        "cause": None if met else cause_of(check, subject),
    }


# Where a goal is missed: the difference between the engines that drives that figure, keyed by
# check prefix and a word of the subject (the first match counts).
CAUSES = {
    ("forward kinematics", "mjx"): (
        "MJX computes in float32: about 1e-7 relative rounding per transform, summed along the "
        "chain of bodies"
    ),
    ("joint divergence", "pybullet"): (
        "different integrators and contact solvers: PyBullet's drive takes MuJoCo's implicit "
        "servo step but sees the contacts' torque one substep late, and Bullet's Featherstone "
        "integrator and contact solver are not MuJoCo's"
    ),
    ("joint divergence", "mjx"): (
        "float32 against float64 (and, in sequences that touch the table, MJX's own collision "
        "routines and fixed solver iterations): differences grow along the trajectory"
    ),
    ("steady press force", ""): (
        "the press commands were recorded in C MuJoCo; this engine resolves the contact "
        "(solver, friction) differently"
    ),
}


def cause_of(check: str, subject: str) -> str:
    """The stated cause of a missed goal (:data:`CAUSES`), or a pointer to the figures."""
    for (prefix, word), cause in CAUSES.items():
        if check.startswith(prefix) and word in subject:
            return cause
    return "no cause established: see the figures in the JSON"
