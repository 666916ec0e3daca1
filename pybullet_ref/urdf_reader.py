"""What PyBullet's URDF loader reads, for the validator's static checks
(:class:`~mjx_arm.urdf.readers.UrdfReader`; named by PyBullet's row in ``pybullet_ref.engine``).

The limits behind it were measured on PyBullet 3.2 and are kept with the validator's others
(:mod:`mjx_arm.urdf.findings`).
"""

from mjx_arm.urdf.findings import MAX_LINE_BYTES, MAX_MESH_PATH_BYTES
from mjx_arm.urdf.readers import UrdfReader

__all__ = ["MESH_FORMATS", "READER"]

# PyBullet reads STL and OBJ, and Collada (.dae) through its own loader (only partly).
MESH_FORMATS = frozenset({".stl", ".obj", ".dae"})

READER = UrdfReader(
    label="PyBullet",
    mesh_formats=MESH_FORMATS,
    max_line_bytes=MAX_LINE_BYTES,
    max_mesh_path_bytes=MAX_MESH_PATH_BYTES,
    undamped_note="PyBullet runs it undamped, which jitters",
    min_damping=0.01,
    invents_mass=True,
)
