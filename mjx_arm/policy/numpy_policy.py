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

import json
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


def check_metadata(metadata: Mapping[str, Any], source: str) -> None:
    """Check a policy file's metadata: its format and contract version.

    Raises:
        PolicyFileError: not an mjx_arm policy file.
        ContractVersionError: written for another contract version.
    """
    if metadata.get("format") != FORMAT:
        raise PolicyFileError(f"{source} is not an mjx_arm policy file (format {FORMAT!r})")
    version = str(metadata.get("contract_version"))
    if version != CONTRACT_VERSION:
        raise ContractVersionError(
            f"{source} was exported for contract version {version!r}, but this runtime "
            f"implements contract version {CONTRACT_VERSION!r}: the observation or action "
            "layout differs. Export the run again with this version of mjx_arm "
            "(mjx-arm export RUN_DIR -o POLICY)."
        )


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

    # ------------------------------------------------------------------ to implement

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """The network output ``(N, 2 * action_size)``: mean, then pre-softplus scale.

        Args:
            state: raw (not yet normalised) observations ``(N, 22)``, float32.
        """
        raise NotImplementedError

    def mode(self, state: np.ndarray) -> np.ndarray:
        """The deterministic action ``(N, action_size)`` for ``state (N, 22)``."""
        params = self.distribution_params(state)
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
        if self.deterministic if deterministic is None else deterministic:
            action = self.mode(batch)
        else:
            action = self.sample(self.distribution_params(batch))
        action = np.clip(action, -1.0, 1.0).astype(np.float32)
        return action[0] if single else action

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
        super().__init__(metadata, deterministic, seed)
        name = self.metadata.get("activation", "swish")
        if name not in ACTIVATIONS:
            raise PolicyFileError(f"unknown activation {name!r}; known: {sorted(ACTIVATIONS)}")
        if self.metadata.get("distribution", "tanh_normal") != "tanh_normal":
            raise PolicyFileError(f"unsupported distribution {self.metadata['distribution']!r}")
        self.activation = ACTIVATIONS[name]
        self.mean = np.asarray(arrays["obs_mean"], dtype=np.float32)
        self.std = np.asarray(arrays["obs_std"], dtype=np.float32)
        self.layers = _layers(arrays)

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """Normaliser then MLP: ``(N, 22)`` -> ``(N, 2 * action_size)``, float32."""
        hidden = (np.asarray(state, dtype=np.float32) - self.mean) / self.std
        last = len(self.layers) - 1
        for i, (kernel, bias) in enumerate(self.layers):
            hidden = hidden @ kernel + bias
            if i != last:
                hidden = self.activation(hidden)
        return hidden

    @classmethod
    def load(cls, path: str | Path, deterministic: bool = True, seed: int | None = None):
        """Read a ``policy.npz`` written by :func:`mjx_arm.policy.export.export_run`.

        Raises:
            PolicyFileError: not a policy file; ContractVersionError: another contract version.
        """
        arrays, metadata = read_npz(path)
        return cls(arrays, metadata, deterministic, seed)


def _layers(arrays: Mapping[str, np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    layers, i = [], 0
    while f"kernel_{i}" in arrays:
        kernel = np.asarray(arrays[f"kernel_{i}"], dtype=np.float32)
        bias = np.asarray(arrays[f"bias_{i}"], dtype=np.float32)
        layers.append((kernel, bias))
        i += 1
    if not layers:
        raise PolicyFileError("the policy file holds no layers (kernel_0, bias_0, ...)")
    return layers


def read_npz(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Arrays and metadata of a ``policy.npz`` (checked for format and contract version)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise PolicyFileError(f"cannot read {path} as a policy .npz: {exc}") from exc
    if "metadata" not in arrays:
        raise PolicyFileError(f"{path} is not an mjx_arm policy file (no metadata)")
    metadata = json.loads(str(arrays.pop("metadata")))
    check_metadata(metadata, str(path))
    return arrays, metadata


def write_npz(path: str | Path, arrays: Mapping[str, np.ndarray], metadata: Mapping) -> Path:
    """Write a ``policy.npz``: the arrays plus the metadata as a JSON string."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
    payload["metadata"] = np.array(json.dumps(dict(metadata), sort_keys=True))
    with path.open("wb") as f:
        np.savez(f, **payload)
    return path
