"""mjx_arm: train and check 6-DoF arm control policies.

Importing the package registers the Gymnasium ids ``mjx_arm/Reach-v0`` and ``mjx_arm/Touch-v0``.
"""

import ctypes.util as _ctypes_util
import os as _os
import sys as _sys

__version__ = "0.1.0"

# Headless rendering by default: MuJoCo picks its GL backend when first imported. Only where an
# EGL library exists: MuJoCo's import fails outright when told to use a missing one.
if (
    "MUJOCO_GL" not in _os.environ
    and _sys.platform.startswith("linux")
    and not _os.environ.get("DISPLAY")
    and _ctypes_util.find_library("EGL")
):
    _os.environ["MUJOCO_GL"] = "egl"

from mjx_arm import _quiet_mjx
from mjx_arm.envs.registration import register_envs as _register_envs

_quiet_mjx.install()  # no "Failed to import warp" notice where warp-lang is not installed

_register_envs()
