"""The order MuJoCo Warp's modules compile in (no GPU or Warp needed: the order is pure)."""

from __future__ import annotations

from types import SimpleNamespace

from mjx_arm.envs.warp_compile import SLOW_FIRST, compile_order

PACKAGE = "mujoco.mjx.third_party.mujoco_warp._src"


def _module(name: str) -> SimpleNamespace:
    return SimpleNamespace(name=f"{PACKAGE}.{name}")


def test_every_block_size_goes_to_one_queue_with_the_slowest_families_first() -> None:
    """All (module, block size) pairs come back once, the SLOW_FIRST families first in that
    tuple's order whatever their block size, and the rest in their listed order: the Newton
    solver's tile Cholesky (its own block size) no longer waits for the 256-thread group."""
    small = [_module(f"smooth._kernel_{i}__locals__kernel_{i:08x}") for i in range(3)]
    narrow = _module("collision_primitive._primitive_narrowphase__locals__primitive_narrowphase_1")
    cholesky = _module("solver._update_gradient_cholesky__locals__kernel_8d4db0b0")
    loads = {256: [small[0], narrow, small[1]], 32: [small[2], cholesky]}
    order = compile_order(loads)
    listed = [(m.name, dim) for dim, modules in loads.items() for m in modules]
    assert sorted((m.name, dim) for m, dim in order) == sorted(listed)
    assert order[:2] == [(cholesky, 32), (narrow, 256)]
    assert order[2:] == [(small[0], 256), (small[1], 256), (small[2], 32)]
    assert SLOW_FIRST.index("_update_gradient_cholesky") < SLOW_FIRST.index(
        "_primitive_narrowphase"
    )
