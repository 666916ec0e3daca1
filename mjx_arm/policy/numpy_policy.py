"""Run an exported policy with numpy alone: no jax, brax or flax.

This module imports nothing but the standard library and numpy, so it can be copied on its own
to a robot computer. An exported ``policy.npz`` holds:

- ``obs_mean (22,)``, ``obs_std (22,)``: the observation normaliser, ``(obs - mean) / std``;
- ``kernel_I (n_in, n_out)``, ``bias_I (n_out,)`` for each dense layer ``I = 0, 1, ...``;
- ``metadata``: a JSON string with the contract version, the observation layout, the
  activation, the action distribution, the action scaling and the training config.

The network is Brax PPO's policy: an MLP with the activation after every hidden layer and a last
layer of ``2 * action_size`` outputs, the mean and the pre-softplus scale of a normal
distribution whose samples pass through ``tanh``. The deterministic action is ``tanh(mean)``.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
import zlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

# Version of the observation/action contract a policy file is written for. Bump it whenever
# the observation layout, its units or the action's meaning change.
CONTRACT_VERSION = "1"
FORMAT = "mjx_arm.policy"
# Brax's NormalTanhDistribution: scale = softplus(raw) + MIN_STD.
MIN_STD = 1e-3


class PolicyFileError(ValueError):
    """A file is not an mjx_arm policy, or is broken."""


class ContractVersionError(PolicyFileError):
    """A policy file was exported for another contract version than this runtime's."""


class NonFiniteActionError(PolicyFileError):
    """A policy computed a NaN or infinite action: damaged weights or a diverged training."""


def _swish(x: np.ndarray) -> np.ndarray:
    # x * sigmoid(x), written with tanh so that no exp overflows
    return 0.5 * x * (1.0 + np.tanh(0.5 * x))


ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "swish": _swish,
    "silu": _swish,
    "relu": lambda x: np.maximum(x, 0.0),
    "tanh": np.tanh,
    "linear": lambda x: x,
}


def _softplus(x: np.ndarray) -> np.ndarray:
    return np.logaddexp(x, 0.0)


def check_metadata(metadata: Any, source: str) -> None:
    """Check a policy file's metadata: its format, contract version and the fields a runtime
    reads (observation layout, action size and scaling, activation, distribution).

    Raises:
        PolicyFileError: not an mjx_arm policy file, or a field missing or of the wrong type.
        ContractVersionError: written for another contract version.
    """
    if not isinstance(metadata, Mapping) or metadata.get("format") != FORMAT:
        raise PolicyFileError(f"{source} is not an mjx_arm policy file (format {FORMAT!r})")
    version = str(metadata.get("contract_version"))
    if version != CONTRACT_VERSION:
        raise ContractVersionError(_version_message(source, version))
    problems = _metadata_problems(metadata)
    if problems:
        raise PolicyFileError(
            f"{source} is a damaged policy file: {'; '.join(problems)}. Export it again "
            "(mjx-arm export RUN_DIR -o POLICY)"
        )


def _version_message(source: str, version: str) -> str:
    if version.isascii() and version.isdigit() and int(version) > int(CONTRACT_VERSION):
        return (
            f"{source} was exported for contract version {version!r}, newer than this "
            f"runtime's {CONTRACT_VERSION!r}: upgrade mjx_arm to run it"
        )
    return (
        f"{source} was exported for contract version {version!r}, but this runtime "
        f"implements contract version {CONTRACT_VERSION!r}: the observation or action "
        "layout differs. Export the run again with this version of mjx_arm "
        "(mjx-arm export RUN_DIR -o POLICY)."
    )


def _is_int(value: Any, low: int = 0) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value)


