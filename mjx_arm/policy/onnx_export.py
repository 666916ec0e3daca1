"""The policy as an ONNX graph, and a runtime for it on onnxruntime.

The graph takes ``state`` ``(batch, 22)`` float32 and has two outputs: ``action``
``(batch, 6)``, the deterministic action ``tanh(mean)``, and ``distribution_params``
``(batch, 12)``, the raw network output (mean, pre-softplus scale) for sampling. The metadata
(contract version, layout, action scaling, training config) is stored as JSON in the model's
``metadata_props`` under the key ``mjx_arm``.

Writing needs the ``onnx`` package, running needs ``onnxruntime`` (``pip install mjx_arm[onnx]``);
neither needs jax.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mjx_arm.inputs import InputError, read_bytes, write_atomic
from mjx_arm.policy import onnx_checks as checks
from mjx_arm.policy.numpy_policy import BasePolicy, PolicyFileError
from mjx_arm.policy.onnx_wire import check_encoding

OPSET = 17
IR_VERSION = 8  # readable by onnxruntime >= 1.10
METADATA_KEY = checks.METADATA_KEY
INPUT, ACTION, PARAMS = "state", checks.ACTION, checks.PARAMS


def _activation_nodes(helper, name: str, x: str, out: str) -> list:
    """Nodes computing ``out = activation(x)``."""
    if name in ("swish", "silu"):
        return [
            helper.make_node("Sigmoid", [x], [f"{x}_sig"]),
            helper.make_node("Mul", [x, f"{x}_sig"], [out]),
        ]
    ops = {"relu": "Relu", "tanh": "Tanh", "linear": "Identity"}
    if name not in ops:
        raise ValueError(f"no ONNX form of activation {name!r}")
    return [helper.make_node(ops[name], [x], [out])]


def build_model(arrays: Mapping[str, np.ndarray], metadata: Mapping[str, Any]):
    """The ONNX ``ModelProto`` of a policy (see the module docstring for its inputs/outputs)."""
    onnx = _require("onnx")
    from onnx import TensorProto, helper, numpy_helper

    n_layers = sum(1 for k in arrays if k.startswith("kernel_"))
    action_size = int(metadata["action_size"])
    inits = {k: np.asarray(v, np.float32) for k, v in arrays.items()}
    inits.update(
        slice_starts=np.array([0], np.int64),
        slice_ends=np.array([action_size], np.int64),
        slice_axes=np.array([1], np.int64),
    )
    clip = float(metadata.get("obs_clip", 0.0))
    if clip > 0:  # the normalised observation clipped as in training
        inits.update(clip_low=np.array(-clip, np.float32), clip_high=np.array(clip, np.float32))
    nodes = _nodes(helper, n_layers, metadata["activation"], clip > 0)
    obs_size = int(inits["obs_mean"].shape[0])
    n_params = int(inits[f"bias_{n_layers - 1}"].shape[0])
    graph = helper.make_graph(
        nodes,
        "mjx_arm_policy",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["batch", obs_size])],
        [
            helper.make_tensor_value_info(ACTION, TensorProto.FLOAT, ["batch", action_size]),
            helper.make_tensor_value_info(PARAMS, TensorProto.FLOAT, ["batch", n_params]),
        ],
        initializer=[numpy_helper.from_array(v, name=k) for k, v in inits.items()],
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="mjx_arm",
        doc_string="Deterministic action = tanh(mean) of a Brax PPO tanh-normal policy.",
    )
    model.ir_version = IR_VERSION
    helper.set_model_props(model, {METADATA_KEY: json.dumps(dict(metadata), sort_keys=True)})
    onnx.checker.check_model(model)
    return model


def _nodes(helper: Any, n_layers: int, activation: str, clip: bool = False) -> list:
    """The graph's nodes: normalise the observation (then clip it to ``clip_low``,
    ``clip_high`` where ``clip``), ``n_layers`` dense layers (``activation`` between them), then
    ``tanh`` of the first ``action_size`` outputs (the mean)."""
    normalised = "normalised" if clip else "h0"
    nodes = [
        helper.make_node("Sub", [INPUT, "obs_mean"], ["centred"]),
        helper.make_node("Div", ["centred", "obs_std"], [normalised]),
    ]
    if clip:
        nodes.append(helper.make_node("Clip", [normalised, "clip_low", "clip_high"], ["h0"]))
    for i in range(n_layers):
        last = i == n_layers - 1
        nodes.append(helper.make_node("MatMul", [f"h{i}", f"kernel_{i}"], [f"mm{i}"]))
        z = PARAMS if last else f"z{i}"
        nodes.append(helper.make_node("Add", [f"mm{i}", f"bias_{i}"], [z]))
        if not last:
            nodes += _activation_nodes(helper, activation, z, f"h{i + 1}")
    nodes += [
        helper.make_node("Slice", [PARAMS, "slice_starts", "slice_ends", "slice_axes"], ["loc"]),
        helper.make_node("Tanh", ["loc"], [ACTION]),
    ]
    return nodes


class OnnxMissingError(InputError, ImportError):
    """An ``.onnx`` file asked for where onnx or onnxruntime is not installed."""


def _require(module: str):
    """Import ``module`` or explain how to install it.

    Raises:
        OnnxMissingError: it is not installed (an ImportError and an input error).
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise OnnxMissingError(
            f"{module} is not installed: pip install 'mjx_arm[onnx]' (onnx + onnxruntime), "
            "or use a .npz policy"
        ) from exc


