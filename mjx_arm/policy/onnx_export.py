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

from mjx_arm.inputs import InputError, write_atomic
from mjx_arm.policy.numpy_policy import BasePolicy, PolicyFileError, check_metadata

OPSET = 17
IR_VERSION = 8  # readable by onnxruntime >= 1.10
METADATA_KEY = "mjx_arm"
INPUT, ACTION, PARAMS = "state", "action", "distribution_params"


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
    nodes = [
        helper.make_node("Sub", [INPUT, "obs_mean"], ["centred"]),
        helper.make_node("Div", ["centred", "obs_std"], ["h0"]),
    ]
    for i in range(n_layers):
        last = i == n_layers - 1
        nodes.append(helper.make_node("MatMul", [f"h{i}", f"kernel_{i}"], [f"mm{i}"]))
        z = PARAMS if last else f"z{i}"
        nodes.append(helper.make_node("Add", [f"mm{i}", f"bias_{i}"], [z]))
        if not last:
            nodes += _activation_nodes(helper, metadata["activation"], z, f"h{i + 1}")
    nodes += [
        helper.make_node("Slice", [PARAMS, "slice_starts", "slice_ends", "slice_axes"], ["loc"]),
        helper.make_node("Tanh", ["loc"], [ACTION]),
    ]
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


def _session_metadata(session: Any, path: str | Path) -> dict[str, Any]:
    """The checked metadata of an ONNX policy, whose graph must take ``state (batch, obs)``
    and give ``action`` and ``distribution_params`` of the sizes it records.

    Raises:
        PolicyFileError: no or broken metadata, or a graph of other inputs or sizes.
    """
    try:
        props = session.get_modelmeta().custom_metadata_map
    except UnicodeDecodeError as exc:  # onnxruntime decodes the properties as UTF-8
        raise PolicyFileError(f"{path}: its metadata is not UTF-8 text ({exc})") from exc
    if METADATA_KEY not in props:
        raise PolicyFileError(f"{path} is not an mjx_arm policy file (no metadata)")
    try:
        metadata = json.loads(props[METADATA_KEY])
    except (ValueError, RecursionError) as exc:
        raise PolicyFileError(f"{path}: its metadata is not valid JSON ({exc})") from exc
    check_metadata(metadata, str(path))
    obs = sum(int(n) for _, n in metadata["obs_layout"])
    action = int(metadata["action_size"])
    shapes = {x.name: list(x.shape) for x in [*session.get_inputs(), *session.get_outputs()]}
    expected = {INPUT: obs, ACTION: action, PARAMS: 2 * action}
    if any(shapes.get(name, [None, None])[1:] != [size] for name, size in expected.items()):
        raise PolicyFileError(
            f"{path}: the graph's inputs and outputs {shapes} do not fit its metadata "
            f"(state {obs}, action {action}); export the policy again"
        )
    return metadata


class OnnxPolicy(BasePolicy):
    """An exported policy run by onnxruntime (CPU).

    Args:
        path: the ``.onnx`` file.
        deterministic: see :class:`~mjx_arm.policy.numpy_policy.BasePolicy`.
        seed: seed of the sampler when not deterministic.

    Raises:
        PolicyFileError: not an mjx_arm policy; ContractVersionError: another contract version.
    """

    def __init__(self, path: str | Path, deterministic: bool = True, seed: int | None = None):
        ort = _require("onnxruntime")
        try:
            session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise PolicyFileError(f"cannot read {path} as an ONNX model: {exc}") from exc
        metadata = _session_metadata(session, path)
        super().__init__(metadata, deterministic, seed)
        self.session = session

    def distribution_params(self, state: np.ndarray) -> np.ndarray:
        """The network output ``(N, 2 * action_size)`` for ``state (N, 22)``."""
        (params,) = self.session.run([PARAMS], {INPUT: np.asarray(state, np.float32)})
        return params

    def mode(self, state: np.ndarray) -> np.ndarray:
        """The graph's deterministic ``action`` output ``(N, action_size)``, its distribution
        params checked finite (:meth:`~mjx_arm.policy.numpy_policy.BasePolicy.check_finite`)."""
        feed = {INPUT: np.asarray(state, np.float32)}
        action, params = self.session.run([ACTION, PARAMS], feed)
        self.check_finite(params)
        return action
