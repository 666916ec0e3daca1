"""The URDF pipeline: validate a URDF, then convert it to an MJX-ready MJCF model.

The names below load on first use (PEP 562), so importing the package, or its command line
(:mod:`mjx_arm.urdf.cli`), does not import MuJoCo.
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    "ConvertConfig": "mjx_arm.urdf.convert",
    "build_spec": "mjx_arm.urdf.convert",
    "load_model": "mjx_arm.urdf.convert",
    "to_mjcf": "mjx_arm.urdf.convert",
    "ConversionError": "mjx_arm.urdf.errors",
    "UrdfError": "mjx_arm.urdf.errors",
    "RobotModel": "mjx_arm.urdf.model",
    "parse_urdf": "mjx_arm.urdf.model",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module 'mjx_arm.urdf' has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)
