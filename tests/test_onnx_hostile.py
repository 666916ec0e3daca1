"""Hand-built hostile ONNX policies: a graph that declares other inputs or outputs than the
contract, one that would allocate 2^36 elements, one whose sizes come from data, one that fails
inside onnxruntime, one that outputs NaN. Each is a named error at load or at the first action,
never a traceback or exhausted memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from input_fuzz.corpus import Corpus, build
from mjx_arm.cli import main
from mjx_arm.names import EXIT_INVALID
from mjx_arm.policy import NonFiniteActionError, PolicyFileError, load
from mjx_arm.policy.numpy_policy import read_npz

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from mjx_arm.policy.onnx_checks import (  # noqa: E402
    MAX_TENSOR_ELEMENTS,
    OnnxContractError,
    OnnxGraphLimitError,
    OnnxRunError,
)
from mjx_arm.policy.onnx_export import build_model  # noqa: E402


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Corpus:
    return build(tmp_path_factory.mktemp("onnx_corpus"))


@pytest.fixture(scope="module")
def policy_parts(corpus: Corpus) -> tuple[dict, dict]:
    return read_npz(corpus.policy)


def _save(model, path: Path) -> Path:
    onnx.save(model, str(path))
    return path


def _side_branch(model, nodes: list, inits: list) -> None:
    """Make ``action`` depend on the scalar ``side`` that ``nodes`` compute: ``action + 0 * side``
    (so that no optimiser drops the branch)."""
    tanh = next(n for n in model.graph.node if n.output[0] == "action")
    tanh.output[0] = "action_raw"
    zero = numpy_helper.from_array(np.zeros((), np.float32), "zero")
    model.graph.initializer.extend([zero, *inits])
    model.graph.node.extend(
        [
            *nodes,
            helper.make_node("Mul", ["side", "zero"], ["side0"]),
            helper.make_node("Add", ["action_raw", "side0"], ["action"]),
        ]
    )


def test_an_exported_policy_passes_the_checks(corpus: Corpus):
    policy = load(corpus.onnx)
    assert policy(np.zeros(policy.obs_size)).shape == (policy.action_size,)


def test_an_input_declared_double_is_refused(policy_parts, tmp_path: Path, capsys):
    model = build_model(*policy_parts)
    model.graph.input[0].type.tensor_type.elem_type = TensorProto.DOUBLE
    path = _save(model, tmp_path / "double.onnx")
    with pytest.raises(OnnxContractError, match=r"declares state: float64 \['batch', 22\].*"
                       r"expected one float32 input"):  # fmt: skip
        load(path)
    code = main(["eval", str(path), "--episodes", "1"])
    err = capsys.readouterr().err
    assert code == EXIT_INVALID and "Traceback" not in err
    (line,) = [x for x in err.splitlines() if x.startswith("error:")]
    assert "float64" in line and "expected one float32 input" in line


def test_other_inputs_or_outputs_are_refused(policy_parts, tmp_path: Path):
    model = build_model(*policy_parts)
    model.graph.input[0].type.tensor_type.shape.dim[1].dim_value = 21
    with pytest.raises(OnnxContractError, match=r"state: float32 \['batch', 21\]"):
        load(_save(model, tmp_path / "narrow.onnx"))
    model = build_model(*policy_parts)
    model.graph.input.append(helper.make_tensor_value_info("extra", TensorProto.FLOAT, [1]))
    with pytest.raises(OnnxContractError, match="extra: float32"):
        load(_save(model, tmp_path / "two_inputs.onnx"))
    model = build_model(*policy_parts)
    del model.graph.output[1]
    with pytest.raises(OnnxContractError, match="distribution_params"):
        load(_save(model, tmp_path / "one_output.onnx"))


def test_a_graph_of_2_to_the_36_elements_is_refused_before_allocation(policy_parts, tmp_path):
    """ConstantOfShape([2^18, 2^18]) is 2^36 float32 (256 GiB): onnxruntime would fold it
    when opening the model; the check refuses it from the inferred shape first."""
    model = build_model(*policy_parts)
    shape = numpy_helper.from_array(np.array([2**18, 2**18], np.int64), "big_shape")
    nodes = [
        helper.make_node("ConstantOfShape", ["big_shape"], ["big"]),
        helper.make_node("ReduceSum", ["big"], ["side"], keepdims=0),
    ]
    _side_branch(model, nodes, [shape])
    with pytest.raises(OnnxGraphLimitError, match=r"'big' of shape \[262144, 262144\] holds "
                       rf"68719476736 elements per batch row, over the limit of "
                       rf"{MAX_TENSOR_ELEMENTS}"):  # fmt: skip
        load(_save(model, tmp_path / "bomb.onnx"))


def test_sizes_computed_from_data_are_refused(policy_parts, tmp_path: Path):
    """A shape built from the input's values (``Cast`` of the state to int64) cannot be
    bounded before running, so it is refused."""
    model = build_model(*policy_parts)
    nodes = [
        helper.make_node("Abs", ["state"], ["abs"]),
        helper.make_node("Cast", ["abs"], ["dims"], to=TensorProto.INT64),
        helper.make_node("ReduceMax", ["dims"], ["n"], keepdims=0),
        helper.make_node("Unsqueeze", ["n", "axis0"], ["n1"]),
        helper.make_node("ConstantOfShape", ["n1"], ["grown"]),
        helper.make_node("ReduceSum", ["grown"], ["side"], keepdims=0),
    ]
    _side_branch(model, nodes, [numpy_helper.from_array(np.array([0], np.int64), "axis0")])
    with pytest.raises(OnnxGraphLimitError, match="cannot be bounded"):
        load(_save(model, tmp_path / "data_sized.onnx"))


def test_a_loop_is_refused(policy_parts, tmp_path: Path):
    model = build_model(*policy_parts)
    body = helper.make_graph(
        [helper.make_node("Identity", ["cond_in"], ["cond_out"])],
        "body",
        [
            helper.make_tensor_value_info("i", TensorProto.INT64, []),
            helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
        ],
        [helper.make_tensor_value_info("cond_out", TensorProto.BOOL, [])],
    )
    trips = numpy_helper.from_array(np.array(10**12, np.int64), "trips")
    true = numpy_helper.from_array(np.array(True), "true")
    nodes = [
        helper.make_node("Loop", ["trips", "true"], [], body=body),
        helper.make_node("Identity", ["zero"], ["side"]),
    ]
    _side_branch(model, nodes, [trips, true])
    with pytest.raises(OnnxGraphLimitError, match=r"Loop .* runs a subgraph"):
        load(_save(model, tmp_path / "loop.onnx"))


def test_a_failure_inside_onnxruntime_is_a_named_error(policy_parts, tmp_path: Path):
    """A Gather whose index comes out of range only at run time (index = 1000 * |state[0]|)."""
    model = build_model(*policy_parts)
    k = numpy_helper.from_array(np.float32(1000.0), "thousand")
    nodes = [
        helper.make_node("ReduceMax", ["state"], ["m"], keepdims=0),
        helper.make_node("Mul", ["m", "thousand"], ["scaled"]),
        helper.make_node("Cast", ["scaled"], ["index"], to=TensorProto.INT64),
        helper.make_node("Gather", ["zero_vec", "index"], ["side"]),
    ]
    zero_vec = numpy_helper.from_array(np.zeros(4, np.float32), "zero_vec")
    _side_branch(model, nodes, [k, zero_vec])
    policy = load(_save(model, tmp_path / "gather.onnx"))
    assert policy(np.zeros(policy.obs_size)).shape == (policy.action_size,)
    with pytest.raises(OnnxRunError, match="onnxruntime failed to run the policy"):
        policy(np.ones(policy.obs_size))
    assert issubclass(OnnxRunError, PolicyFileError)


def test_a_nan_output_is_a_non_finite_action_error(policy_parts, tmp_path: Path):
    """obs_std = 0: (0 - 0) / 0 is NaN in every network output."""
    arrays, meta = policy_parts
    arrays = {**arrays, "obs_mean": np.zeros(22, np.float32), "obs_std": np.zeros(22, np.float32)}
    policy = load(_save(build_model(arrays, meta), tmp_path / "nan.onnx"))
    for deterministic in (True, False):
        with pytest.raises(NonFiniteActionError, match="non-finite action"):
            policy(np.zeros(policy.obs_size), deterministic=deterministic)
