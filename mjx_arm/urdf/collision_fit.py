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

A gripper's pads are fitted first (:func:`fit_pads`): a pad whose collision is a mesh gets the
box :mod:`mjx_arm.urdf.pad_fit` fits to it, the box PyBullet's copy of the URDF gets too
(:mod:`pybullet_ref.pads`), so MuJoCo, MJX and PyBullet press the object with the same pad.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_arm.urdf.errors import ConversionError
from mjx_arm.urdf.pad_fit import PAD_GEOM_SUFFIX, REST_MESH_SUFFIX, FittedPads

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


def fit_pads(spec: mujoco.MjSpec, pads: FittedPads | None) -> None:
    """Replace the collision meshes of each fitted pad link of ``spec`` by its fitted box
    (named ``LINK`` + :data:`~mjx_arm.urdf.pad_fit.PAD_GEOM_SUFFIX`) and the kept parts of its
    cut meshes (new meshes ``LINK`` + :data:`~mjx_arm.urdf.pad_fit.REST_MESH_SUFFIX` + a
    number, each collided through its hull), with the replaced geoms' contact settings."""
    if pads is None:
        return
    for link in sorted(pads.replaced):
        body = spec.body(link)
        if body is None:
            raise ConversionError(f"pad link {link!r} is not a body of the model")
        meshes = [g for g in body.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH and _collides(g)]
        if not meshes:
            continue
        template = meshes[0]
        box = pads.box(link)
        if box is not None:
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, np.ascontiguousarray(box.rotation).ravel())
            added = _pad_geom(body, template, mujoco.mjtGeom.mjGEOM_BOX)
            added.name = f"{link}{PAD_GEOM_SUFFIX}"
            added.pos, added.quat, added.size = list(box.centre), list(quat), list(box.half)
        rests = [vertices for name, vertices in pads.rests if name == link]
        for i, vertices in enumerate(rests):
            mesh = spec.add_mesh()
            mesh.name = f"{link}{REST_MESH_SUFFIX}{i}"
            mesh.uservert = np.asarray(vertices, float).ravel().tolist()
            _pad_geom(body, template, mujoco.mjtGeom.mjGEOM_MESH).meshname = mesh.name
        for geom in meshes:
            spec.delete(geom)
    _exclude_hand(spec, pads)


def _exclude_hand(spec: mujoco.MjSpec, pads: FittedPads) -> None:
    """No contacts between a fitted pad and the gripper's other links (its hand and every link
    below the hand): a box around a finger overlaps the knuckles it turns with."""
    hand = spec.body(pads.hand) if pads.hand else None
    if hand is None:
        return
    below, stack = [], [hand]
    while stack:
        body = stack.pop()
        below.append(body.name)
        stack.extend(body.bodies)
    for link in sorted(pads.replaced):
        for other in below:
            if other != link:
                exclude = spec.add_exclude()
                exclude.bodyname1, exclude.bodyname2 = link, other


def _pad_geom(body: mujoco.MjsBody, template: mujoco.MjsGeom, kind) -> mujoco.MjsGeom:
    """A new collision geom of ``kind`` on ``body`` with ``template``'s contact settings."""
    geom = body.add_geom()
    geom.type = kind
    for attribute in ("contype", "conaffinity", "condim", "group", "priority", "margin", "gap"):
        setattr(geom, attribute, getattr(template, attribute))
    geom.friction = list(template.friction)
    geom.solref, geom.solimp = list(template.solref), list(template.solimp)
    return geom
