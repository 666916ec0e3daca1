"""The engine registry: its rows, the batch physics protocol, a toy engine added and removed
through the same path a real engine uses, and where engine names may be spelled out."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from mjx_arm import engines
from mjx_arm.cli import build_parser
from mjx_arm.envs.registration import make_env
from mjx_arm.names import engine_label, env_id

ROOT = Path(__file__).resolve().parents[1]


def test_rows_list_the_engines_in_the_orders_the_commands_show() -> None:
    assert engines.engine_names() == ("mujoco", "mjx", "pybullet")
    assert engines.engine_names("env") == ("mujoco", "pybullet")
    assert engines.eval_engines() == ("mujoco", "pybullet", "mjx")
    assert engines.engine_names("parity") == ("mujoco", "mjx", "pybullet")
    assert engines.engine_names("position_env") == ("mujoco", "pybullet")
    assert engines.engine("pybullet").requires == "pybullet"
    assert engines.engine("mujoco").requires is None
    assert engine_label("mjx", "mujoco") == "mjx (backend mujoco)"
    assert engine_label("pybullet", "mujoco") == "pybullet"


def test_every_import_path_of_every_row_loads() -> None:
    from mjx_arm.urdf.readers import UrdfReader

    fields = ("env", "position_env", "parity", "grasp", "urdf_check")
    for name in engines.engine_names():
        row = engines.engine(name)
        paths = [getattr(row, f) for f in fields if getattr(row, f)]
        for path in [*paths, *row.batch_physics.values()]:
            assert callable(engines.load(path)), path
    for name in engines.engine_names("urdf_reader"):
        assert isinstance(engines.load(engines.engine(name).urdf_reader), UrdfReader), name
    assert engines.engine_names("urdf_reader") == engines.engine_names("urdf_check")


def test_an_unknown_engine_is_a_named_input_error() -> None:
    from mjx_arm.inputs import InputError

    with pytest.raises(InputError, match="unknown engine 'nope'"):
        engines.engine("nope")
    with pytest.raises(engines.UnknownEngineError, match="choose one of"):
        engines.engine("mjx", "env")  # the batched engine has no Gymnasium env


def test_both_batch_physics_satisfy_the_protocol() -> None:
    declared = {
        name: inspect.signature(member)
        for name, member in vars(engines.BatchPhysics).items()
        if callable(member) and not name.startswith("_")
    }
    assert len(declared) == 10
    for backend, path in engines.engine("mjx").batch_physics.items():
        cls = engines.load(path)
        assert issubclass(cls, engines.BatchPhysics), backend
        for name, signature in declared.items():
            own = list(inspect.signature(getattr(cls, name)).parameters)
            assert own[: len(signature.parameters)] == list(signature.parameters), (cls, name)


class ToyArmEnv(gym.Env):
    """A toy engine: a point in 3-D that an action ``(3,)`` pushes, observed as ``(3,)``."""

    def __init__(self, task, arm=None, render_mode=None, **kwargs) -> None:
        self.task = task
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self._x = np.zeros(3, np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._x = self.np_random.uniform(-0.5, 0.5, 3).astype(np.float32)
        return self._x.copy(), {}

    def step(self, action):
        self._x = np.clip(self._x + 0.1 * np.asarray(action, np.float32), -1.0, 1.0)
        return self._x.copy(), -float(np.linalg.norm(self._x)), False, False, {}


@pytest.fixture
def toy_engine(register_engine):
    return register_engine(
        engines.EngineSpec(name="toy", label="Toy point", env=f"{__name__}:ToyArmEnv")
    )


def _eval_help(capsys) -> str:
    """What ``mjx-arm eval --help`` prints."""
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["eval", "--help"])
    assert exit_.value.code == 0
    return capsys.readouterr().out


def test_a_toy_engine_is_listed_and_made_like_a_real_one(toy_engine, capsys) -> None:
    assert engines.engine_names("env") == ("mujoco", "pybullet", "toy")
    assert engines.eval_engines() == ("mujoco", "pybullet", "toy", "mjx")
    assert "--engine {mujoco,pybullet,toy,mjx}" in _eval_help(capsys)
    assert build_parser().parse_args(["eval", "p.npz", "--engine", "toy"]).engine == "toy"
    env = gym.make(env_id("reach"), engine="toy")
    assert isinstance(env.unwrapped, ToyArmEnv)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (3,)
    limit = env.unwrapped.task.episode_steps
    for step in range(limit):
        obs, reward, terminated, truncated, _ = env.step(-obs)  # push towards the origin
        assert not terminated
        assert truncated == (step == limit - 1)  # the registered id's time limit holds
    assert abs(reward) < 1e-6  # x - 0.1 x, 150 times: 0.9**150 * 0.87 ~ 1e-7
    env.close()


def test_an_engine_without_its_package_says_how_to_install_it() -> None:
    row = engines.EngineSpec(
        name="toy", label="Toy point", env=f"{__name__}:ToyArmEnv",
        requires="mjx_arm_no_such_package", install_hint="pip install toy-physics",
    )  # fmt: skip
    engines.register_engine(row)
    try:
        with pytest.raises(engines.EngineUnavailableError, match="pip install toy-physics"):
            gym.make(env_id("reach"), engine="toy")
    finally:
        engines.unregister_engine("toy")
    engines.check_installed("pybullet")  # the reference engine's package is a dependency


def test_a_removed_engine_is_gone_everywhere(toy_engine, capsys) -> None:
    engines.unregister_engine("toy")
    assert engines.eval_engines() == ("mujoco", "pybullet", "mjx")
    assert "--engine {mujoco,pybullet,mjx}" in _eval_help(capsys)
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["eval", "p.npz", "--engine", "toy"])
    assert exit_.value.code == 2
    with pytest.raises(ValueError, match="unknown engine 'toy'"):
        make_env("reach", engine="toy")


def test_a_missed_parity_goal_takes_its_cause_from_the_rows_of_its_engines() -> None:
    from mjx_arm.bench.parity_figures import cause_of

    divergence, fk = "joint divergence at 1 s, median", "forward kinematics, max"
    mjx, bullet = (engines.engine(n).parity_causes for n in ("mjx", "pybullet"))
    assert cause_of(divergence, "mujoco vs mjx-jax") == mjx["joint divergence"]
    # A pair is explained by the engine whose own goal it is held to (PyBullet's, as the goal).
    assert cause_of(divergence, "mjx-warp vs pybullet") == bullet["joint divergence"]
    assert cause_of(fk, "mujoco vs mjx-jax") == mjx["forward kinematics"]
    assert cause_of(fk, "mujoco vs pybullet").startswith("no cause established")
    press = cause_of("steady press force in the Touch band", "pybullet")
    assert press.startswith("the press commands were recorded in C MuJoCo")
    row = engines.EngineSpec(name="toy", label="Toy", parity_causes={"joint divergence": "toy"})
    engines.register_engine(row)
    try:
        assert cause_of(divergence, "mujoco vs toy") == "toy"
    finally:
        engines.unregister_engine("toy")
    assert cause_of(divergence, "mujoco vs toy").startswith("no cause established")


# Where the reference engine's name may still be written outside the registry and its own
# package: a package name in a benchmark's version list.
ALLOWED = {"mjx_arm/bench/results.py": 1}
# Modules that read what an engine does from its row (its URDF reader, its parity causes, its
# choice of MJX implementation) or from the registry's constants (the converter's engine, the
# reference engine, the batch engines) and name no engine at all, not even the built-in ones.
NAMELESS = (
    "mjx_arm/arm/cli.py",
    "mjx_arm/arm/resolve.py",
    "mjx_arm/bench/cli.py",
    "mjx_arm/bench/parity.py",
    "mjx_arm/bench/parity_config.py",
    "mjx_arm/bench/seeds.py",
    "mjx_arm/demo.py",
    "mjx_arm/train/ppo.py",
    "mjx_arm/urdf/cli.py",
    "mjx_arm/urdf/convert.py",
    "mjx_arm/urdf/check_geometry.py",
    "mjx_arm/urdf/check_joints.py",
    "mjx_arm/urdf/check_physics.py",
    "mjx_arm/urdf/check_tree.py",
    "mjx_arm/urdf/findings.py",
    "mjx_arm/urdf/mesh_limits.py",
    "mjx_arm/urdf/readers.py",
    "mjx_arm/urdf/validate.py",
    "mjx_arm/bench/parity_figures.py",
)

# Modules that branched on an engine's name and now write one only where it is no branch: a
# default a user can type, a backend of the batched JAX env ("mjx" or "mujoco", the choices of
# --backend), an engine's choice of a command, an env naming its own engine.
TYPED = {
    "mjx_arm/evaluate/cli.py": {"mujoco": 1},  # --engine's default
    # the batched runner's default backend, and the backend whose CPU compile takes minutes
    "mjx_arm/evaluate/runners.py": {"mjx": 2},
    "mjx_arm/bench/transfer.py": {"mjx": 1, "mujoco": 1},  # the backends of two rows
    "mjx_arm/bench/robustness.py": {"mjx": 1, "mujoco": 1},  # the backends of its engines
    "mjx_arm/bench/robustness_config.py": {"mjx": 1},  # a choice of --engine
    "mjx_arm/envs/mjx_env.py": {"mjx": 1},  # the env's own engine
}


def _name_strings(name: str, paths: list[Path]) -> dict[str, int]:
    """Per file, how many string constants of ``paths`` are exactly ``name``."""
    counts: dict[str, int] = {}
    for path in paths:
        tree = ast.parse(path.read_text(), str(path))
        n = sum(isinstance(c, ast.Constant) and c.value == name for c in ast.walk(tree))
        if n:
            counts[str(path.relative_to(ROOT))] = n
    return counts


def test_the_reference_engine_is_named_only_in_its_row_and_its_package() -> None:
    # "mujoco" and "mjx" are backend and module names too, so the count covers the engine that
    # lives in a package of its own, as any added engine would.
    paths = [p for p in sorted((ROOT / "mjx_arm").rglob("*.py")) if p.name != "engines.py"]
    assert _name_strings("pybullet", paths) == ALLOWED


def test_the_urdf_checks_and_parity_causes_name_no_engine() -> None:
    paths = [ROOT / p for p in NAMELESS]
    for name in engines.engine_names():
        assert _name_strings(name, paths) == {}, name


def test_the_modules_that_branched_on_names_keep_only_typed_names() -> None:
    for path, expected in TYPED.items():
        counts = {name: _name_strings(name, [ROOT / path]).get(path, 0) for name in expected}
        assert counts == expected, path
        others = set(engines.engine_names()) - set(expected)
        assert all(_name_strings(name, [ROOT / path]) == {} for name in others), path


def test_the_roles_name_rows_that_fill_them() -> None:
    converter = engines.engine(engines.CONVERTER_ENGINE, "urdf_reader")
    assert converter.provides("env")  # the converted MJCF model is what its env loads
    reference = engines.engine(engines.REFERENCE_ENGINE, "parity")
    assert reference.provides("env")  # the demo films it through its Gymnasium env
    assert [n for n in engines.engine_names() if engines.engine(n).impl_choice] == ["mjx"]


def test_parity_runs_once_per_implementation_only_where_the_row_offers_a_choice() -> None:
    from mjx_arm.bench.parity import ParityConfig, engine_specs

    both = ParityConfig.quick(engines=("mujoco", "mjx"), impls=("jax", "jax"))
    assert engine_specs(both) == [("mujoco", "auto"), ("mjx", "jax")]
    ParityConfig.quick(engines=("mjx",), impls=("jax", "warp"))  # two runs of one engine
    with pytest.raises(ValueError, match="two engines"):
        ParityConfig.quick(engines=("pybullet",), impls=("jax", "warp"))
