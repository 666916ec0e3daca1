"""Hand-built hostile ONNX policies: a graph that declares other inputs or outputs than the
contract, one that would allocate 2^36 elements, one whose sizes come from data, one that fails
inside onnxruntime, one that outputs NaN; one of 3,000 MatMuls (seconds per action), of too many
nodes or too much structure (gigabytes to parse), with a model-local function, a huge sparse
initializer, an output named twice, a tensor in another file. Each is a named error at load
(before parsing or before an inference session where it would cost) or at the first action,
never a traceback or exhausted memory."""

from __future__ import annotations

import itertools
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


# --------------------------------------------------------------------------- size and work


def _refuse_sessions(monkeypatch) -> None:
    """Fail the test if onnxruntime is asked to open a model."""
    import onnxruntime

    def no_session(*args, **kwargs):
        raise AssertionError("an inference session was built for a graph that must be refused")

    monkeypatch.setattr(onnxruntime, "InferenceSession", no_session)


def _refuse_parsing(monkeypatch) -> None:
    """Fail the test if the file is parsed (refusal must come from its encoding)."""

    def no_parse(*args, **kwargs):
        raise AssertionError("the model was parsed; it must be refused from its encoding")

    monkeypatch.setattr(onnx, "load_model_from_string", no_parse)


def test_3000_matmuls_on_one_weight_are_refused_by_their_work(policy_parts, tmp_path, monkeypatch):
    """3,000 MatMul nodes on one 2048 x 2048 weight: no tensor is over the element limit, but
    each action would take 12.6 G multiply-adds (3.5 s per step, 32 s to open, measured): the
    work estimate refuses it before any inference session is built."""
    from mjx_arm.policy.onnx_work import MAX_WORK_PER_ROW, OnnxWorkLimitError

    model = build_model(*policy_parts)
    weight = numpy_helper.from_array(np.zeros((2048, 2048), np.float32), "w")
    nodes = [helper.make_node("ReduceSum", ["state"], ["s0"], keepdims=1)]  # (batch, 1)
    nodes.append(helper.make_node("Expand", ["s0", "wide"], ["m0"]))  # (batch, 2048)
    nodes += [helper.make_node("MatMul", [f"m{i}", "w"], [f"m{i + 1}"]) for i in range(3000)]
    nodes.append(helper.make_node("ReduceSum", ["m3000"], ["side"], keepdims=0))
    wide = numpy_helper.from_array(np.array([1, 2048], np.int64), "wide")
    _side_branch(model, nodes, [weight, wide])
    path = _save(model, tmp_path / "matmuls.onnx")
    _refuse_sessions(monkeypatch)
    with pytest.raises(OnnxWorkLimitError, match=r"3,019 nodes would do about 12,58\d,\d{3},\d{3} "
                       rf"operations per action .* MatMul .* over the limit of "
                       rf"{MAX_WORK_PER_ROW:,}"):  # fmt: skip
        load(path)
    assert issubclass(OnnxWorkLimitError, OnnxGraphLimitError)


def _identity_chain(model, count: int) -> None:
    """Route ``action`` through ``count`` Identity nodes."""
    tanh = next(n for n in model.graph.node if n.output[0] == "action")
    tanh.output[0] = "x0"
    names = [f"x{i}" for i in range(count)] + ["action"]
    model.graph.node.extend(
        helper.make_node("Identity", [a], [b]) for a, b in itertools.pairwise(names)
    )


def test_a_graph_of_too_many_nodes_is_refused_before_parsing(policy_parts, tmp_path, monkeypatch):
    from mjx_arm.policy.onnx_wire import GRAPH_LIMITS, OnnxSizeError

    model = build_model(*policy_parts)
    _identity_chain(model, GRAPH_LIMITS["node"])
    path = _save(model, tmp_path / "identities.onnx")
    _refuse_parsing(monkeypatch)
    with pytest.raises(OnnxSizeError, match=r"more than 4096 entries of 'node'.* before parsing"):
        load(path)


def _field(number: int, payload: bytes) -> bytes:
    """One length-delimited protobuf field."""

    def varint(value: int) -> bytes:
        out = bytearray()
        while True:
            out.append((value & 0x7F) | (0x80 if value > 0x7F else 0))
            value >>= 7
            if not value:
                return bytes(out)

    return varint(number << 3 | 2) + varint(len(payload)) + payload


