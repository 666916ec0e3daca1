"""The robustness benchmark: each perturbation changes what it says (model, action timing,
observation), the sweep's structure, Wilson intervals against known figures, and the command on
bad input. Run on the C MuJoCo batch (compiles in seconds on a CPU); the MJX model's changes are
checked without stepping it.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_arm.bench.robustness import point_result, summarize
from mjx_arm.bench.robustness_config import (
    JOINT,
    PERTURBATIONS,
    Perturbation,
    joint_config,
    perturbations_for,
    sweep_points,
)
from mjx_arm.cli import EXIT_INVALID, main
from mjx_arm.envs.mjx_env import MjxArmEnv
from mjx_arm.envs.mjx_physics import Dynamics
from mjx_arm.envs.mujoco_batch import MujocoCallbackPhysics
from mjx_arm.envs.physics_config import NOMINAL, ROBUST, RandomizationConfig
from mjx_arm.envs.randomization import delayed_action, push_action, sample_episode
from mjx_arm.evaluate.stats import wilson_interval
from mjx_arm.inputs import ConfigError
from mjx_arm.task import touch_config
from mjx_arm.task.observation import obs_slices

SLICES = obs_slices()
BY_NAME = {p.name: p for p in PERTURBATIONS}


def _env(randomization: RandomizationConfig = NOMINAL, **task) -> MjxArmEnv:
    return MjxArmEnv(
        touch_config(**task), physics_factory=MujocoCallbackPhysics, randomization=randomization
    )


@pytest.fixture(scope="module")
def env() -> MjxArmEnv:
    env = _env()
    env.jit_start, env.jit_step = jax.jit(env.start), jax.jit(env.step)
    return env


def _start(env: MjxArmEnv, cfg: RandomizationConfig, key: int = 3):
    episode = sample_episode(jax.random.PRNGKey(key), cfg, env.arm.n_joints)
    return env.jit_start(jax.random.PRNGKey(7), episode)


# --------------------------------------------------------------------------- statistics


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [(5, 10, 0.2366, 0.7634), (0, 10, 0.0, 0.2775), (10, 10, 0.7225, 1.0), (0, 0, 0.0, 1.0)],
)
def test_wilson_interval_known_figures(k, n, low, high):
    """Wilson 95 % bounds: 5/10 -> [0.2366, 0.7634]; 0/10 -> upper z^2/(n+z^2) = 0.2775."""
    got = wilson_interval(k, n)
    np.testing.assert_allclose(got, (low, high), atol=1e-4)


def test_point_result_and_summary():
    """A point's numbers, and the summary names where success falls below the goal."""
    p = BY_NAME["latency"]
    points = [pt for pt in sweep_points((p,)) if pt.perturbation == "latency"]
    rows = []
    for pt in points:
        ok = np.arange(10) < (10 if pt.value < 2 else 5)
        rows.append(point_result(pt, ok, np.full(10, 20.0)))
    rows.append(point_result(sweep_points((p,))[-1], np.ones(20, bool), np.full(20, 30.0)))
    assert rows[0]["success_ci95"] == pytest.approx(list(wilson_interval(10, 10)))
    assert rows[0]["median_peak_force"] == 20.0
    summary = summarize(rows, (p,))
    assert summary["per_perturbation"]["latency"]["below_goal_at"] == [2.0, 3.0]
    assert not summary["all_points_goal_met"] and summary["joint_goal_met"]
    assert summary["nominal_pooled"]["episodes"] == 10  # latency 0 is the nominal point


# --------------------------------------------------------------------------- sweep structure


