"""JAX's persistent compilation cache, shared by every command that compiles."""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_FOLDER = Path.home() / ".cache" / "mjx_arm" / "jax"


def enable_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache under ``~/.cache/mjx_arm/jax``
    (``MJX_ARM_JAX_CACHE`` overrides the folder); compilations of 1 s or more are kept."""
    import jax

    folder = os.environ.get("MJX_ARM_JAX_CACHE", str(DEFAULT_FOLDER))
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
