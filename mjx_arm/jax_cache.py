"""JAX's persistent compilation cache, shared by every command that compiles."""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_FOLDER = Path.home() / ".cache" / "mjx_arm" / "jax"


def enable_compilation_cache() -> None:
    """Turn on JAX's persistent compilation cache under ``~/.cache/mjx_arm/jax``
    (``MJX_ARM_JAX_CACHE`` overrides the folder).

    Every compiled program is kept, however small: JAX's default keeps only those that took
    1 s or more, and a new process then compiles dozens of small programs again (a few
    tenths of a second each on a GPU). Programs with host callbacks (the C MuJoCo backend's
    physics) are never kept: JAX cannot store them.
    """
    import jax

    jax.config.update("jax_compilation_cache_dir", str(cache_folder()))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def cache_folder() -> Path:
    """Where JAX's compilation cache lives: ``MJX_ARM_JAX_CACHE``, else
    ``~/.cache/mjx_arm/jax``."""
    return Path(os.environ.get("MJX_ARM_JAX_CACHE", str(DEFAULT_FOLDER)))
