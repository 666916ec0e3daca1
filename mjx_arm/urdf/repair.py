"""The repairs an arm config asks of its URDF, applied to the URDF's XML alike for every engine.

An arm file (or ``--repair-inertia``, ``--default-effort``, ``--default-velocity``) may repair a
URDF that no engine would load as written: inertia tensors that break the triangle inequality
(or are not positive definite) become the nearest valid tensor
(:func:`mjx_arm.urdf.inertia.repair_inertia`), and moving joints without an effort or velocity
limit get the configured default. :func:`repair_tree` edits the parsed XML in place; MuJoCo's
conversion (:mod:`mjx_arm.urdf.mjcf`) feeds the edited text to MuJoCo's importer, and PyBullet
loads a copy of the same edited text (:func:`pybullet_ref.hulls.bullet_urdf`).

Why a repaired copy of the URDF for PyBullet, not the same values set through its API
(``changeDynamics(localInertiaDiagonal=)``, motor force caps):

- One function makes the repaired numbers of both engines, so they cannot drift apart: MuJoCo
  and PyBullet read the same ``<inertia>`` and ``<limit>`` text.
- Bullet's importer diagonalises a tensor with products of inertia and puts the link's inertial
  frame on its principal axes. ``changeDynamics`` sets the three moments only, in the frame
  Bullet derived from the broken tensor, and cannot turn that frame; from the repaired text
  Bullet derives the frame of the repaired tensor itself.
- The validator loads what the env loads: its PyBullet check loads the repaired copy
  (:func:`pybullet_ref.urdf_check.check_pybullet_load`), so an arm that validates with its
  repairs is the arm PyBullet steps.
- The PyBullet env loads a cached copy of the URDF already (its collision hulls shrunk by
  Bullet's margin): the repairs go into that copy, named by a hash of the source's bytes and of
  the repair options, in the user's cache folder, never beside the user's file.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mjx_arm.urdf.inertia import (
    INERTIA_KEYS,
    inertia_problem,
    inertia_tensor,
    is_frame,
    on_triangle_edge,
    repair_inertia,
)

# Where each of INERTIA_KEYS sits in the (3, 3) tensor.
_TENSOR_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
LIMIT_ATTRS = ("effort", "velocity")

# The fix a finding names for a broken inertia: the flag of every command that loads an arm
# (convert, validate, arm, train, warmup, eval) and the arm-file key of every command's --arm.
# Short enough (under 100 characters) to end a command's one error line whole.
INERTIA_FIX = "correct <inertia>, or --repair-inertia, or repair_inertia = true in an arm file"


def limit_fix(attr: str, unit: str) -> str:
    """The fix a finding names for a moving joint without an ``attr`` (effort or velocity)
    limit: its value, or the flag and the arm-file key that give every such joint one (under
    100 characters)."""
    return f"set it ({unit}), or --default-{attr} VALUE, or default_{attr} = VALUE in an arm file"


@dataclass(frozen=True)
class UrdfRepairs:
    """What to repair in a URDF: the fields of the same names of
    :class:`~mjx_arm.arm.config.ArmConfig` and
    :class:`~mjx_arm.urdf.convert_config.ConvertConfig`.

    Attributes:
        repair_inertia: replace each inertia tensor an engine uses that breaks the triangle
            inequality, is not positive definite or lies on the edge of the inequality by
            the nearest valid one.
        default_effort, default_velocity: the limit (N m or N; rad/s or m/s) of every moving
            joint whose ``<limit>`` gives none (or 0); 0 leaves such a joint as it is.
    """

    repair_inertia: bool = False
    default_effort: float = 0.0
    default_velocity: float = 0.0

    @classmethod
    def of(cls, config: Any) -> UrdfRepairs:
        """The repairs of an ``ArmConfig`` or a ``ConvertConfig``."""
        return cls(config.repair_inertia, config.default_effort, config.default_velocity)

    @classmethod
    def from_limits(cls, repair_inertia: bool, limits: Mapping[str, float] | None) -> UrdfRepairs:
        """The repairs of the validator's options (``default_limits``: ``effort``/``velocity``
        -> value)."""
        limits = limits or {}
        return cls(repair_inertia, limits.get("effort", 0.0), limits.get("velocity", 0.0))

    def limits(self) -> dict[str, float]:
        """``effort``/``velocity`` -> the value given to a joint without one."""
        return {"effort": self.default_effort, "velocity": self.default_velocity}

    @property
    def any(self) -> bool:
        """Whether anything is to be repaired."""
        return self.repair_inertia or self.default_effort > 0 or self.default_velocity > 0

    def describe(self) -> str:
        """The repairs in words, e.g. ``inertia; effort 80 where none``; "none"."""
        parts = ["inertia"] if self.repair_inertia else []
        parts += [f"{attr} {value:g} where none" for attr, value in self.limits().items() if value]
        return "; ".join(parts) or "none"

    def key(self) -> bytes:
        """The options as bytes, for the name of a cached repaired copy."""
        return repr((self.repair_inertia, *self.limits().values())).encode()


def repair_tree(root: ET.Element, repairs: UrdfRepairs) -> tuple[str, ...]:
    """Apply ``repairs`` to a URDF's ``<robot>`` element, in place.

    Returns:
        What changed, one entry per element: ``"joint NAME effort"``, ``"link NAME inertia"``.
    """
    changed = fill_limits(root, repairs.limits())
    if repairs.repair_inertia:
        changed += repair_inertias(root)
    return changed


def moves(joint: ET.Element) -> bool:
    """Whether a ``<joint>`` element moves (any type but fixed; a missing type is an error the
    validator reports)."""
    return joint.get("type", "") not in ("fixed", "")


def fill_limits(root: ET.Element, defaults: Mapping[str, float]) -> tuple[str, ...]:
    """Give moving joints without an effort or velocity limit the configured default (> 0)."""
    changed = []
    for joint in root.findall("joint"):
        if not moves(joint):
            continue
        limit = joint.find("limit")
        for attr, value in defaults.items():
            if value <= 0:
                continue
            if limit is None:
                limit = ET.SubElement(joint, "limit")
            try:
                missing = float(limit.get(attr, "0")) <= 0
            except ValueError:
                missing = False  # not a number: the validator has already said so
            if missing:
                limit.set(attr, repr(float(value)))
                changed.append(f"joint {joint.get('name', '?')} {attr}")
    return tuple(changed)


def inertial_links(root: ET.Element) -> list[ET.Element]:
    """The ``<link>`` elements whose inertia the engines use: every link a joint moves, and
    every link that is not a massless frame welded to its parent (:func:`is_frame`)."""
    moved = {c.get("link") for j in root.findall("joint") if moves(j) for c in j.findall("child")}
    return [
        link
        for link in root.findall("link")
        if link.get("name") in moved or not is_frame(link)
        if link.find("inertial/inertia") is not None
    ]


def link_tensor(link: ET.Element) -> np.ndarray:
    """The ``(3, 3)`` tensor of a link's ``<inertial><inertia>`` (missing values read 0).

    Raises:
        ValueError: a value that is not a number (the validator reports it first).
    """
    inertia = link.find("inertial/inertia")
    return inertia_tensor({k: float(inertia.get(k, "0")) for k in INERTIA_KEYS})


def repair_inertias(root: ET.Element) -> tuple[str, ...]:
    """Replace each used inertia tensor that is not valid, or lies on the edge of the triangle
    inequality, by :func:`~mjx_arm.urdf.inertia.repair_inertia` of it. Tensors with non-finite
    or non-numeric values are left for the checks to report."""
    changed = []
    for link in inertial_links(root):
        try:
            tensor = link_tensor(link)
        except ValueError:
            continue
        if not all(map(math.isfinite, tensor.ravel())):
            continue
        if inertia_problem(tensor) is None and not on_triangle_edge(tensor):
            continue
        fixed = repair_inertia(tensor)
        inertia = link.find("inertial/inertia")
        for key, (i, j) in zip(INERTIA_KEYS, _TENSOR_INDEX, strict=True):
            inertia.set(key, repr(float(fixed[i, j])))
        changed.append(f"link {link.get('name', '?')} inertia")
    return tuple(changed)
