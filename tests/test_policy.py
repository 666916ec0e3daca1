"""Policy export and the numpy / ONNX runtimes (:mod:`mjx_arm.policy`).

A small Reach policy is trained once per session (about 30-40 s on a CPU, C MuJoCo backend) by
:func:`trained_run_dir`; ``test_evaluate`` and ``test_replay`` reuse it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mjx_arm.cli import EXIT_INVALID, EXIT_OK, main
from mjx_arm.policy import (
    CONTRACT_VERSION,
    ContractVersionError,
    NumpyPolicy,
    PolicyFileError,
    export_policy,
    load,
)
from mjx_arm.policy.numpy_policy import read_npz, write_npz

_RUN: dict[str, Path] = {}
# 3 PPO epochs of 40,960 steps: about 0.9 eval success on Reach.
TRAIN_OVERRIDES = ["task=reach", "backend=mujoco", "num_timesteps=122880", "num_evals=4"]
JAX_MODULES = ("jax", "jaxlib", "brax", "flax", "orbax", "optax")


def trained_run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run directory with a small trained Reach policy, trained once per test session."""
    if "run" not in _RUN:
        from mjx_arm.train.ppo import train
        from mjx_arm.train.presets import load_config

        run_dir = tmp_path_factory.mktemp("policy_run") / "run"
        train(load_config("cpu", overrides=TRAIN_OVERRIDES), run_dir, quiet=True)
        _RUN["run"] = run_dir
    return _RUN["run"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return trained_run_dir(tmp_path_factory)


@pytest.fixture(scope="module")
def exported(run_dir: Path, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("exported")
    paths = {"npz": export_policy(run_dir, folder / "policy.npz")}
    if _have_onnx():
        paths["onnx"] = export_policy(run_dir, folder / "policy.onnx")
    return paths


def _have_onnx() -> bool:
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


needs_onnx = pytest.mark.skipif(not _have_onnx(), reason="needs onnx and onnxruntime")


def _probe_obs(policy: NumpyPolicy, n: int = 512) -> np.ndarray:
    """Observations ``(2n, 22)``: near the training data and far outside it."""
    rng = np.random.default_rng(1)
    near = policy.mean + policy.std * rng.standard_normal((n, 22))
    wide = rng.uniform(-3.0, 3.0, (n, 22))
    return np.concatenate([near, wide]).astype(np.float32)


# --------------------------------------------------------------------------- export


@pytest.mark.filterwarnings("ignore:Sharding info not provided")
def test_export_npz_round_trip(run_dir: Path, exported: dict[str, Path]):
    from mjx_arm.policy.export import available_steps, policy_arrays
    from mjx_arm.train.rundir import RunDir

    arrays, meta = read_npz(exported["npz"])
    assert meta["contract_version"] == CONTRACT_VERSION
    assert meta["step"] == available_steps(run_dir)[-1]  # the newest checkpoint by default
    assert meta["task"] == "reach"
    assert meta["config"]["train"]["policy_hidden"] == [128, 128, 128]
    assert meta["obs_layout"][0] == ["ee_pose", 7] and len(meta["v_max"]) == 6
    params = RunDir.load_params(RunDir(run_dir).latest_checkpoint())
    for key, value in policy_arrays(params).items():
        np.testing.assert_array_equal(arrays[key], value)
    assert [arrays[f"kernel_{i}"].shape for i in range(4)] == [
        (22, 128),
        (128, 128),
        (128, 128),
        (128, 12),
    ]


def test_export_step_picks_a_checkpoint(run_dir: Path, tmp_path: Path):
    from mjx_arm.policy.export import available_steps

    first = available_steps(run_dir)[0]
    path = export_policy(run_dir, tmp_path / "old.npz", step=first)
    assert load(path).metadata["step"] == first
    with pytest.raises(FileNotFoundError, match="steps available"):
        export_policy(run_dir, tmp_path / "none.npz", step=first + 1)
    with pytest.raises(ValueError, match=r"\.npz"):
        export_policy(run_dir, tmp_path / "policy.pt")


def test_cli_export_writes_both_formats(run_dir: Path, tmp_path: Path, capsys):
    outputs = [tmp_path / "p.npz"] + ([tmp_path / "p.onnx"] if _have_onnx() else [])
    argv = ["export", str(run_dir)] + [a for o in outputs for a in ("-o", str(o))]
    assert main(argv) == EXIT_OK
    assert all(o.is_file() for o in outputs)
    assert main(["export", str(tmp_path), "-o", str(tmp_path / "x.npz")]) == EXIT_INVALID
    assert "not a run directory" in capsys.readouterr().err


# --------------------------------------------------------------------------- agreement


def test_jax_npz_and_onnx_agree(run_dir: Path, exported: dict[str, Path]):
    from mjx_arm.policy.export import brax_policy

    npz = load(exported["npz"])
    obs = _probe_obs(npz)
    reference = brax_policy(run_dir)(obs)
    # three float32 runtimes (XLA, numpy/BLAS, onnxruntime) sum each layer in their own order;
    # measured up to 4.3e-6 on the wide probes (7e-7 on the near ones): 5e-5 leaves 10x margin
    np.testing.assert_allclose(npz(obs), reference, atol=5e-5, rtol=0)
    if "onnx" in exported:
        np.testing.assert_allclose(load(exported["onnx"])(obs), reference, atol=5e-5, rtol=0)


def test_policy_reproduces_the_recorded_transitions(run_dir: Path, exported: dict[str, Path]):
    from mjx_arm.train.rundir import RunDir

    data = np.load(RunDir(run_dir).latest_checkpoint() / "transitions.npz")
    np.testing.assert_allclose(load(exported["npz"])(data["obs"]), data["action"], atol=1e-5)


@pytest.mark.parametrize("kind", ["npz", pytest.param("onnx", marks=needs_onnx)])
def test_inputs_shapes_and_range(exported: dict[str, Path], kind: str):
    from mjx_arm.task.observation import unflatten_obs

    policy = load(exported[kind])
    obs = _probe_obs(load(exported["npz"]), 8) * 100.0  # far outside: still inside [-1, 1]
    batch = policy(obs)
    assert batch.shape == (16, 6) and batch.dtype == np.float32
    assert np.all(np.abs(batch) <= 1.0)
    single = policy(obs[3])
    assert single.shape == (6,)
    # one observation and a batch take different float32 code paths (matrix-vector against
    # matrix-matrix); unsaturated actions differ by up to 8.4e-6 measured: 1e-4 bounds it
    np.testing.assert_allclose(single, batch[3], atol=1e-4)
    np.testing.assert_allclose(policy(unflatten_obs(obs)), batch, atol=1e-4)
    np.testing.assert_allclose(policy(unflatten_obs(obs[3])), single, atol=1e-4)
    with pytest.raises(ValueError, match="shape"):
        policy(np.zeros(21))


def test_action_scaling_is_the_contracts(exported: dict[str, Path]):
    from mjx_arm.arm.info import arm_info

    policy = load(exported["npz"])
    expected = np.array([1, -1, 0.5, 0, 1, 1]) * 0.5 * arm_info().v_max  # reach: scale 0.5
    np.testing.assert_allclose(policy.joint_velocity_targets([1, -1, 0.5, 0, 1, 1]), expected)


def test_stochastic_actions_are_seeded(exported: dict[str, Path]):
    obs = np.zeros((4, 22), np.float32)
    a = load(exported["npz"], deterministic=False, seed=3)(obs)
    b = load(exported["npz"], deterministic=False, seed=3)(obs)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(a) <= 1.0)
    assert not np.allclose(a, load(exported["npz"])(obs))


# --------------------------------------------------------------------------- no jax


@pytest.mark.parametrize("kind", ["npz", pytest.param("onnx", marks=needs_onnx)])
def test_loading_and_running_imports_no_jax(exported: dict[str, Path], kind: str):
    code = f"""
        import sys
        import numpy as np
        from mjx_arm.policy import load
        policy = load({str(exported[kind])!r})
        action = policy(np.zeros(22, np.float32))
        assert action.shape == (6,), action.shape
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in {JAX_MODULES!r})
        print("loaded:", loaded)
        assert not loaded, loaded
    """
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_numpy_runtime_is_one_standalone_file(exported: dict[str, Path]):
    """numpy_policy.py runs copied on its own: numpy only, no mjx_arm package."""
    source = Path(__file__).resolve().parents[1] / "mjx_arm" / "policy" / "numpy_policy.py"
    code = f"""
        import importlib.util, sys
        import numpy as np
        spec = importlib.util.spec_from_file_location("numpy_policy", {str(source)!r})
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        policy = module.NumpyPolicy.load({str(exported["npz"])!r})
        print(policy(np.zeros(22)))
        assert not any(m.split(".")[0] in ("mjx_arm", "jax", "gymnasium") for m in sys.modules)
    """
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr


# --------------------------------------------------------------------------- bad files


def test_another_contract_version_is_refused(exported: dict[str, Path], tmp_path: Path):
    arrays, meta = read_npz(exported["npz"])
    old = write_npz(tmp_path / "old.npz", arrays, {**meta, "contract_version": "0"})
    with pytest.raises(ContractVersionError, match=r"contract version '0'.*mjx-arm export"):
        load(old)


@needs_onnx
def test_onnx_with_another_contract_version_is_refused(exported: dict[str, Path], tmp_path):
    import onnx

    model = onnx.load(str(exported["onnx"]))
    for prop in model.metadata_props:
        meta = json.loads(prop.value)
        prop.value = json.dumps({**meta, "contract_version": "99"})
    onnx.save(model, str(tmp_path / "old.onnx"))
    with pytest.raises(ContractVersionError, match="'99'"):
        load(tmp_path / "old.onnx")


def test_other_files_are_not_policies(tmp_path: Path):
    np.savez(tmp_path / "weights.npz", w=np.zeros(3))
    with pytest.raises(PolicyFileError, match="not an mjx_arm policy"):
        load(tmp_path / "weights.npz")
    (tmp_path / "policy.pt").write_bytes(b"x")
    with pytest.raises(PolicyFileError, match=r"\.npz or \.onnx"):
        load(tmp_path / "policy.pt")
    with pytest.raises(FileNotFoundError):
        load(tmp_path / "missing.npz")


SHIPPED_TOUCH = Path(__file__).parent.parent / "benchmarks/results/policies/touch_fast_seed0.npz"


def test_an_observation_the_policy_never_trained_on_is_refused_by_name():
    """The first observations of 50 CPU MuJoCo episodes of a shipped Touch policy's own task
    lie within 10 training stds (measured: at most 4.1 over 200), while a target 1 mm above the
    box top, a height training held at 0.05 m, is 1,000 stds out and refused, named."""
    from mjx_arm.evaluate import eval_task, make_eval_env
    from mjx_arm.policy.familiar import (
        UnfamiliarObservationError,
        check_familiar,
        unfamiliar_inputs,
    )

    policy = load(SHIPPED_TOUCH)
    env = make_eval_env(eval_task(policy)[0], "mujoco")
    for seed in range(50):
        obs, _ = env.reset(seed=seed)
        check_familiar(policy, obs)
    env.close()
    obs["target_rel"] = obs["target_rel"] + np.array([0.0, 0.0, 0.001], np.float32)
    (entry,) = unfamiliar_inputs(policy, obs)
    assert entry.name == "target_rel[2]" and entry.distance == pytest.approx(1000, rel=0.01)
    with pytest.raises(UnfamiliarObservationError, match=r"target_rel\[2\] = 0.051 is 1,0\d\d "):
        check_familiar(policy, obs)
    assert unfamiliar_inputs(object(), obs) == []  # no normaliser arrays (ONNX): not checked
