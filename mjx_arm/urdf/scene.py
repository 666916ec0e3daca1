"""The task scene around the arm: floor, table, target and a camera, built on an ``MjSpec``.

Sizes and names come from :mod:`mjx_arm.urdf.scene_shapes` (no MuJoCo there), re-exported here.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_arm.urdf.model import Geometry
from mjx_arm.urdf.scene_shapes import (
    CAMERA_EYE,
    CAMERA_FOVY,
    CAMERA_TARGET,
    CUBE_BODY,
    CUBE_GEOM,
    CUBE_HALF,
    CUBE_MASS,
    FLOOR_Z,
    SCENE_CONAFFINITY,
    SCENE_CONTYPE,
    SCENES,
    TARGET_BODY,
    TARGET_GEOM,
    TARGET_SITE,
    SceneSpec,
    box_top_offset,
    scene_geometry,
)

__all__ = [
    "CAMERA_EYE",
    "CAMERA_FOVY",
    "CAMERA_TARGET",
    "CUBE_BODY",
    "CUBE_HALF",
    "CUBE_MASS",
    "FLOOR_Z",
    "SCENES",
    "TARGET_BODY",
    "TARGET_GEOM",
    "TARGET_SITE",
    "SceneSpec",
    "add_scene",
    "box_top_offset",
    "camera_quat",
    "scene_geometry",
]


def camera_quat() -> np.ndarray:
    """Orientation (w, x, y, z) of a MuJoCo camera at CAMERA_EYE looking at CAMERA_TARGET."""
    eye, target = np.array(CAMERA_EYE), np.array(CAMERA_TARGET)
    back = eye - target
    back /= np.linalg.norm(back)  # camera z axis points away from the scene
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.stack([right, up, back], axis=1).ravel())
    return quat


def add_scene(spec: mujoco.MjSpec, scene: SceneSpec) -> None:
    """Add what ``scene`` holds: floor, table, light, camera and the mocap target body, with the
    box on the target or a marker, and a free cube resting on the table."""
    if not scene.table:
        return
    world = spec.worldbody
    _add_room(world)
    target = world.add_body()
    target.name = TARGET_BODY
    target.mocap = True
    target.pos = [0.5, 0.0, 0.0]
    site = target.add_site()
    site.name = TARGET_SITE
    site.size = [0.006, 0, 0]
    site.group = 4
    if scene.box:
        for g in scene_geometry()["box"]:
            geom = target.add_geom()
            geom.name = TARGET_GEOM
            _set_box(geom, g, rgba=[0.85, 0.15, 0.15, 1.0])
            geom.contype, geom.conaffinity = SCENE_CONTYPE, SCENE_CONAFFINITY
        site.pos = [0.0, 0.0, box_top_offset()]
    else:
        _add_marker(target, scene.marker)
    if scene.cube_half:
        _add_cube(world, scene.cube_half)


def _add_room(world: mujoco.MjsBody) -> None:
    """The light, the floor (no collision), the table's boxes and the main camera."""
    light = world.add_light()
    light.pos = [0.5, -0.5, 2.5]
    light.dir = [-0.2, 0.2, -1.0]
    floor = world.add_geom()
    floor.name = "floor"
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [3.0, 3.0, 0.05]
    floor.pos = [0.0, 0.0, FLOOR_Z]
    floor.rgba = [0.8, 0.8, 0.82, 1.0]
    floor.contype = floor.conaffinity = 0
    for i, g in enumerate(scene_geometry()["table"]):
        geom = world.add_geom()
        geom.name = f"table_{i}"
        _set_box(geom, g, rgba=[0.62, 0.5, 0.38, 1.0])
        geom.contype, geom.conaffinity = SCENE_CONTYPE, SCENE_CONAFFINITY
    camera = world.add_camera()
    camera.name = "main"
    camera.pos = list(CAMERA_EYE)
    camera.quat = camera_quat()
    camera.fovy = CAMERA_FOVY


def _add_marker(target: mujoco.MjsBody, visible: bool) -> None:
    """The target's green sphere (no collision), transparent where not ``visible``."""
    marker = target.add_geom()
    marker.name = "target_marker"
    marker.type = mujoco.mjtGeom.mjGEOM_SPHERE
    marker.size = [0.02, 0, 0]
    marker.rgba = [0.1, 0.8, 0.2, 0.5 if visible else 0.0]
    marker.contype = marker.conaffinity = 0


def _add_cube(world, half: float) -> None:
    """The free cube, resting on the table in front of the arm (a ``half`` edge (m),
    :data:`CUBE_MASS`); its free joint is its body's name."""
    cube = world.add_body()
    cube.name = CUBE_BODY
    cube.pos = [0.5, 0.15, half]
    joint = cube.add_freejoint()
    joint.name = CUBE_BODY
    geom = cube.add_geom()
    geom.name = CUBE_GEOM
    geom.type = mujoco.mjtGeom.mjGEOM_BOX
    geom.size = [half] * 3
    geom.mass = CUBE_MASS
    geom.rgba = [0.2, 0.35, 0.85, 1.0]
    # it rests on the table and is held by the fingers: it collides with both
    geom.contype = SCENE_CONTYPE | SCENE_CONAFFINITY
    geom.conaffinity = SCENE_CONTYPE | SCENE_CONAFFINITY


def _set_box(geom, source: Geometry, rgba: list[float]) -> None:
    if source.kind != "box" or any(source.origin.rpy):
        raise ValueError("scene pieces must be axis-aligned boxes")
    geom.type = mujoco.mjtGeom.mjGEOM_BOX
    geom.size = [s / 2 for s in source.size]
    geom.pos = list(source.origin.xyz)
    geom.rgba = rgba
