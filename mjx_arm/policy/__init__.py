"""Exported policies: write them from a run directory, load and run them without jax.

>>> from mjx_arm import policy
>>> pi = policy.load("policy.npz")  # or "policy.onnx" (needs onnxruntime)
>>> action = pi(obs)  # Dict obs, state (22,), or a batch -> float32 (6,) in [-1, 1]

Importing this package and running a loaded policy imports numpy (and onnxruntime for ``.onnx``)
only; :func:`export_policy` reads Brax checkpoints and so imports jax when it is called.
(The function is not called ``export``: that name is the :mod:`mjx_arm.policy.export` module.)
"""

from __future__ import annotations

from pathlib import Path

from mjx_arm.inputs import require_file
from mjx_arm.policy.numpy_policy import (
    CONTRACT_VERSION,
    BasePolicy,
    ContractVersionError,
    NumpyPolicy,
    PolicyFileError,
)

__all__ = [
    "CONTRACT_VERSION",
    "BasePolicy",
    "ContractVersionError",
    "NumpyPolicy",
    "PolicyFileError",
    "export_policy",
    "load",
]


def load(path: str | Path, deterministic: bool = True, seed: int | None = None) -> BasePolicy:
    """Load an exported policy: ``.npz`` (numpy runtime) or ``.onnx`` (onnxruntime).

    Args:
        path: the policy file.
        deterministic: act with ``tanh(mean)`` (default); else sample the tanh-normal.
        seed: seed of the sampler when not deterministic.

    Returns:
        A callable from the Dict observation, ``state (22,)`` or a batch of either to a float32
        action ``(6,)`` / ``(N, 6)`` in [-1, 1].

    Raises:
        FileNotFoundError: no such file (an :class:`~mjx_arm.inputs.InputError`).
        PolicyFileError: not a policy file; ContractVersionError: another contract version.
    """
    path = require_file(path, "policy file")
    if path.suffix == ".onnx":
        from mjx_arm.policy.onnx_export import OnnxPolicy

        return OnnxPolicy(path, deterministic, seed)
    if path.suffix == ".npz":
        return NumpyPolicy.load(path, deterministic, seed)
    raise PolicyFileError(f"{path}: a policy file ends in .npz or .onnx")


def export_policy(run_dir: str | Path, output: str | Path, step: int | None = None) -> Path:
    """Export a run's policy (newest checkpoint, or ``step``) to ``output`` (.npz or .onnx)."""
    from mjx_arm.policy.export import export_run

    return export_run(run_dir, output, step)
