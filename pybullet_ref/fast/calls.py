"""The PyBullet client calls of every control step, bound once.

``BulletClient`` looks each method up and wraps it on every attribute access; an env that calls
six of them several times a substep binds them once per client instead.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:  # importing pybullet prints its build time; pybullet_ref.quiet silences it
    from pybullet_utils.bullet_client import BulletClient

__all__ = ["HotCalls"]


class HotCalls(NamedTuple):
    """The client calls of every step, bound once (``BulletClient`` rebinds them per access)."""

    get_joint_states: Callable
    get_link_state: Callable
    get_link_states: Callable
    inverse_dynamics: Callable
    mass_matrix: Callable
    set_motors: Callable
    step: Callable

    @classmethod
    def of(cls, client: BulletClient) -> HotCalls:
        """Bind the calls of ``client``."""
        return cls(
            client.getJointStates,
            client.getLinkState,
            client.getLinkStates,
            client.calculateInverseDynamics,
            client.calculateMassMatrix,
            client.setJointMotorControlArray,
            client.stepSimulation,
        )
