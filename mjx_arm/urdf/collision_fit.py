"""Collision primitives fitted to an arm's collision meshes (``ConvertConfig.collision``).

MuJoCo's compiler fits a capsule or a box to a mesh geom whose type is set to that primitive
(the mesh stays as the fit's source; the fit is made in the mesh's principal frame from its
inertia). A capsule fitted to a flat part bulges past it: its radius covers the part's wider
side, so across the thin side it reaches further than the mesh. On a flange that is the tool
axis, which moves the point where the tool meets a surface (the xArm7's last link: 8.7 mm,
the UR10's: 11.8 mm), and a policy trained on the capsule presses short of the box in an engine
that keeps the meshes. ``capsule`` therefore keeps a capsule only where it stays within
:data:`CAPSULE_BULGE` of the mesh across its axis; elsewhere the mesh gets a fitted box, which
a flat part fills (its ends along the axis may round off past the mesh: those ends overlap the
neighbouring links at the joints).
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_arm.urdf.errors import ConversionError

COLLISION_SHAPES = {
    "mesh": None,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "box": mujoco.mjtGeom.mjGEOM_BOX,
}

# m: the furthest a fitted capsule may reach past its mesh across its axis; further, a box.
# The Panda's capsules stay within 2.4 mm, the flanges of the xArm7 and the UR10 do not.
CAPSULE_BULGE = 0.005


def fit_collision_primitives(spec: mujoco.MjSpec, collision: str) -> None:
    """Replace each collision mesh of the arm by a primitive that MuJoCo's compiler fits to it:
    ``"box"`` a box, ``"capsule"`` a capsule (a box where the capsule would bulge, see the
    module doc), ``"mesh"`` keeps the meshes.

    Collision cylinders always become capsules of the same radius and half-length (each end
    rounds off, one radius further out): MJX does not collide cylinders with boxes, spheres or
    meshes, so a cylinder arm would not touch the table or the box in the batch.
    """
    if collision not in COLLISION_SHAPES:
        raise ConversionError(
            f"collision must be one of {list(COLLISION_SHAPES)}, not {collision!r}"
        )
    for geom in spec.geoms:
        if geom.type == mujoco.mjtGeom.mjGEOM_CYLINDER and _collides(geom):
            geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE
    shape = COLLISION_SHAPES[collision]
    if shape is None:
        return
    geoms = spec.geoms
    mesh = mujoco.mjtGeom.mjGEOM_MESH
    fitted = [i for i, g in enumerate(geoms) if g.type == mesh and _collides(g)]
    for index in fitted:
        geoms[index].type = shape
    if collision == "capsule":
        for index in _bulging_capsules(spec, fitted):
            geoms[index].type = mujoco.mjtGeom.mjGEOM_BOX


def _collides(geom: mujoco.MjsGeom) -> bool:
    return bool(geom.contype or geom.conaffinity)


def _bulging_capsules(spec: mujoco.MjSpec, fitted: list[int]) -> list[int]:
    """The positions in ``spec.geoms`` among ``fitted`` (capsules fitted to meshes) of the
    capsules that reach more than :data:`CAPSULE_BULGE` past their mesh across their axis,
    from a compiled copy (its geoms are named there so that the copy's ids can be found)."""
    if not fitted:
        return []
    copy = spec.copy()
    copied = copy.geoms
    names = {index: f"mjx_arm_fit_{index}" for index in fitted}
    for index, name in names.items():
        copied[index].name = name
    model = copy.compile()
    return [
        index
        for index, name in names.items()
        if capsule_bulge(model, model.geom(name).id, copied[index].meshname) > CAPSULE_BULGE
    ]


def capsule_bulge(model: mujoco.MjModel, geom: int, mesh: str) -> float:
    """How far (m) fitted capsule ``geom`` of ``model`` reaches past the vertices of ``mesh``
    across its axis (its local x and y; negative: it stays inside). The capsule's frame is the
    mesh's principal frame, the one its vertices are stored in."""
    mesh_id = model.mesh(mesh).id
    start = model.mesh_vertadr[mesh_id]
    vertices = model.mesh_vert[start : start + model.mesh_vertnum[mesh_id]]  # (n, 3)
    radius = float(model.geom_size[geom][0])
    across = vertices[:, :2]
    return float(np.max(np.concatenate([radius - across.max(axis=0), radius + across.min(axis=0)])))