def _metadata_problems(meta: Mapping[str, Any]) -> list[str]:
    """What is wrong with the fields a runtime reads (empty: nothing)."""
    problems = []
    layout = meta.get("obs_layout")
    pairs = isinstance(layout, list) and all(
        isinstance(e, list) and len(e) == 2 and isinstance(e[0], str) and _is_int(e[1], 1)
        for e in layout
    )
    if not layout or not pairs:
        problems.append("obs_layout must list [name, size] pairs")
    elif len({e[0] for e in layout}) != len(layout):
        problems.append("obs_layout names a key twice")
    if not _is_int(meta.get("action_size"), 1):
        problems.append("action_size must be a whole number >= 1")
    if not _is_number(meta.get("action_scale")):
        problems.append("action_scale must be a finite number")
    v_max = meta.get("v_max")
    if not isinstance(v_max, list) or not all(_is_number(v) for v in v_max):
        problems.append("v_max must list finite numbers")
    speeds = meta.get("joint_speeds", v_max)  # files before joint_speeds: from v_max
    if not isinstance(speeds, list) or not all(_is_number(v) for v in speeds):
        problems.append("joint_speeds must list finite numbers")
    elif isinstance(v_max, list) and len(speeds) != len(v_max):
        problems.append(f"joint_speeds has {len(speeds)} entries, v_max {len(v_max)}")
    activation = meta.get("activation", "swish")
    if not isinstance(activation, str) or activation not in ACTIVATIONS:
        problems.append(f"unknown activation {activation!r}; known: {sorted(ACTIVATIONS)}")
    if meta.get("distribution", "tanh_normal") != "tanh_normal":
        problems.append(f"unsupported distribution {meta.get('distribution')!r}")
    clip = meta.get("obs_clip", 0.0)  # files before obs_clip: no clip
    if not _is_number(clip) or clip < 0:
        problems.append("obs_clip must be a finite number >= 0")
    if not isinstance(meta.get("config", {}), Mapping):
        problems.append("config must be a table")
    if not isinstance(meta.get("task", ""), str):
        problems.append("task must be a text")
    if "ctrl_dt" in meta and not (_is_number(meta["ctrl_dt"]) and meta["ctrl_dt"] > 0):
        problems.append(f"ctrl_dt must be a number of seconds > 0, not {meta['ctrl_dt']!r:.40}")
    return problems + _arm_problems(meta.get("arm", {}), v_max)


def _arm_problems(arm: Any, v_max: Any) -> list[str]:
    """What is wrong with a policy's arm record (its joints, config and model hash)."""
    if not isinstance(arm, Mapping):
        return ["arm must be a table"]
    if not arm:
        return []  # files from before arm records: the shipped arm
    names = arm.get("joint_names")
    problems = []
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        problems.append("arm.joint_names must list joint names")
    elif isinstance(v_max, list) and len(v_max) != len(names):
        problems.append(f"v_max has {len(v_max)} entries for {len(names)} joints")
    if not isinstance(arm.get("config", {}), Mapping):
        problems.append("arm.config must be a table")
    if not isinstance(arm.get("model_hash", ""), str):
        problems.append("arm.model_hash must be a text")
    return problems


def check_arrays(arrays: Mapping[str, np.ndarray], metadata: Mapping[str, Any], source: str):
    """Check a policy's normaliser and layers against its metadata: shapes that chain from the
    observation (``obs_size``) to the distribution params (``2 * action_size``), finite
    numbers, a positive ``obs_std``.

    Returns:
        The layers ``[(kernel (n_in, n_out), bias (n_out,)), ...]``, float32.

    Raises:
        PolicyFileError: a missing array, a shape that does not fit, a non-finite number.
    """
    obs_size = sum(int(n) for _, n in metadata["obs_layout"])
    outputs = 2 * int(metadata["action_size"])
    try:
        normaliser = [_array(arrays, k, (obs_size,)) for k in ("obs_mean", "obs_std")]
        if not np.all(normaliser[1] > 0):
            raise ValueError("obs_std must be > 0")
        layers, width, i = [], obs_size, 0
        while f"kernel_{i}" in arrays or i == 0:
            kernel = _array(arrays, f"kernel_{i}", (width, None))
            width = kernel.shape[1]
            layers.append((kernel, _array(arrays, f"bias_{i}", (width,))))
            i += 1
        if width != outputs:
            raise ValueError(f"the last layer has {width} outputs, not 2 * action_size = {outputs}")
    except ValueError as err:
        raise PolicyFileError(
            f"{source}: {err} (observation {obs_size}, actions {outputs // 2}); export the "
            "policy again (mjx-arm export RUN_DIR -o POLICY)"
        ) from err
    return layers


