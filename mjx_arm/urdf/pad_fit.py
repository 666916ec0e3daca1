"""Finger pads fitted to collision meshes, the same in every engine.

A gripper's pads are where its contact forces are read (MuJoCo's touch sensors, PyBullet's
contact points) and what presses the object. A pad whose collision is a mesh is replaced by one
box fitted to it here, from the mesh files (no engine involved), so that the converter
(:func:`mjx_arm.urdf.collision_fit.fit_pads`, MuJoCo and MJX) and PyBullet's copy of the URDF
put the same box in the same place:

- a finger (a moving jaw, a linkage's or a parallel gripper's finger): every collision mesh of
  its link becomes one box around their vertices, turned to the gripper's closing and approach
  directions at the closed pose;
- a fixed jaw (one-jaw grippers: a moving jaw closes on a jaw that is part of the hand): the
  hand's collision meshes are cut across the approach direction where the jaw ends. Both
  engines collide a mesh through its convex hull, and the hull of a hand with a jaw sticking out
  of it fills the space between the jaws with a slope from the palm to the jaw's tip (on the
  SO-101 it reaches 1-2 cm into the grasp). The part beyond the cut (the jaw) becomes the pad
  box; the rest of each cut mesh stays a mesh (its own hull). The cut: from the tip back, slab
  by slab (:data:`JAW_SLAB` thick) while the jaw's inner face (its side towards the moving jaw)
  stays within :data:`JAW_FACE_STEP` of where it is at the tip; the palm, wider, ends it.

Every length in m; vertices and boxes in the link's frame (the URDF link frame, which is also
MuJoCo's body frame and PyBullet's link frame).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.mesh_convert import load_mesh
from mjx_arm.urdf.meshes import existing_mesh
from mjx_arm.urdf.model import RobotModel, parse_urdf

JAW_SLAB = 0.005  # m: the slabs a hand's meshes are looked at in, from the tip back
# m: the fixed jaw ends where its inner face comes this much nearer the moving jaw than at the
# tip (the SO-101's jaw face recedes by 5 mm over its 5 cm; its palm stands 1 cm proud of it)
JAW_FACE_STEP = 0.005
PAD_GEOM_SUFFIX = "_pad_box"  # the fitted box's name: LINK + this (MuJoCo)
REST_MESH_SUFFIX = "_rest"  # the kept part of a cut mesh: LINK + this + its number (MuJoCo)


@dataclass(frozen=True)
class PadAxes:
    """One pad to fit, and how its box is turned (both unit vectors in the link's frame).

    Attributes:
        link: the pad's link.
        closing: from this pad towards the other one, with the gripper closed.
        approach: from the hand towards the fingertips, across ``closing``.
        fixed_jaw: the link is a hand whose meshes carry a fixed jaw: the pad is cut from them
            (module doc) and its box keeps ``closing`` and ``approach`` (its face along the
            tool axis, where a cube standing on the table meets it); otherwise all its
            collision meshes make the pad, and the box turns to the finger's face
            (:func:`_box`).
        tip: a moving jaw's pad is its last ``tip`` (m) towards its tip along ``approach``,
            its box square to ``closing`` and ``approach`` (the rest of its meshes stays
            hulls); 0: the whole finger.
    """

    link: str
    closing: tuple[float, float, float]
    approach: tuple[float, float, float]
    fixed_jaw: bool = False
    tip: float = 0.0


@dataclass(frozen=True, eq=False)
class PadBox:
    """A fitted pad: a box in its link's frame.

    Attributes:
        link: the pad's link.
        centre: the box's centre, ``(3,)``.
        rotation: link-from-box rotation ``(3, 3)``, its columns the closing, approach and
            across directions.
        half: half sizes along those, ``(3,)``.
    """

    link: str
    centre: np.ndarray
    rotation: np.ndarray
    half: np.ndarray

    @property
    def inner_face(self) -> np.ndarray:
        """The centre of the box's face towards the other pad, ``(3,)``, link frame."""
        return self.centre + self.rotation[:, 0] * self.half[0]


@dataclass(frozen=True, eq=False)
class FittedPads:
    """The pads of one gripper, fitted.

    Attributes:
        boxes: one per fitted pad.
        rests: ``(link, vertices (k, 3))`` of each cut mesh's kept part (a hand's palm).
        replaced: the links whose collision meshes the boxes and rests replace.
        hand: the link the gripper hangs from: a fitted pad does not collide with it or with
            any link below it (a box around a finger overlaps the knuckles it turns with).
    """

    boxes: tuple[PadBox, ...] = ()
    rests: tuple[tuple[str, np.ndarray], ...] = ()
    replaced: frozenset[str] = field(default_factory=frozenset)
    hand: str = ""

    def box(self, link: str) -> PadBox | None:
        """The fitted box of ``link``, or None."""
        return next((b for b in self.boxes if b.link == link), None)


def mesh_vertices(
    model: RobotModel, link: str, package_dirs: Mapping[str, str] | None = None
) -> list[np.ndarray]:
    """The vertices ``(n, 3)`` of each collision mesh of ``link``, in the link's frame (scaled
    and placed by each ``<collision>`` origin); [] without any.

    Raises:
        ConversionError: a mesh that cannot be found or read.
    """
    path = Path(model.path) if model.path else Path(".")
    out = []
    for geometry in model.links[link].collisions:
        if geometry.kind != "mesh" or not geometry.filename:
            continue
        source = existing_mesh(geometry.filename, path, link, dict(package_dirs or {}))
        vertices = _file_vertices(str(source), source.stat().st_mtime_ns)
        local = vertices * np.asarray(geometry.scale, float)
        out.append(local @ geometry.origin.matrix()[:3, :3].T + np.asarray(geometry.origin.xyz))
    return out


@functools.lru_cache(maxsize=64)
def _file_vertices(path: str, mtime_ns: int) -> np.ndarray:
    del mtime_ns  # part of the cache key
    return np.asarray(load_mesh(path).vertices, float)


def shape_centre(model: RobotModel, link: str) -> np.ndarray:
    """The middle of ``link``'s collision shapes in its frame, ``(3,)``: of its meshes'
    vertices where it has meshes, else the mean of its shapes' origins (0 without any)."""
    meshes = mesh_vertices(model, link)
    if meshes:
        points = np.concatenate(meshes)
        return 0.5 * (points.min(axis=0) + points.max(axis=0))
    shapes = model.links[link].collisions
    if not shapes:
        return np.zeros(3)
    return np.mean([np.asarray(s.origin.xyz, float) for s in shapes], axis=0)


def fit_pads(model: RobotModel, axes: tuple[PadAxes, ...], hand: str = "") -> FittedPads:
    """The fitted pads of ``axes`` (module doc) of a gripper that hangs from ``hand``, cached
    per URDF file version; a pad without collision meshes is left out (its own shapes stay its
    pad).

    Raises:
        ConversionError: a mesh that cannot be read, or a hand whose meshes have no part
            that can be cut off as its fixed jaw.
    """
    path = Path(model.path).resolve()
    return _fit_cached(str(path), path.stat().st_mtime_ns, axes, hand)


@functools.lru_cache(maxsize=32)
def _fit_cached(path: str, mtime_ns: int, axes: tuple[PadAxes, ...], hand: str) -> FittedPads:
    del mtime_ns
    model = parse_urdf(path)
    boxes, rests, replaced = [], [], set()
    for pad in axes:
        meshes = mesh_vertices(model, pad.link)
        if not meshes:
            continue
        rotation = _rotation(pad)
        if pad.fixed_jaw or pad.tip:
            if pad.fixed_jaw:
                jaw, kept = _cut_jaw(model, pad, meshes, rotation)
            else:
                tip = max(float((m @ rotation[:, 1]).max()) for m in meshes)
                jaw, kept = _cut(meshes, rotation, tip - pad.tip)
            rests += [(pad.link, part) for part in kept]
            boxes.append(_box(pad.link, jaw, rotation, turn=False))
        else:
            boxes.append(_box(pad.link, np.concatenate(meshes), rotation))
        replaced.add(pad.link)
    return FittedPads(tuple(boxes), tuple(rests), frozenset(replaced), hand)


def _rotation(pad: PadAxes) -> np.ndarray:
    """Link-from-box rotation ``(3, 3)``: closing, approach (made square to it), across."""
    closing = np.asarray(pad.closing, float)
    closing /= np.linalg.norm(closing)
    approach = np.asarray(pad.approach, float)
    approach = approach - closing * (approach @ closing)
    approach /= np.linalg.norm(approach)
    return np.stack([closing, approach, np.cross(closing, approach)], axis=1)


def _box(link: str, vertices: np.ndarray, rotation: np.ndarray, turn: bool = True) -> PadBox:
    """The box around ``vertices (n, 3)`` (link frame), its faces along the pad's inner face
    (``turn``): ``rotation``'s axes turned about the across axis by the slant of that face (a
    line through its outermost point in each :data:`JAW_SLAB` along the approach, within
    :data:`MAX_TURN`); without ``turn``, ``rotation``'s axes. A finger that slants at the
    closed pose (the SO-101's moving jaw, 12 degrees) gets a box that presses with its face,
    not one as thick as its slant."""
    face, along = vertices @ rotation[:, 0], vertices @ rotation[:, 1]
    slabs = np.floor((along - along.min()) / JAW_SLAB).astype(int)
    tops = [(along[slabs == k].mean(), face[slabs == k].max()) for k in np.unique(slabs)]
    slope = np.polyfit(*np.array(tops).T, 1)[0] if turn and len(tops) >= 2 else 0.0
    turn = np.clip(np.arctan(slope), -np.radians(MAX_TURN), np.radians(MAX_TURN))
    c, s = np.cos(turn), np.sin(turn)
    closing = c * rotation[:, 0] - s * rotation[:, 1]
    approach = s * rotation[:, 0] + c * rotation[:, 1]
    turned = np.stack([closing, approach, rotation[:, 2]], axis=1)
    local = vertices @ turned
    low, high = local.min(axis=0), local.max(axis=0)
    return PadBox(link, turned @ (0.5 * (low + high)), turned, 0.5 * (high - low))


MAX_TURN = 30.0  # degrees: the most a pad box turns from the closing direction to fit


def _cut_jaw(
    model: RobotModel, pad: PadAxes, meshes: list[np.ndarray], rotation: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The fixed jaw's vertices ``(k, 3)`` and each cut mesh's kept vertices (link frame):
    slabs from the tip back while the inner face keeps within :data:`JAW_FACE_STEP` of the
    tip's (module doc)."""
    points = np.concatenate(meshes)
    face, along = points @ rotation[:, 0], points @ rotation[:, 1]
    tip = along.max()
    tip_face = face[along > tip - JAW_SLAB].max()
    cut = tip - JAW_SLAB
    while cut > along.min():
        slab = (along > cut - JAW_SLAB) & (along <= cut)
        if slab.any() and face[slab].max() > tip_face + JAW_FACE_STEP:
            break
        cut -= JAW_SLAB
    jaw, kept = _cut(meshes, rotation, cut)
    if len(jaw) < 4 or not kept:
        raise ConversionError(
            f"{model.path}: link {pad.link!r}: no fixed jaw can be cut from its collision "
            "meshes (nothing sticks out towards the moving jaw's tip); give the jaw its own "
            "collision box"
        )
    return jaw, kept


def _cut(
    meshes: list[np.ndarray], rotation: np.ndarray, cut: float
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The vertices beyond ``cut`` along the approach (``rotation``'s second axis), and each
    mesh's vertices before it (those with at least 4 left)."""
    points = np.concatenate(meshes)
    kept = [m[m @ rotation[:, 1] <= cut] for m in meshes]
    return points[points @ rotation[:, 1] > cut], [k for k in kept if len(k) >= 4]