def test_sweep_covers_each_stated_range_from_nominal():
    """Every perturbation sweeps its nominal value, both ends of its stated range and 3+
    points; Touch skips the cube; the joint draw is last and draws each stated range."""
    for p in PERTURBATIONS:
        changed = {
            k for k, v in p.config(p.values[-1]).to_dict().items() if v != getattr(NOMINAL, k)
        }
        assert changed <= {p.field, "latency_prob"}, p.name  # a point changes only its field
        assert len(p.values) >= 4 and p.stated[0] in p.values and p.stated[1] in p.values
        nominal = getattr(NOMINAL, p.field)[0] if p.kind == "range" else 0.0
        assert nominal in p.values and p.inside(nominal), p.name
    touch = perturbations_for(gripper=False)
    assert "cube_mass" not in {p.name for p in touch}
    points = sweep_points(touch)
    assert points[-1].perturbation == JOINT and points[-1].value is None
    joint = joint_config(touch)
    assert joint.gain == BY_NAME["servo_gain"].stated and joint.latency_steps == (0, 3)
    assert joint.payload == (0.0, 5.0) and joint.ft_force_noise == 3.5
    assert joint_config(PERTURBATIONS) == ROBUST  # the training draw is the benchmark's


def test_point_config_fixes_its_value():
    """A sweep point's draw is exactly its value in every env."""
    cfg = BY_NAME["payload"].config(2.5)
    for key in jax.random.split(jax.random.PRNGKey(0), 2):
        draw = sample_episode(key, cfg)
        assert float(draw.dynamics.payload) == pytest.approx(2.5)
        np.testing.assert_allclose(np.asarray(draw.dynamics.gain), 1.0)
        assert float(sample_episode(key, BY_NAME["latency"].config(2)).latency) == 2.0


def test_config_rejects_bad_ranges():
    for bad in (
        {"latency_steps": (0, 4)},
        {"payload": (2.0, 1.0)},
        {"ctrl_jitter": 0.9},
        {"joint_noise": -1.0},
    ):
        with pytest.raises(ConfigError):
            NOMINAL.replace(**bad)
    with pytest.raises(ConfigError):
        Perturbation("x", "payload", "range", "kg", (0, 1), (0, 1), "").config(-1.0)


# --------------------------------------------------------------------------- the model


def _row(**changes) -> Dynamics:
    return Dynamics.nominal().replace(**{k: jnp.asarray(v) for k, v in changes.items()})


def test_c_batch_applies_payload_friction_table_and_timestep(env):
    """One row per change; the row's model carries exactly that change, the others none.
    5 kg at the flange pulls the arm down under the same zero command (the gravity
    compensation does not hold it); the F/T tare holds (the payload is upstream of the
    sensor)."""
    physics = env.physics
    ids, base = physics.ids, physics.mj_model
    rows = [
        _row(),
        _row(payload=5.0),
        _row(frictionloss=jnp.full(6, 0.1)),
        _row(table=-0.02),
        _row(timestep=1.1),
    ]
    dyn = jax.tree.map(lambda *x: jnp.stack(x), *rows)
    state = env.jit_start(jax.random.PRNGKey(1), sample_episode(jax.random.PRNGKey(0), NOMINAL))
    data = jax.tree.map(lambda x: jnp.stack([x] * 5), state.pipeline_state)
    step = jax.jit(jax.vmap(physics.step))
    for _ in range(5):
        data = step(data, jnp.zeros((5, 6)), dyn)
    models = physics.stepper.copies.models
    flange, table, dofs = ids.flange_body, ids.table_geoms, ids.dof_adr
    assert models[1].body_mass[flange] == pytest.approx(base.body_mass[flange] + 5.0)
    np.testing.assert_allclose(models[2].dof_frictionloss[dofs], 0.1)
    np.testing.assert_allclose(models[3].geom_pos[table, 2], base.geom_pos[table, 2] - 0.02)
    assert models[4].opt.timestep == pytest.approx(base.opt.timestep * 1.1, rel=1e-6)
    m0 = models[0]
    assert m0.body_mass[flange] == base.body_mass[flange] and m0.opt.timestep == base.opt.timestep
    assert not m0.dof_frictionloss.any()
    reading = jax.vmap(physics.read)(data)
    ee_z = np.asarray(reading.ee_pos)[:, 2]
    assert ee_z[1] < ee_z[0] - 1e-3  # sags by millimetres in 1/6 s
    np.testing.assert_allclose(ee_z[2:4], ee_z[0], atol=1e-3)  # friction, table: no sag
    assert np.abs(np.asarray(reading.wrench)[:2, :3]).max() < 1.0