def _array(arrays: Mapping[str, np.ndarray], key: str, shape: tuple) -> np.ndarray:
    """``arrays[key]`` as float32, checked for ``shape`` (None: any size) and finite values.

    Raises:
        ValueError: missing, of another shape or type, or not finite.
    """
    if key not in arrays:
        raise ValueError(f"it has no {key}")
    value = np.asarray(arrays[key])
    fits = value.ndim == len(shape) and all(
        s in (None, n) for s, n in zip(shape, value.shape, strict=True)
    )
    if not fits or value.dtype.kind not in "fiu":
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise ValueError(f"{key} has shape {value.shape} ({value.dtype}), expected ({want})")
    value = value.astype(np.float32)
    if not np.all(np.isfinite(value)):
        raise ValueError(f"{key} holds NaN or infinite numbers")
    return value


class BasePolicy:
    """A deterministic-by-default policy on the contract's observations.

    Call it with the Dict observation (values ``(22,)`` in total), the flat ``state (22,)``, or a
    batch of either (``(N, 22)`` or a Dict of ``(N, k)`` arrays); it returns a float32 action
    ``(6,)`` or ``(N, 6)`` in [-1, 1].

    Args:
        metadata: the file's metadata (contract version, layout, action scaling, config).
        deterministic: return ``tanh(mean)``; otherwise sample the tanh-normal distribution.
        seed: seed of the sampler when not deterministic.
    """

    def __init__(
        self, metadata: Mapping[str, Any], deterministic: bool = True, seed: int | None = None
    ) -> None:
        self.metadata = dict(metadata)
        self.deterministic = deterministic
        self.rng = np.random.default_rng(seed)
        self.obs_layout = [(str(k), int(n)) for k, n in self.metadata["obs_layout"]]
        self.obs_size = sum(n for _, n in self.obs_layout)
        self.action_size = int(self.metadata["action_size"])
        self.observation_steps = 0  # calls so far: the step a non-finite action is reported at

    # ------------------------------------------------------------------ to implement

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """The network output ``(N, 2 * action_size)``: mean, then pre-softplus scale.

        Args:
            state: raw (not yet normalised) observations ``(N, 22)``, float32.
        """
        raise NotImplementedError

    def mode(self, state: np.ndarray) -> np.ndarray:
        """The deterministic action ``(N, action_size)`` for ``state (N, 22)``."""
        params = self.check_finite(self.distribution_params(state))
        return np.tanh(params[:, : self.action_size])

    # ------------------------------------------------------------------ public API

    def __call__(self, obs: Any, deterministic: bool | None = None) -> np.ndarray:
        """The action for one observation or a batch, float32 in [-1, 1].

        Args:
            obs: a Dict observation, the flat ``state (22,)``, or a batch ``(N, 22)`` / Dict of
                ``(N, k)`` arrays.
            deterministic: override the policy's default for this call.

        Returns:
            ``(action_size,)`` for a single observation, ``(N, action_size)`` for a batch.
        """
        state = self.flatten(obs)
        single = state.ndim == 1
        batch = state[None] if single else state
        self.observation_steps += 1
        with np.errstate(over="ignore", invalid="ignore"):  # reported by check_finite instead
            if self.deterministic if deterministic is None else deterministic:
                action = self.mode(batch)
            else:
                action = self.sample(self.check_finite(self.distribution_params(batch)))
        action = np.clip(self.check_finite(action), -1.0, 1.0).astype(np.float32)
        return action[0] if single else action

    def check_finite(self, values: np.ndarray) -> np.ndarray:
        """``values`` (network outputs or actions) when all are finite.

        Raises:
            NonFiniteActionError: a NaN or infinite value, named with the observation step.
        """
        values = np.asarray(values)
        if not np.all(np.isfinite(values)):
            raise NonFiniteActionError(
                f"the policy produced a non-finite action (NaN or inf) at observation step "
                f"{self.observation_steps}: the policy file is likely damaged or its training "
                "diverged; export it again from a healthy checkpoint (mjx-arm export RUN_DIR "
                "-o POLICY)"
            )
        return values

    def sample(self, params: np.ndarray) -> np.ndarray:
        """A tanh-normal sample ``(N, action_size)`` from distribution params ``(N, 2 * A)``."""
        loc, raw_scale = params[:, : self.action_size], params[:, self.action_size :]
        scale = _softplus(raw_scale) + MIN_STD
        return np.tanh(loc + scale * self.rng.standard_normal(loc.shape))

    def flatten(self, obs: Any) -> np.ndarray:
        """Observation(s) as float32 ``state``, ``(22,)`` or ``(N, 22)``.

        Raises:
            ValueError: a key is missing or the size is not the contract's.
        """
        if isinstance(obs, Mapping):
            missing = [k for k, _ in self.obs_layout if k not in obs]
            if missing:
                raise ValueError(f"observation lacks keys {missing}")
            parts = [np.asarray(obs[k], dtype=np.float32) for k, _ in self.obs_layout]
            state = np.concatenate(parts, axis=-1)
        else:
            state = np.asarray(obs, dtype=np.float32)
        if state.ndim not in (1, 2) or state.shape[-1] != self.obs_size:
            raise ValueError(
                f"observation must have shape ({self.obs_size},) or (N, {self.obs_size}), "
                f"got {state.shape}"
            )
        return state

    def joint_velocity_targets(self, action: np.ndarray) -> np.ndarray:
        """Joint velocity targets (rad/s) of ``action (..., n)``: ``a * joint_speeds`` (files
        older than ``joint_speeds``: ``a * action_scale * v_max``, what they trained with)."""
        scale = self.metadata.get("joint_speeds")
        if scale is None:
            scale = float(self.metadata["action_scale"]) * np.asarray(self.metadata["v_max"])
        scale = np.asarray(scale, dtype=np.float64)
        return np.asarray(action, dtype=np.float64) * scale

    @property
    def config(self) -> dict[str, Any]:
        """The training run's config (``config.json``: train, task, convert)."""
        return dict(self.metadata.get("config", {}))

    @property
    def task(self) -> str:
        """The task the policy was trained on ("reach" or "touch")."""
        return str(self.metadata.get("task", self.config.get("task", {}).get("task", "")))


