"""Import ``mujoco.mjx`` without its notice about a missing Warp.

``mujoco.mjx`` imports its Warp backend on load; where warp-lang is not installed (every CPU
install of this project) that module prints ``Failed to import warp: ...`` and ``Failed to import
mujoco_warp: ...`` to stdout, and Brax imports ``mujoco.mjx`` too. The notice is not the user's
to act on: this project picks the JAX implementation there (``physics.impl=auto``).

:func:`install` puts a finder first on ``sys.meta_path`` that wraps the loading of that one
module (``mujoco.mjx.warp``) in ``contextlib.redirect_stdout``; every other module, and that
module's behaviour (``WARP_INSTALLED`` stays False), is untouched. It does nothing where
warp-lang is installed.
"""

from __future__ import annotations

import contextlib
import importlib.abc
import importlib.machinery
import importlib.util
import io
import sys
from types import ModuleType

QUIET_MODULE = "mujoco.mjx.warp"


class _QuietLoader(importlib.abc.Loader):
    """Runs another loader's ``exec_module`` with Python's stdout swallowed."""

    def __init__(self, loader: importlib.abc.Loader) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            self._loader.exec_module(module)


class _QuietFinder(importlib.abc.MetaPathFinder):
    """Finds :data:`QUIET_MODULE` through the other finders and quiets its loader."""

    def find_spec(self, fullname, path, target=None):
        if fullname != QUIET_MODULE:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None and spec.loader is not None:
                spec.loader = _QuietLoader(spec.loader)
                return spec
        return None


def install() -> None:
    """Quiet ``mujoco.mjx.warp``'s notice where warp-lang is missing (idempotent)."""
    if QUIET_MODULE in sys.modules or importlib.util.find_spec("warp") is not None:
        return
    if not any(isinstance(f, _QuietFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _QuietFinder())
