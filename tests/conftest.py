"""Shared test settings: JAX's persistent compilation cache and quiet logs."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# mjx-arm's error-report files (mjx_arm.cli) go to a folder of this run, not the user's.
os.environ["XDG_STATE_HOME"] = tempfile.mkdtemp(prefix="mjx_arm-test-state-")
_REPO = Path(__file__).resolve().parents[1]
_CACHE = Path(os.environ.get("MJX_ARM_JAX_CACHE", _REPO / ".jax_cache"))


def pytest_configure(config: pytest.Config) -> None:
    """Compile each JAX function once per machine: later runs load it from the cache."""
    import jax

    jax.config.update("jax_compilation_cache_dir", str(_CACHE))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


@pytest.fixture
def register_engine():
    """Adds engine-registry rows for one test: ``register_engine(row)`` registers ``row`` and
    returns it; every row added is removed when the test ends, pass or fail."""
    from mjx_arm import engines

    names: list[str] = []

    def register(row: engines.EngineSpec) -> engines.EngineSpec:
        engines.register_engine(row)
        names.append(row.name)
        return row

    yield register
    for name in names:
        engines.unregister_engine(name)
