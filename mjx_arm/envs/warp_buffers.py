"""MuJoCo Warp's buffers for a task model: how big each must be, and the model changes Warp needs.

Warp sizes its buffers once, for the whole batch, where MJX's JAX implementation sizes each
env's arrays statically. The bounds here come from that static sizing (every geom pair the
contact filters allow), so a buffer sized from them cannot overflow:

- ``naconmax``: the contact pool that all envs of a batch share (contacts per env x batch).
- ``njmax``: constraint rows per env (all contacts and joint limits active at once).
- ``naccdmax``: collision pairs that go through Warp's convex collider (GJK/EPA) in one
  launch, per pair type, over the batch. Warp allocates its multi-contact scratch arrays with
  this many rows on every convex narrowphase call (a dozen arrays of up to ``2 x`` the largest
  mesh polygon count each); its default, ``naconmax``, made them 1-2.3 GB per call for a
  mesh-collision arm at 8,192 envs and ran an H200 out of memory. The bound is the model's
  largest count of allowed geom pairs of one convex type pair.
"""

from __future__ import annotations

import collections
import copy
from typing import Any, NamedTuple

import mujoco

# Warp's overflow bits (mujoco_warp OverflowType) that mean contacts or constraint rows were
# dropped: nefc > njmax (1), Jacobian non-zeros (2), broadphase (4), narrowphase (8), convex
# collider pairs (16, naccdmax), islands (128). Iteration limits (512, 1024) are expected with a
# fixed 2-iteration solver.
DROPPED_BITS = 1 | 2 | 4 | 8 | 16 | 128

_G = mujoco.mjtGeom
# The geom type pairs that MuJoCo Warp (mujoco-mjx 3.17) collides with its convex collider:
# every pair of convex shapes that has no dedicated function. Box-box is not among them here:
# :func:`warp_compatible` sends it to the box-box function, as C MuJoCo does.
CONVEX_PAIRS = frozenset(
    frozenset(int(kind) for kind in pair)
    for pair in (
        (_G.mjGEOM_SPHERE, _G.mjGEOM_ELLIPSOID),
        (_G.mjGEOM_SPHERE, _G.mjGEOM_MESH),
        (_G.mjGEOM_CAPSULE, _G.mjGEOM_ELLIPSOID),
        (_G.mjGEOM_CAPSULE, _G.mjGEOM_CYLINDER),
        (_G.mjGEOM_CAPSULE, _G.mjGEOM_MESH),
        (_G.mjGEOM_ELLIPSOID, _G.mjGEOM_ELLIPSOID),
        (_G.mjGEOM_ELLIPSOID, _G.mjGEOM_CYLINDER),
        (_G.mjGEOM_ELLIPSOID, _G.mjGEOM_BOX),
        (_G.mjGEOM_ELLIPSOID, _G.mjGEOM_MESH),
        (_G.mjGEOM_CYLINDER, _G.mjGEOM_CYLINDER),
        (_G.mjGEOM_CYLINDER, _G.mjGEOM_BOX),
        (_G.mjGEOM_CYLINDER, _G.mjGEOM_MESH),
        (_G.mjGEOM_BOX, _G.mjGEOM_MESH),
        (_G.mjGEOM_MESH, _G.mjGEOM_MESH),
    )
)


class ModelBounds(NamedTuple):
    """What one env of a model can produce at most.

    Attributes:
        contacts: contacts (every allowed geom pair times its collider's largest count).
        rows: constraint rows (all contacts and every limited joint).
        convex_pairs: allowed geom pairs of the most common convex type pair
            (:data:`CONVEX_PAIRS`), 0 where the model has none.
    """

    contacts: int
    rows: int
    convex_pairs: int


def model_bounds(mj_model: mujoco.MjModel) -> ModelBounds:
    """The :class:`ModelBounds` of ``mj_model``: contacts and rows read from MJX's JAX sizing of
    its arrays (their shapes only: nothing is built on a device, which took about a second on
    a GPU), convex pairs from the geom pairs that MJX's contact filters allow."""
    import jax
    from mujoco import mjx

    data = jax.eval_shape(lambda: mjx.make_data(mjx.put_model(mj_model, impl="jax"), impl="jax"))
    return ModelBounds(
        int(data._impl.contact.dist.shape[0]),
        int(data._impl.efc_J.shape[0]),
        convex_pair_count(mj_model),
    )


def convex_pair_count(mj_model: mujoco.MjModel) -> int:
    """The largest number of geom pairs of one convex type pair (:data:`CONVEX_PAIRS`) that the
    contact filters of ``mj_model`` allow (contype/conaffinity, parent and welded bodies,
    ``<exclude>``; plus every ``<pair>``), 0 where none is convex."""
    from mujoco.mjx._src.collision_driver import geom_pairs

    per_type: collections.Counter = collections.Counter()
    for g1, g2, _ in geom_pairs(mj_model):
        types = frozenset((int(mj_model.geom_type[g1]), int(mj_model.geom_type[g2])))
        if types in CONVEX_PAIRS:
            per_type[types] += 1
    return max(per_type.values(), default=0)


def warp_compatible(mj_model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``mj_model`` for MuJoCo Warp: without the options it rejects, and with box-box
    contacts through the box-box collider that C MuJoCo uses.

    - The converter disables MuJoCo's automatic reset of a diverged state (so that divergence
      shows as a non-finite state); Warp has no automatic reset and refuses the flag, so it is
      cleared.
    - C MuJoCo always collides two boxes with its dedicated box-box function. MuJoCo Warp sends
      box-box pairs through its general convex collider (GJK/EPA) unless native CCD is
      disabled, a flag that in Warp changes nothing else. Disabling it gives the same collider
      as the CPU engines that exported policies run in, and spares the convex kernel's compile
      (about 52 s on an H200) where boxes are a model's only convex pairs (the gripper arm's
      pads and cube).
    """
    model = copy.copy(mj_model)
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    return model


def overflow_message(count: float, buffers: dict[str, Any]) -> str:
    """The error text of a Warp buffer overflow in ``count`` envs (or env-steps)."""
    sizes = ", ".join(
        f"{key}={buffers.get(key)}" for key in ("naconmax_per_env", "njmax", "naccdmax_per_env")
    )
    return (
        f"MuJoCo Warp dropped contacts or constraint rows in {count:g} env(s): its buffers "
        f"({sizes}) are too small for this model and batch. Raise them with --set "
        "physics.naconmax_per_env=N physics.njmax=N physics.naccdmax_per_env=N (0 = the "
        "model's bound), or use physics.impl=jax."
    )