def test_a_million_identity_nodes_are_refused_in_bounded_memory(policy_parts, tmp_path):
    """A million Identity nodes, 27 MB on disk, took 1-2 GB to open; the walk of the encoding
    refuses them with at most a small multiple of the file in memory (protobuf merges a second
    ``graph`` field into the first: its nodes are appended)."""
    import tracemalloc

    from mjx_arm.policy.onnx_wire import OnnxSizeError

    node = helper.make_node("Identity", ["action"], ["action"]).SerializeToString()
    extra = _field(7, _field(1, node) * 1_000_000)  # ModelProto.graph, GraphProto.node
    path = tmp_path / "million.onnx"
    path.write_bytes(build_model(*policy_parts).SerializeToString() + extra)
    size = path.stat().st_size
    assert size > 20 * 2**20
    tracemalloc.start()
    with pytest.raises(OnnxSizeError, match="more than 4096 entries of 'node'"):
        load(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 2 * size, f"{peak / 2**20:.0f} MiB to refuse a {size / 2**20:.0f} MiB file"


def test_too_much_graph_structure_is_refused_before_parsing(policy_parts, tmp_path, monkeypatch):
    """Few nodes, but 2 MiB of structure (a doc string): refused from the encoding."""
    from mjx_arm.policy.onnx_wire import MAX_STRUCTURE_BYTES, OnnxSizeError

    model = build_model(*policy_parts)
    model.graph.doc_string = "x" * (2 * MAX_STRUCTURE_BYTES)
    path = _save(model, tmp_path / "structure.onnx")
    _refuse_parsing(monkeypatch)
    with pytest.raises(OnnxSizeError, match=r"graph structure .* over the limit of 1,048,576"):
        load(path)


def test_a_model_local_function_is_refused_before_parsing(policy_parts, tmp_path, monkeypatch):
    from mjx_arm.policy.onnx_wire import OnnxSizeError

    model = build_model(*policy_parts)
    body = [helper.make_node("Identity", ["x"], ["y"])]
    function = helper.make_function(
        "local", "twice", ["x"], ["y"], body, [helper.make_opsetid("", 17)]
    )
    model.functions.append(function)
    model.opset_import.append(helper.make_opsetid("local", 1))
    _side_branch(model, [helper.make_node("twice", ["zero"], ["side"], domain="local")], [])
    path = _save(model, tmp_path / "function.onnx")
    _refuse_parsing(monkeypatch)
    with pytest.raises(OnnxSizeError, match="holds model-local functions"):
        load(path)


def test_a_sparse_initializer_counts_by_its_dense_size(policy_parts, tmp_path, monkeypatch):
    """One stored value in a dense shape of 2^28 float32 (1 GiB), used by no node: onnxruntime
    would densify it when it opens the model; it is refused before."""
    model = build_model(*policy_parts)
    values = numpy_helper.from_array(np.ones(1, np.float32), "sparse")
    indices = numpy_helper.from_array(np.zeros(1, np.int64), "sparse_indices")
    model.graph.sparse_initializer.append(helper.make_sparse_tensor(values, indices, [2**28]))
    path = _save(model, tmp_path / "sparse.onnx")
    assert path.stat().st_size < 100_000
    _refuse_sessions(monkeypatch)
    with pytest.raises(OnnxGraphLimitError, match=r"'sparse' of shape \[268435456\] holds"):
        load(path)


def test_an_output_named_twice_or_a_value_defined_twice_is_refused(policy_parts, tmp_path):
    model = build_model(*policy_parts)
    model.graph.output.append(model.graph.output[0])
    with pytest.raises(OnnxContractError, match=r"names the output\(s\) \['action'\] more than"):
        load(_save(model, tmp_path / "two_actions.onnx"))
    model = build_model(*policy_parts)
    model.graph.node.append(helper.make_node("Identity", ["h0"], ["centred"]))
    with pytest.raises(PolicyFileError, match="defines the value 'centred' twice"):
        load(_save(model, tmp_path / "twice.onnx"))


def test_a_tensor_stored_in_another_file_is_refused(policy_parts, tmp_path):
    model = build_model(*policy_parts)
    kernel = next(t for t in model.graph.initializer if t.name == "kernel_0")
    kernel.ClearField("raw_data")
    kernel.data_location = TensorProto.EXTERNAL
    kernel.external_data.add(key="location", value="/etc/passwd")
    with pytest.raises(PolicyFileError, match="'kernel_0' keeps its numbers in another file"):
        load(_save(model, tmp_path / "external.onnx"))
