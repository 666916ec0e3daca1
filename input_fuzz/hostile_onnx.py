"""Structure-aware mutations of ONNX policies: the file stays a well-formed ONNX model with the
policy's metadata, and its graph is hostile.

- :func:`input_double`: the ``state`` input declared double;
- :func:`input_shape`: the ``state`` input of another rank or other dimensions;
- :func:`runtime_bomb`: ``distribution_params`` gets ``+ 0 * sum(big)`` where ``big`` has
  :data:`BOMB_ELEMENTS` float32 elements (256 GiB), made at run time by Expand (its shape from
  the input's batch, so it cannot be folded at load time), ConstantOfShape or Tile fed by
  constants;
- :func:`nan_output`: ``distribution_params`` gets ``+ NaN`` (or ``+ inf``);
- work bombs (:data:`WORK_BOMBS`): :func:`matmul_flood` (up to 3,000 ``MatMul`` nodes reusing
  one 1024 x 1024 or 2048 x 2048 weight), :func:`identity_flood` (a chain of up to 300,000
  ``Identity`` nodes, written straight into the file's encoding), :func:`sparse_bomb` (a sparse
  initializer of three values whose dense shape is 2^40 elements), :func:`local_functions`
  (model-local functions that call each other twice per level, 2^30 nodes expanded),
  :func:`duplicate_outputs` (an output named twice, or written by two nodes);
- :func:`hostile_metadata`: the policy metadata with an unknown task, a string ``ctrl_dt`` or
  unknown observation keys.

Each is a mutation ``(good file, output path, rng) -> description`` (:mod:`input_fuzz.mutate`).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import pick
from mjx_arm.protobuf_wire import length_delimited

BOMB_ELEMENTS = 2**36
INPUT, PARAMS = "state", "distribution_params"


def _load(good: Path):
    import onnx

    return onnx.load(str(good))


def _save(model, out: Path) -> None:
    out.write_bytes(model.SerializeToString())


def input_double(good: Path, out: Path, rng: np.random.Generator) -> str:
    """The ``state`` input declared DOUBLE (the graph's constants stay float)."""
    from onnx import TensorProto

    model = _load(good)
    model.graph.input[0].type.tensor_type.elem_type = TensorProto.DOUBLE
    _save(model, out)
    return "state declared double"


def input_shape(good: Path, out: Path, rng: np.random.Generator) -> str:
    """The ``state`` input of rank 1 or 3, or of another observation size."""
    model = _load(good)
    dims = model.graph.input[0].type.tensor_type.shape.dim
    op = pick(rng, ("rank1", "rank3", "size"))
    if op == "rank1":
        del dims[0]
    elif op == "rank3":
        dims.add().dim_value = 1
    else:
        dims[1].dim_value = int(pick(rng, (1, dims[1].dim_value + 1, 2**31 - 1)))
    _save(model, out)
    return f"state shape {[d.dim_value or d.dim_param for d in dims]}"


def _rewire(model, make_nodes) -> None:
    """Make the node that writes ``distribution_params`` write ``params_raw`` instead, and put
    ``make_nodes(helper) -> nodes`` (reading ``params_raw``, writing ``distribution_params``)
    right after it."""
    from onnx import helper

    graph = model.graph
    index = next(i for i, n in enumerate(graph.node) if PARAMS in n.output)
    node = graph.node[index]
    node.output[list(node.output).index(PARAMS)] = "params_raw"
    for offset, new in enumerate(make_nodes(helper)):
        graph.node.insert(index + 1 + offset, new)


def _const(helper, name: str, values, dtype) -> object:
    from onnx import numpy_helper

    tensor = numpy_helper.from_array(np.asarray(values, dtype=dtype), name)
    return helper.make_node("Constant", [], [name], value=tensor)


def _bomb_nodes(helper, how: str) -> list:
    """Nodes whose output ``big`` holds :data:`BOMB_ELEMENTS` float32."""
    if how == "expand":  # the shape from the input's batch: only known at run time
        return [
            helper.make_node("Shape", [INPUT], ["state_shape"], start=0, end=1),
            _const(helper, "bomb_factor", [BOMB_ELEMENTS], np.int64),
            helper.make_node("Mul", ["state_shape", "bomb_factor"], ["bomb_shape"]),
            _const(helper, "bomb_zero", 0.0, np.float32),
            helper.make_node("Expand", ["bomb_zero", "bomb_shape"], ["big"]),
        ]
    if how == "constant_of_shape":
        return [
            _const(helper, "bomb_shape", [BOMB_ELEMENTS], np.int64),
            helper.make_node("ConstantOfShape", ["bomb_shape"], ["big"]),
        ]
    return [  # tile
        _const(helper, "bomb_seed", [0.0], np.float32),
        _const(helper, "bomb_repeats", [BOMB_ELEMENTS], np.int64),
        helper.make_node("Tile", ["bomb_seed", "bomb_repeats"], ["big"]),
    ]


def runtime_bomb(good: Path, out: Path, rng: np.random.Generator) -> str:
    """``distribution_params + 0 * sum(big)``, ``big`` of 2^36 float32 made by the graph."""
    how = pick(rng, ("expand", "expand", "constant_of_shape", "tile"))
    model = _load(good)

    def nodes(helper) -> list:
        return [
            *_bomb_nodes(helper, how),
            helper.make_node("ReduceSum", ["big"], ["big_sum"], keepdims=0),
            _const(helper, "bomb_nought", 0.0, np.float32),
            helper.make_node("Mul", ["big_sum", "bomb_nought"], ["bomb_term"]),
            helper.make_node("Add", ["params_raw", "bomb_term"], [PARAMS]),
        ]

    _rewire(model, nodes)
    _save(model, out)
    return f"allocates {BOMB_ELEMENTS} float32 by {how}"


def nan_output(good: Path, out: Path, rng: np.random.Generator) -> str:
    """``distribution_params + NaN`` (or ``+ inf``): every action non-finite."""
    value = float(pick(rng, (np.nan, np.nan, np.inf)))
    model = _load(good)
    _rewire(
        model,
        lambda helper: [
            _const(helper, "poison", value, np.float32),
            helper.make_node("Add", ["params_raw", "poison"], [PARAMS]),
        ],
    )
    _save(model, out)
    return f"outputs {value}"


def _dead_sum(helper, tensor: str) -> list:
    """Nodes adding ``0 * sum(tensor)`` to ``params_raw`` (so ``tensor`` is computed)."""
    return [
        helper.make_node("ReduceSum", [tensor], [f"{tensor}_sum"], keepdims=0),
        _const(helper, f"{tensor}_nought", 0.0, np.float32),
        helper.make_node("Mul", [f"{tensor}_sum", f"{tensor}_nought"], [f"{tensor}_term"]),
        helper.make_node("Add", ["params_raw", f"{tensor}_term"], [PARAMS]),
    ]


def matmul_flood(good: Path, out: Path, rng: np.random.Generator) -> str:
    """``count`` MatMul nodes, each by the same ``size`` x ``size`` weight, on a projection of
    the input (the work per action: count x size^2 multiply-adds)."""
    from onnx import numpy_helper

    size = int(pick(rng, (1024, 2048)))
    count = int(pick(rng, (16, 60, 300, 3000)))
    model = _load(good)
    obs = model.graph.input[0].type.tensor_type.shape.dim[1].dim_value
    small = np.random.default_rng(0)
    model.graph.initializer.extend([
        numpy_helper.from_array(small.normal(0, 0.01, (obs, size)).astype(np.float32), "flood_p"),
        numpy_helper.from_array(np.eye(size, dtype=np.float32), "flood_w"),
    ])  # fmt: skip

    def nodes(helper) -> list:
        made = [helper.make_node("MatMul", [INPUT, "flood_p"], ["flood_0"])]
        for i in range(count):
            made.append(helper.make_node("MatMul", [f"flood_{i}", "flood_w"], [f"flood_{i + 1}"]))
        return made + _dead_sum(helper, f"flood_{count}")

    _rewire(model, nodes)
    _save(model, out)
    return f"matmul_flood: {count} MatMul by a {size} x {size} weight"


def identity_flood(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A chain of Identity nodes from the input, its end summed into the output; the nodes are
    written as protobuf bytes before the graph's own (order kept: they only need the input)."""
    count = int(pick(rng, (4000, 5000, 100_000, 300_000)))
    model = _load(good)
    _rewire(model, lambda helper: _dead_sum(helper, "chain_end"))
    names = [INPUT, *(f"c{i}" for i in range(count - 1)), "chain_end"]
    encoded = [name.encode() for name in names]
    nodes = b"".join(  # names of under 128 bytes: every length is one byte
        b"\n" + bytes([len(a) + len(b) + 14]) + b"\n" + bytes([len(a)]) + a
        + b"\x12" + bytes([len(b)]) + b + b'"\x08Identity'
        for a, b in itertools.pairwise(encoded)
    )  # fmt: skip
    graph = nodes + model.graph.SerializeToString()
    model.ClearField("graph")
    out.write_bytes(model.SerializeToString() + length_delimited(7, graph))
    return f"identity_flood: {count} Identity nodes"


def sparse_bomb(good: Path, out: Path, rng: np.random.Generator) -> str:
    """A sparse initializer of three values whose dense shape holds 2^40 (or 2^24 + 1)
    elements (onnxruntime makes it dense when it opens the model): unused, or summed into the
    output (which shape inference cannot type)."""
    from onnx import helper, numpy_helper

    dims = pick(rng, ((2**20, 2**20), (2**40,), (2**24 + 1,)))
    values = numpy_helper.from_array(np.ones(3, np.float32), "sparse_big")
    indices = numpy_helper.from_array(np.array([0, 5, 9], np.int64), "sparse_big_indices")
    model = _load(good)
    model.graph.sparse_initializer.append(helper.make_sparse_tensor(values, indices, dims))
    used = rng.random() < 0.3
    if used:
        _rewire(model, lambda h: _dead_sum(h, "sparse_big"))
    _save(model, out)
    return f"sparse_bomb: dense shape {dims}{', used' if used else ''}"


def local_functions(good: Path, out: Path, rng: np.random.Generator) -> str:
    """Model-local functions ``f0 .. f{levels}``, each calling the one below twice: the last,
    called once, expands to 2^levels nodes."""
    from onnx import helper

    levels = int(pick(rng, (1, 10, 30)))
    domain = "fuzz.local"
    functions = [helper.make_function(domain, "f0", ["x"], ["y"],
                                      [helper.make_node("Identity", ["x"], ["y"])],
                                      [helper.make_opsetid("", 17)])]  # fmt: skip
    for level in range(1, levels + 1):
        body = [
            helper.make_node(f"f{level - 1}", ["x"], ["a"], domain=domain),
            helper.make_node(f"f{level - 1}", ["a"], ["y"], domain=domain),
        ]
        opsets = [helper.make_opsetid("", 17), helper.make_opsetid(domain, 1)]
        functions.append(helper.make_function(domain, f"f{level}", ["x"], ["y"], body, opsets))
    model = _load(good)
    model.functions.extend(functions)
    model.opset_import.append(helper.make_opsetid(domain, 1))
    _rewire(model, lambda h: [h.make_node(f"f{levels}", ["params_raw"], [PARAMS], domain=domain)])
    _save(model, out)
    return f"local_functions: {levels} levels"


def duplicate_outputs(good: Path, out: Path, rng: np.random.Generator) -> str:
    """``action`` listed twice among the outputs, or written by a second node."""
    model = _load(good)
    if rng.random() < 0.5:
        model.graph.output.append(model.graph.output[0])
        what = "action listed twice"
    else:
        from onnx import helper

        model.graph.node.append(helper.make_node("Identity", [PARAMS], ["action"]))
        what = "action written by two nodes"
    _save(model, out)
    return f"duplicate_outputs: {what}"


def hostile_metadata(good: Path, out: Path, rng: np.random.Generator) -> str:
    """The mjx_arm metadata with an unknown task, a string ctrl_dt, or unknown (or renamed)
    observation keys."""
    import json

    model = _load(good)
    prop = next(p for p in model.metadata_props if p.key == "mjx_arm")
    data = json.loads(prop.value)
    op = pick(rng, ("task", "ctrl_dt", "obs_keys", "obs_keys"))
    if op == "task":
        data["task"] = pick(rng, ("fly", "", "REACH", "reach\u0000", "x" * 10_000))
        what = f"task {data['task'][:12]!r}"
    elif op == "ctrl_dt":
        data["ctrl_dt"] = pick(rng, ("0.0333", "fast", "", "nan"))
        what = f"ctrl_dt {data['ctrl_dt']!r}"
    else:
        layout = data.get("obs_layout") or [["x", 1]]
        i = int(rng.integers(len(layout)))
        layout[i] = [pick(rng, ("no_such_obs", "", "joint_angles", "x" * 5000)), layout[i][1]]
        data["obs_layout"] = layout
        what = f"obs_layout key {i} is {layout[i][0][:16]!r}"
    prop.value = json.dumps(data)
    _save(model, out)
    return f"metadata: {what}"


WORK_BOMBS = (matmul_flood, identity_flood, sparse_bomb, local_functions, duplicate_outputs)
ONNX_MUTATIONS = (input_double, input_shape, runtime_bomb, nan_output, *WORK_BOMBS,
                  hostile_metadata, hostile_metadata)  # fmt: skip