class NumpyPolicy(BasePolicy):
    """An exported Brax PPO policy evaluated with numpy.

    Args:
        arrays: ``obs_mean``, ``obs_std``, ``kernel_I``, ``bias_I`` (see the module docstring).
        metadata: the file's metadata.
        deterministic: see :class:`BasePolicy`.
        seed: see :class:`BasePolicy`.
    """

    def __init__(
        self,
        arrays: Mapping[str, np.ndarray],
        metadata: Mapping[str, Any],
        deterministic: bool = True,
        seed: int | None = None,
    ) -> None:
        check_metadata(metadata, "the policy")
        super().__init__(metadata, deterministic, seed)
        self.activation = ACTIVATIONS[self.metadata.get("activation", "swish")]
        self.layers = check_arrays(arrays, self.metadata, "the policy")
        self.mean = np.asarray(arrays["obs_mean"], dtype=np.float32)
        self.std = np.asarray(arrays["obs_std"], dtype=np.float32)
        self.clip = float(self.metadata.get("obs_clip", 0.0))

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """Normaliser (clipped to ``+-obs_clip`` where the file sets one) then MLP: ``(N, 22)``
        -> ``(N, 2 * action_size)``, float32."""
        hidden = (np.asarray(state, dtype=np.float32) - self.mean) / self.std
        if self.clip > 0:
            hidden = np.clip(hidden, -self.clip, self.clip)
        last = len(self.layers) - 1
        for i, (kernel, bias) in enumerate(self.layers):
            hidden = hidden @ kernel + bias
            if i != last:
                hidden = self.activation(hidden)
        return hidden

    @classmethod
    def load(
        cls,
        path: str | Path,
        deterministic: bool = True,
        seed: int | None = None,
        read_members: MemberReader | None = None,
    ):
        """Read a ``policy.npz`` written by :func:`mjx_arm.policy.export.export_run`
        (``read_members``: see :func:`read_npz`).

        Raises:
            PolicyFileError: not a policy file; ContractVersionError: another contract version.
        """
        arrays, metadata = read_npz(path, read_members)
        return cls(arrays, metadata, deterministic, seed)


