"""The PyBullet reference engine. ``PybulletArmEnv`` is imported on first use, so the settings
modules (``pybullet_ref.contact``) load without PyBullet."""

from typing import Any

__all__ = ["PybulletArmEnv"]


def __getattr__(name: str) -> Any:
    if name == "PybulletArmEnv":
        from pybullet_ref.env import PybulletArmEnv

        return PybulletArmEnv
    raise AttributeError(f"module 'pybullet_ref' has no attribute {name!r}")
