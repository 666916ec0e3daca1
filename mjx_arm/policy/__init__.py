"""Exported policies: write them from a run directory, load and run them without jax.

>>> from mjx_arm import policy
>>> pi = policy.load("policy.npz")  # or "policy.onnx" (needs onnxruntime)
>>> action = pi(obs)  # Dict obs, state (22,), or a batch -> float32 (6,) in [-1, 1]

Importing this package and running a loaded policy imports numpy (and onnxruntime for ``.onnx``)
only; :func:`export_policy` reads Brax checkpoints and so imports jax when it is called.
(The function is not called ``export``: that name is the :mod:`mjx_arm.policy.export` module.)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from mjx_arm.inputs import MiB, read_npz_members, require_file
from mjx_arm.policy.numpy_policy import (
    CONTRACT_VERSION,
    BasePolicy,
    ContractVersionError,
    NonFiniteActionError,
    NumpyPolicy,
    PolicyFileError,
)

# What a policy .npz may unpack to. Exported policies hold at most 180 KiB in all, 64 KiB in
# their largest member (a 128 x 128 float32 kernel, benchmarks/results): the limits leave a
# margin of thousands (a 8192 x 8192 float32 kernel is 256 MiB) and stop a file whose member
# would unpack to gigabytes before it is unpacked. Members a policy does not use are never read.
POLICY_MEMBER_BYTES = 256 * MiB
POLICY_TOTAL_BYTES = 512 * MiB
# The metadata member, a JSON text of a few kB: parsed whole, so bounded on its own (a 256 MiB
# text of "[0,0,...]" would parse to gigabytes of Python numbers).
POLICY_METADATA_BYTES = MiB


def read_policy_members(path: Path, wanted: Callable[[str], bool]) -> dict[str, Any]:
    """The members ``wanted`` of a policy .npz, each checked against the limits above (the
    metadata against :data:`POLICY_METADATA_BYTES`)."""
    groups = (
        (lambda k: k != "metadata" and wanted(k), POLICY_MEMBER_BYTES),
        (lambda k: k == "metadata" and wanted(k), POLICY_METADATA_BYTES),
    )
    members: dict[str, Any] = {}
    for chosen, limit in groups:
        members |= read_npz_members(
            path,
            "policy",
            chosen,
            max_member_bytes=limit,
            max_total_bytes=POLICY_TOTAL_BYTES,
            error=PolicyFileError,
        )
    return members


__all__ = [
    "CONTRACT_VERSION",
    "BasePolicy",
    "ContractVersionError",
    "NonFiniteActionError",
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
        PolicyFileError: not a policy file; ContractVersionError: another contract version;
            OversizedInputError: a member that would unpack to more than its limit.
    """
    path = require_file(path, "policy file")
    if path.suffix == ".onnx":
        from mjx_arm.policy.onnx_export import OnnxPolicy

        return OnnxPolicy(path, deterministic, seed)
    if path.suffix == ".npz":
        return NumpyPolicy.load(path, deterministic, seed, read_policy_members)
    raise PolicyFileError(f"{path}: a policy file ends in .npz or .onnx")


def export_policy(run_dir: str | Path, output: str | Path, step: int | None = None) -> Path:
    """Export a run's policy (newest checkpoint, or ``step``) to ``output`` (.npz or .onnx)."""
    from mjx_arm.policy.export import export_run

    return export_run(run_dir, output, step)
