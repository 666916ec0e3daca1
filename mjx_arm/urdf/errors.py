"""Errors raised by the URDF pipeline."""

from __future__ import annotations

from mjx_arm.inputs import InputError


class UrdfError(InputError, ValueError):
    """A URDF that cannot be used, with a message that names the element and the fix."""


class ConversionError(UrdfError):
    """A URDF that MuJoCo's importer or compiler rejects, or that lacks what conversion needs."""


def one_line(text: object) -> str:
    """``text`` (an exception, a message) on one line: its non-empty lines joined by ``; ``."""
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())