def write_onnx(path: str | Path, arrays: Mapping[str, np.ndarray], metadata: Mapping) -> Path:
    """Write the policy as an ONNX file (atomically: a failure leaves an older file whole);
    returns the path."""
    path = Path(path)
    write_atomic(build_model(arrays, metadata).SerializeToString(), path)
    return path


def read_checked_model(path: str | Path) -> tuple[bytes, dict[str, Any], str, int]:
    """Read an ONNX policy and check it before onnxruntime opens it: the file's size (read
    under :data:`~mjx_arm.policy.onnx_checks.MAX_FILE_BYTES`), its encoding before parsing
    (:mod:`mjx_arm.policy.onnx_wire`: entries, structure, no local functions), then the parsed
    graph (:mod:`mjx_arm.policy.onnx_checks`: definitions, contract, element limit, bounded
    shapes, estimated work).

    Returns:
        (the file's bytes, its checked metadata, the input's name, the input's rank).

    Raises:
        OversizedInputError: a file over the size limit; PolicyFileError: not an ONNX policy;
            OnnxContractError: other inputs or outputs; OnnxGraphLimitError: over a limit
            (OnnxSizeError before parsing, OnnxWorkLimitError on the work) or a shape that
            cannot be bounded.
    """
    onnx = _require("onnx")
    path = Path(path)
    data = read_bytes(path, "ONNX policy", checks.MAX_FILE_BYTES)
    check_encoding(onnx, data, str(path))
    try:
        model = onnx.load_model_from_string(data)
    except Exception as exc:  # protobuf's DecodeError and onnx's own errors
        raise PolicyFileError(f"cannot read {path} as an ONNX model: {exc}") from exc
    metadata = checks.model_metadata(model, str(path))
    checks.check_definitions(onnx, model, str(path))
    name, rank = checks.check_contract(onnx, model, metadata, str(path))
    checks.check_bounded(onnx, model, name, str(path))
    return data, metadata, name, rank


class OnnxPolicy(BasePolicy):
    """An exported policy run by onnxruntime (CPU).

    Args:
        path: the ``.onnx`` file.
        deterministic: see :class:`~mjx_arm.policy.numpy_policy.BasePolicy`.
        seed: seed of the sampler when not deterministic.

    Raises:
        PolicyFileError: not an mjx_arm policy; ContractVersionError: another contract version;
            OnnxContractError, OnnxGraphLimitError: see :func:`read_checked_model`. Running it
            raises OnnxRunError when onnxruntime fails, NonFiniteActionError on NaN or inf.
    """

    def __init__(self, path: str | Path, deterministic: bool = True, seed: int | None = None):
        ort = _require("onnxruntime")
        data, metadata, self.input_name, self.input_rank = read_checked_model(path)
        try:
            session = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise PolicyFileError(f"cannot read {path} as an ONNX model: {exc}") from exc
        super().__init__(metadata, deterministic, seed)
        self.session = session
        self.path = path

    def _run(self, names: list[str], state: np.ndarray) -> list[np.ndarray]:
        """The outputs ``names`` for ``state (N, obs)``, each ``(N, ..)`` float32; a graph of
        rank-1 input runs row by row.

        Raises:
            OnnxRunError: onnxruntime failed, or an output of another shape or type.
        """
        state = np.asarray(state, np.float32)
        feeds = [state] if self.input_rank == 2 else list(state)
        try:
            runs = [self.session.run(names, {self.input_name: x}) for x in feeds]
        except Exception as exc:  # onnxruntime's exceptions share no base class but Exception
            raise checks.OnnxRunError(
                f"{self.path}: onnxruntime failed to run the policy: {type(exc).__name__}: {exc}"
            ) from exc
        outs = [np.stack(o) if self.input_rank == 1 else o[0] for o in zip(*runs, strict=True)]
        for name, out in zip(names, outs, strict=True):
            if out.dtype != np.float32 or out.ndim != 2 or len(out) != len(state):
                raise checks.OnnxRunError(
                    f"{self.path}: output {name!r} came out {out.dtype} {out.shape}, "
                    f"expected float32 ({len(state)}, ..)"
                )
        return outs

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """The network output ``(N, 2 * action_size)`` for ``state (N, 22)``."""
        (params,) = self._run([PARAMS], state)
        return params

    def mode(self, state: np.ndarray) -> np.ndarray:
        """The graph's deterministic ``action`` output ``(N, action_size)``, its distribution
        params checked finite (:meth:`~mjx_arm.policy.numpy_policy.BasePolicy.check_finite`)."""
        action, params = self._run([ACTION, PARAMS], state)
        self.check_finite(params)
        return action
