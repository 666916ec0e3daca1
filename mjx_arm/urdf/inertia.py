"""Checks and repairs of link inertia tensors, shared by validation and conversion."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping

import numpy as np

# Relative slack on the triangle inequality, as MuJoCo's compiler allows for rounding.
TRIANGLE_TOL = 1e-6


INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def inertia_tensor(values: Mapping[str, float]) -> np.ndarray:
    """The symmetric tensor, shape ``(3, 3)``, of a URDF ``<inertia>``'s six values."""
    v = values
    return np.array(
        [
            [v["ixx"], v["ixy"], v["ixz"]],
            [v["ixy"], v["iyy"], v["iyz"]],
            [v["ixz"], v["iyz"], v["izz"]],
        ]
    )


def principal_moments(inertia: np.ndarray) -> np.ndarray:
    """Eigenvalues of a symmetric inertia tensor, shape ``(3,)``, ascending.

    The tensor is scaled to unit size first, so entries near the float limit (1e308) do not
    overflow the eigen solver.
    """
    moments, _ = _scaled_eigh(inertia)
    return moments


def _scaled_eigh(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues ``(3,)`` and eigenvectors ``(3, 3)`` of the symmetric part of a finite tensor."""
    scale = float(np.abs(inertia).max())
    if scale == 0.0:
        return np.zeros(3), np.eye(3)
    unit = inertia / scale
    moments, axes = np.linalg.eigh(0.5 * (unit + unit.T))
    return moments * scale, axes


def inertia_problem(inertia: np.ndarray) -> str | None:
    """Describe what is wrong with an inertia tensor, or return None when it is physical.

    Args:
        inertia: the tensor about the centre of mass, shape ``(3, 3)``.
    """
    if not np.all(np.isfinite(inertia)):
        return "has non-finite entries"
    moments = principal_moments(inertia)
    if moments[0] <= 0.0:
        return f"is not positive definite (principal moments {_fmt(moments)})"
    a, b, c = moments
    if a + b < c * (1.0 - TRIANGLE_TOL):
        return (
            f"breaks the triangle inequality of its principal moments {_fmt(moments)}: "
            f"{a:.6g} + {b:.6g} < {c:.6g}"
        )
    return None


REPAIR_MARGIN = 1e-4  # relative: well above the 6 significant digits MuJoCo writes


def on_triangle_edge(inertia: np.ndarray) -> bool:
    """True for a tensor within :data:`REPAIR_MARGIN` of breaking ``a + b >= c`` (or breaking
    it by less than the tolerance of :func:`inertia_problem`): MuJoCo may refuse it once the
    tensor is written with 6 significant digits."""
    a, b, c = principal_moments(inertia)
    return a + b < c * (1.0 + REPAIR_MARGIN)


def repair_inertia(inertia: np.ndarray) -> np.ndarray:
    """Return the nearest tensor that satisfies the triangle inequality, shape ``(3, 3)``.

    The principal axes are kept; the two smaller principal moments are raised together until
    their sum exceeds the largest one by :data:`REPAIR_MARGIN` of it (so the tensor stays valid
    once MuJoCo writes it with 6 significant digits), and every moment is kept above a small
    positive floor.
    """
    moments, axes = _scaled_eigh(inertia)
    floor = max(1e-9, 1e-6 * float(np.abs(moments).max()))
    moments = np.maximum(moments, floor)
    deficit = moments[2] * (1.0 + REPAIR_MARGIN) - (moments[0] + moments[1])
    if deficit > 0:
        moments[0] += deficit / 2
        moments[1] += deficit / 2
    return axes @ np.diag(moments) @ axes.T


def _fmt(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


def is_frame(link: ET.Element) -> bool:
    """A link without mass: no ``<inertial>``, or mass 0 with an all-zero (or no) inertia.

    Description packages mark frames this way (UR's ``base``, ``tool0``, ``ee_link``; Panda's
    ``panda_link8``). On a fixed joint such a link is welded to its parent and needs no inertia.
    """
    inertial = link.find("inertial")
    if inertial is None:
        return True
    mass = inertial.find("mass")
    try:
        if mass is not None and float(mass.get("value", "0")) != 0.0:
            return False
        inertia = inertial.find("inertia")
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        return inertia is None or all(float(inertia.get(k, "0")) == 0.0 for k in keys)
    except ValueError:
        return False
