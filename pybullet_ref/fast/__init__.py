"""The PyBullet env's per-step work in Python floats: the client calls bound once
(:mod:`~pybullet_ref.fast.calls`), three-vectors and rotations (:mod:`~pybullet_ref.fast.vec3`).
"""