def test_mjx_model_gets_the_same_changes():
    """MJX's randomised model: the same fields as the C batch's (no step: compiles fast)."""
    from mjx_arm.envs.physics_config import PhysicsConfig

    env = MjxArmEnv(touch_config(), physics=PhysicsConfig(impl="jax"))
    p = env.physics
    m = p.randomized(_row(payload=2.0, table=0.01, timestep=0.9, frictionloss=jnp.full(6, 0.05)))
    ids, base = p.ids, p.mj_model
    assert float(m.body_mass[ids.flange_body]) == pytest.approx(base.body_mass[ids.flange_body] + 2)
    np.testing.assert_allclose(np.asarray(m.geom_pos)[ids.table_geoms, 2], -0.025 + 0.01)
    np.testing.assert_allclose(np.asarray(m.dof_frictionloss)[ids.dof_adr], 0.05)
    assert float(m.opt.timestep) == pytest.approx(base.opt.timestep * 0.9, rel=1e-6)


# --------------------------------------------------------------------------- actions, observations


def test_delayed_action_is_k_steps_old():
    """Under a delay of k the applied action is the one of k steps before (zeros first)."""
    past = jnp.zeros((3, 2))
    applied = {k: [] for k in range(4)}
    for t in range(6):
        action = jnp.array([t + 1.0, -(t + 1.0)])
        for k in range(4):
            applied[k].append(float(delayed_action(action, past, jnp.asarray(float(k)))[0]))
        past = push_action(action, past)
    for k in range(4):
        assert applied[k] == [max(t + 1 - k, 0) if t >= k else 0.0 for t in range(6)]


def test_latency_delays_the_arm_by_k_steps(env):
    """With latency k the arm stays put for k steps under a full-speed command, then moves."""
    moved = {}
    for k in (0, 2):
        state = _start(env, BY_NAME["latency"].config(k))
        q = [np.asarray(env.physics.read(state.pipeline_state).qpos)]
        for _ in range(3):
            state = env.jit_step(state, jnp.ones(6))
            q.append(np.asarray(env.physics.read(state.pipeline_state).qpos))
        moved[k] = np.abs(np.diff(np.stack(q), axis=0)).max(axis=1)
    full = moved[0].min()
    assert full > 1e-2
    assert moved[2][0] < 0.1 * full and moved[2][1] < 0.1 * full and moved[2][2] > 0.5 * full


def test_biases_shift_the_observation_by_their_value(env):
    """Joint bias and F/T bias move the observed joint angles and force by exactly their value;
    the pose error moves the observed target; the true state is the same."""
    nominal = _start(env, NOMINAL)
    for name, value, key in (
        ("joint_bias", 0.01, "joint_angles"),
        ("ft_bias", 4.0, "contact_force"),
        ("table_height", 0.02, "target_rel"),
    ):
        state = _start(env, BY_NAME[name].config(value))
        shift = np.asarray(state.obs[SLICES[key]]) - np.asarray(nominal.obs[SLICES[key]])
        want = {
            "joint_angles": np.full(6, value),
            "contact_force": [value] * 3 + [0.0] * 3,
            "target_rel": np.zeros(3),  # the observation keeps the nominal table
        }[key]
        np.testing.assert_allclose(shift, want, atol=1e-5, err_msg=name)
    tall = _start(env, BY_NAME["table_height"].config(0.02))
    true_z = np.asarray(env.physics.read(tall.pipeline_state).target_pos)[2]
    nominal_z = np.asarray(env.physics.read(nominal.pipeline_state).target_pos)[2]
    assert true_z - nominal_z == pytest.approx(0.02, abs=1e-5)


