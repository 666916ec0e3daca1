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


def test_precompile_does_nothing_without_threads_devices_or_loads():
    """0 threads never compiles, nor do empty loads; on a machine without a GPU the default
    devices are none, so nothing is compiled either."""
    assert warp_compile.precompile(0, {1: ["a module"]}, ["cpu"]) == 0.0
    assert warp_compile.precompile(8, {}, ["cpu"]) == 0.0
    assert warp_compile.start_precompile(0, {1: ["a module"]}) is None
    if jax.default_backend() == "cpu":
        assert warp_compile.precompile(8, {1: ["a module"]}) == 0.0
        assert warp_compile.start_precompile(8, {1: ["a module"]}) is None
