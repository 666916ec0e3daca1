"""Where the shipped assets live, in a source checkout and in an installed wheel."""

from __future__ import annotations

from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent


def assets_dir() -> Path:
    """Return the folder holding the arm URDF and the scene pieces.

    An installed wheel carries them as ``mjx_arm/_assets``; a source checkout (also an editable
    install) keeps them in the top-level ``assets/`` folder beside the package.
    """
    for candidate in (_PACKAGE_DIR / "_assets", _PACKAGE_DIR.parent / "assets"):
        if (candidate / "ur5e.urdf").is_file():
            return candidate
    raise FileNotFoundError(
        f"mjx_arm assets not found next to {_PACKAGE_DIR}; reinstall the package "
        "(the wheel ships them as mjx_arm/_assets)"
    )


def asset(name: str) -> Path:
    """Return the path of one shipped asset, e.g. ``asset("ur5e.urdf")``."""
    path = assets_dir() / name
    if not path.exists():
        raise FileNotFoundError(f"no asset named {name!r} in {assets_dir()}")
    return path


def default_arm_urdf() -> Path:
    """Return the path of the shipped UR5e-class arm URDF."""
    return asset("ur5e.urdf")