def test_noise_scales_show_per_step(env):
    """Joint-angle and F/T noise: per-step draws of the stated scale reach the observation."""
    from mjx_arm.envs.randomization import ft_noise, joint_noise

    cfg = NOMINAL.replace(joint_noise=0.01, ft_force_noise=2.0)
    episode = sample_episode(jax.random.PRNGKey(0), cfg)
    keys = jax.random.split(jax.random.PRNGKey(1), 200)
    q = np.stack([np.asarray(joint_noise(k, episode)) for k in keys[:50]])
    f = np.stack([np.asarray(ft_noise(k, episode)) for k in keys[50:]])
    assert 0.008 < q.std() < 0.012 and 1.7 < f[:, :3].std() < 2.3 and not f[:, 3:].any()
    noisy = env.jit_step(env.jit_start(jax.random.PRNGKey(7), episode), jnp.zeros(6))
    quiet = env.jit_step(_start(env, NOMINAL, key=0), jnp.zeros(6))
    diff = np.asarray(noisy.obs - quiet.obs)
    assert 0 < np.abs(diff[SLICES["joint_angles"]]).max() < 0.05
    assert 0 < np.abs(diff[SLICES["contact_force"]]).max() < 10.0


# --------------------------------------------------------------------------- command line


def test_cli_rejects_bad_input(tmp_path: Path, capsys):
    """A missing policy and a bad flag are named errors (exit 2), before any work."""
    argv = ["bench", "robustness", str(tmp_path / "none.npz"), "--out", str(tmp_path)]
    assert main(argv) == EXIT_INVALID
    assert "none.npz" in capsys.readouterr().err
    policy = Path(__file__).parents[1] / "benchmarks/results/policies/touch_fast_seed0.npz"
    assert main(["bench", "robustness", str(policy), "--episodes", "0"]) == EXIT_INVALID
    assert "episodes" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "robustness", str(policy), "--engine", "bullet"])


@pytest.mark.slow
def test_quick_run_writes_the_report(tmp_path: Path):
    """End to end on the C batch: one episode per point, the three files (--plot: the PNG)."""
    policy = Path(__file__).parents[1] / "benchmarks/results/policies/touch_fast_seed0.npz"
    argv = [
        "bench",
        "robustness",
        str(policy),
        "--quick",
        "--episodes",
        "1",
        "--out",
        str(tmp_path),
    ]
    assert main([*argv, "--joint-episodes", "2", "--name", "r", "--plot"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r.md", "r.png"]
    for suffix in ("md", "json", "png"):
        assert (tmp_path / f"r.{suffix}").stat().st_size > 0


def test_robust_preset_is_the_measured_training():
    """The ``robust`` preset is exactly the ``fast`` preset with the ``--set`` items that the
    GPU runs of ``benchmarks/results/robustness/{latency_gpu,selected_gpu,robust_seeds}``
    trained with (Touch with twice fast's budget, and the running std of the wrench)."""
    from mjx_arm.train.presets import load_config

    latency = [
        "randomization.enabled=true",
        "randomization.latency_prob=1",
        "randomization.latency_steps=[0,3]",
    ]
    selected = [
        *latency,
        "randomization.table_height=[-0.02,0.02]",
        "randomization.ft_force_bias=[-4,4]",
        "randomization.frictionloss=[0,0.1]",
    ]
    # Touch's robust runs trained before fast's fixed wrench scale (normalizer.force_scale) and
    # its end of press pay after a reading over the band, and before fast's evaluations from
    # 5M steps on; robust takes none of them
    budget = [
        "num_timesteps=60000000",
        "num_evals=61",
        "normalizer.force_scale=0",
        "task.pay_after_overforce=true",
        "eval_from_step=0",
    ]
    # Lift's robust runs also trained before fast's evaluations from 3M steps on, and before its
    # evaluation gate
    lift = [*selected, "eval_from_step=0", "eval_gate=0"]
    for task, sets in (("touch", [*latency, *budget]), ("lift", lift)):
        # robust runs stopped at 0.97; fast stops where its task counts as solved since
        sets = [*sets, "stop_at_success=0.97"]
        measured = load_config("fast", None, [f"task={task}", *sets])
        assert load_config("robust", None, [f"task={task}"]) == measured, task
