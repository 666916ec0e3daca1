"""The MJX physics settings: named errors for bad values, and the Warp precompile's no-op cases."""

from __future__ import annotations

import jax
import pytest

from mjx_arm.envs import warp_compile
from mjx_arm.envs.physics_config import PhysicsConfig


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"impl": "cuda"}, "physics.impl must be one of"),
        ({"njmax": -1}, "physics.njmax"),
        ({"naconmax_per_env": -2}, "physics.naconmax_per_env"),
        ({"compile_threads": -1}, "physics.compile_threads"),
    ],
)
def test_bad_values_are_named(changes, message):
    with pytest.raises(ValueError, match=message):
        PhysicsConfig(**changes)


def test_round_trip_and_unknown_keys():
    config = PhysicsConfig(impl="jax", njmax=12, compile_threads=0)
    assert PhysicsConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError, match="unknown physics config keys: \\['threads'\\]"):
        PhysicsConfig.from_dict({"threads": 4})


def test_precompile_does_nothing_without_threads_or_gpu():
    """0 threads never compiles; on a machine without a GPU nothing is compiled either."""
    assert warp_compile.precompile(0) == 0.0
    if jax.default_backend() == "cpu":
        assert warp_compile.precompile(8) == 0.0


def test_step_modules_are_files_of_mujoco_warp():
    """Every listed module is one of MuJoCo Warp's source files in the installed mujoco-mjx
    (found on disk: importing them needs warp-lang)."""
    from pathlib import Path

    from mujoco import mjx

    root = Path(mjx.__file__).parent.parent.parent  # site-packages
    folder = root.joinpath(*warp_compile.PACKAGE.split("."))
    for name in warp_compile.STEP_MODULES:
        assert (folder / f"{name}.py").is_file(), name