# (path, wanted member names) -> the arrays of those members
MemberReader = Callable[[Path, Callable[[str], bool]], Mapping[str, np.ndarray]]


def is_policy_member(name: str) -> bool:
    """Whether a policy runtime reads the ``.npz`` member ``name``: the metadata, the
    normaliser, the layers; any other member is never unpacked."""
    layer = re.fullmatch(r"(kernel|bias)_\d{1,3}", name) is not None
    return layer or name in ("metadata", "obs_mean", "obs_std")


def read_npz(
    path: str | Path, read_members: MemberReader | None = None
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Arrays and metadata of a ``policy.npz``, checked: format, contract version, fields,
    shapes and finite weights. Only the members :func:`is_policy_member` names are read.

    Args:
        path: the file.
        read_members: the reader of the members; :func:`mjx_arm.policy.load` passes
            :func:`mjx_arm.inputs.read_npz_members`, which checks each member's size before
            unpacking it. The default, for this file copied on its own, is ``numpy.load``.

    Raises:
        PolicyFileError: not a readable policy file (truncated, not a zip, not ours, damaged).
        ContractVersionError: another contract version.
    """
    path = Path(path)
    arrays = dict(read_members(path, is_policy_member) if read_members else _np_load(path))
    if "metadata" not in arrays:
        raise PolicyFileError(f"{path} is not an mjx_arm policy file (no metadata)")
    try:
        metadata = json.loads(str(arrays.pop("metadata")))
    except (ValueError, RecursionError) as exc:
        raise PolicyFileError(f"{path}: its metadata is not valid JSON ({exc})") from exc
    check_metadata(metadata, str(path))
    check_arrays(arrays, metadata, str(path))
    return arrays, metadata


# What a member may unpack to in the standalone reader (the zip directory's sizes, checked
# before numpy unpacks it): :mod:`mjx_arm.policy` reads with the same limits and more checks.
MAX_MEMBER_BYTES, MAX_METADATA_BYTES = 256 * 2**20, 2**20


def _np_load(path: Path) -> dict[str, np.ndarray]:
    """The policy members of an ``.npz``, with ``numpy.load`` (no pickles), each refused when
    the zip directory says it unpacks to more than its limit."""
    try:
        with np.load(path, allow_pickle=False) as data:
            for info in data.zip.infolist():
                limit = MAX_METADATA_BYTES if info.filename == "metadata.npy" else MAX_MEMBER_BYTES
                if is_policy_member(info.filename[:-4]) and info.file_size > limit:
                    raise PolicyFileError(
                        f"{path}: member {info.filename!r} unpacks to {info.file_size:,} bytes, "
                        f"over the limit of {limit:,}: not an exported policy"
                    )
            return {k: data[k] for k in data.files if is_policy_member(k)}
    except PolicyFileError:
        raise
    except (
        OSError,
        ValueError,
        EOFError,
        KeyError,
        MemoryError,
        zipfile.BadZipFile,
        zlib.error,
    ) as exc:
        raise PolicyFileError(
            f"cannot read {path} as a policy .npz (truncated or not an exported policy?): "
            f"{type(exc).__name__}: {exc}"
        ) from exc


def npz_bytes(arrays: Mapping[str, np.ndarray], metadata: Mapping) -> bytes:
    """The bytes of a ``policy.npz``: the arrays (float32) plus the metadata as a JSON string."""
    payload = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
    payload["metadata"] = np.array(json.dumps(dict(metadata), sort_keys=True))
    buffer = io.BytesIO()
    np.savez(buffer, **payload)
    return buffer.getvalue()


def write_npz(path: str | Path, arrays: Mapping[str, np.ndarray], metadata: Mapping) -> Path:
    """Write a ``policy.npz`` (:func:`npz_bytes`); :func:`mjx_arm.policy.export.export_run`
    writes it atomically instead."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(npz_bytes(arrays, metadata))
    return path
