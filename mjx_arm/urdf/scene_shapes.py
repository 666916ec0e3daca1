"""The scene's names and shapes, without MuJoCo: table and box sizes, the target's names, the
camera and the collision bits of scene geoms.

Table and box sizes come from ``assets/table.urdf`` and ``assets/target_box.urdf``, which the
PyBullet reference env loads directly, so both engines see the same scene. Engine-neutral code
(the task rules) reads the box height here without importing MuJoCo.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from mjx_arm.paths import asset
from mjx_arm.urdf.model import Geometry, parse_urdf

# Collision bit masks of scene geoms (table, target box): they never collide with each other,
# only with the arm (mjx_arm.urdf.convert_config has the arm's bits).
SCENE_CONTYPE, SCENE_CONAFFINITY = 2, 1

TARGET_BODY = "target"
TARGET_SITE = "target"
TARGET_GEOM = "target_box"
FLOOR_Z = -0.75
# The lift scene's free cube (the gripper's 85 mm stroke takes 4-5 cm cubes): its body and geom,
# half edge (m) and mass (kg) as built; a task or check moves it through its free joint.
CUBE_BODY, CUBE_GEOM = "cube", "cube"
CUBE_HALF, CUBE_MASS = 0.0225, 0.1


@dataclass(frozen=True)
class SceneSpec:
    """What a task's scene holds around the arm, as data: the MuJoCo scene builder
    (:func:`mjx_arm.urdf.scene.add_scene`) and the PyBullet env build from it. A task declares
    its scene (:attr:`mjx_arm.task.spec.Task.scene`): one of :data:`SCENES` or its own.

    Attributes:
        name: the scene's name (``mjx-arm convert --scene`` takes those of :data:`SCENES`).
        table: the floor, light, table, camera and the mocap target body (False: the arm
            alone; nothing below applies).
        box: the target box (``assets/target_box.urdf``) stands on the target body, the target
            site on its top face; otherwise the target body carries a sphere marker.
        marker: the sphere marker is drawn (it marks the target in the model either way).
        cube_half: half edge (m) of a free cube (:data:`CUBE_BODY`, :data:`CUBE_MASS`) resting
            on the table; 0: no cube.
    """

    name: str
    table: bool = True
    box: bool = False
    marker: bool = True
    cube_half: float = 0.0


NO_SCENE = SceneSpec("none", table=False, marker=False)
REACH_SCENE = SceneSpec("reach")  # a marker the arm passes through
TOUCH_SCENE = SceneSpec("touch", box=True, marker=False)  # the 5 cm box on the table
LIFT_SCENE = SceneSpec("lift", marker=False, cube_half=CUBE_HALF)  # the target is the cube
# The scenes the converter builds by name (``--scene``); a task may declare one of its own.
SCENES = {scene.name: scene for scene in (NO_SCENE, REACH_SCENE, TOUCH_SCENE, LIFT_SCENE)}

# One camera for every engine: eye, look-at point (m, world frame) and vertical field of view.
CAMERA_EYE = (1.45, -1.05, 0.85)
CAMERA_TARGET = (0.35, 0.0, 0.1)
CAMERA_FOVY = 45.0


@functools.cache
def scene_geometry() -> dict[str, tuple[Geometry, ...]]:
    """Collision shapes of the table and the target box, from the shipped URDFs."""
    table = parse_urdf(asset("table.urdf"))
    box = parse_urdf(asset("target_box.urdf"))
    return {
        "table": table.links["table_top"].collisions,
        "box": box.links["box"].collisions,
    }


def box_top_offset() -> float:
    """Height (m) of the target box's top face above the box frame (its bottom face centre)."""
    (geom,) = scene_geometry()["box"]
    return geom.origin.xyz[2] + geom.size[2] / 2


def box_half_width() -> float:
    """Half the target box's width (m) across its top face (the narrower side)."""
    (geom,) = scene_geometry()["box"]
    return min(geom.size[0], geom.size[1]) / 2


def table_top_extent(margin: float = 0.0) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((x_min, y_min), (x_max, y_max))`` of the table's top face (m), shrunk by ``margin``."""
    (geom,) = scene_geometry()["table"]
    centre = geom.origin.xyz
    half = (geom.size[0] / 2 - margin, geom.size[1] / 2 - margin)
    low = (centre[0] - half[0], centre[1] - half[1])
    return low, (centre[0] + half[0], centre[1] + half[1])
