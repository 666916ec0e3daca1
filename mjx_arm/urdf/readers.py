"""What an engine's URDF loader can read: the facts the validator's static checks ask of it.

Each engine that loads a URDF names its :class:`UrdfReader` in its row of the engine registry
(:mod:`mjx_arm.engines`, field ``urdf_reader``); the checks read these fields and never an
engine's name. MuJoCo's reader (:data:`MUJOCO`) is here, beside the converter it describes;
PyBullet's is in ``pybullet_ref.urdf_reader``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from mjx_arm.engines import engine, load
from mjx_arm.urdf.mesh_convert import CONVERTIBLE_FORMATS
from mjx_arm.urdf.meshes import MUJOCO_MESH_FORMATS

__all__ = ["MUJOCO", "UrdfReader", "readers_of"]


@dataclass(frozen=True)
class UrdfReader:
    """One engine's URDF loader, as the static checks see it.

    Attributes:
        label: how findings name the engine ("MuJoCo").
        mesh_formats: mesh file suffixes it reads, lower case with the dot (``".stl"``).
        converts_formats: collision mesh suffixes its converter turns into STL (with trimesh).
        drops_unreadable_visuals: a visual mesh it cannot read is left out (a warning, not an
            error: it only draws).
        max_line_bytes: bytes of one URDF line it reads whole; None: no limit.
        max_mesh_path_bytes: bytes of a mesh's absolute path it loads without crashing; None:
            no limit.
        undamped_note: what it does with a joint without ``<dynamics damping>`` (a warning's
            clause); empty: nothing worth a warning.
        min_damping: joint damping (N m s/rad or N s/m) below which it jitters; 0: no limit.
        sizes_actuators_from_limits: a continuous joint needs ``<limit effort velocity>``
            (its converter sizes the joint's velocity actuator from them).
        free_joint_root_only: a floating joint is an error (a free joint is allowed only on a
            body attached to the world).
        checks_every_inertia: every ``<inertia>`` is read, also of massless fixed links.
        invents_mass: a link without ``<inertial>`` gets 1 kg, so a massless link that
            collides needs its mass 0 written out.
        capsules_cylinders: a collision cylinder becomes a capsule (MJX collides no cylinder
            with boxes, spheres or meshes).
    """

    label: str
    mesh_formats: frozenset[str]
    converts_formats: frozenset[str] = frozenset()
    drops_unreadable_visuals: bool = False
    max_line_bytes: int | None = None
    max_mesh_path_bytes: int | None = None
    undamped_note: str = ""
    min_damping: float = 0.0
    sizes_actuators_from_limits: bool = False
    free_joint_root_only: bool = False
    checks_every_inertia: bool = False
    invents_mass: bool = False
    capsules_cylinders: bool = False

    def reads(self, suffix: str) -> bool:
        """Whether it reads a mesh with the lower-case ``suffix`` (``".dae"``) as it is."""
        return suffix in self.mesh_formats


MUJOCO = UrdfReader(
    label="MuJoCo",
    mesh_formats=MUJOCO_MESH_FORMATS,
    converts_formats=CONVERTIBLE_FORMATS,
    drops_unreadable_visuals=True,
    undamped_note="the converter injects its default damping for MuJoCo",
    sizes_actuators_from_limits=True,
    free_joint_root_only=True,
    checks_every_inertia=True,
    capsules_cylinders=True,
)


def readers_of(names: tuple[str, ...], min_damping: float | None = None) -> tuple[UrdfReader, ...]:
    """The readers of the engines ``names`` (registry rows), in that order.

    Args:
        names: engine names whose rows name a ``urdf_reader``.
        min_damping: replaces ``min_damping`` in every reader that has one (> 0); None keeps
            each reader's own.
    """
    readers = tuple(load(engine(name, "urdf_reader").urdf_reader) for name in names)
    if min_damping is None:
        return readers
    return tuple(replace(r, min_damping=min_damping) if r.min_damping else r for r in readers)
