"""Structure-aware mutations of ONNX policies: the file stays a well-formed ONNX model with the
policy's metadata, and its graph is hostile.

- :func:`input_double`: the ``state`` input declared double;
- :func:`input_shape`: the ``state`` input of another rank or other dimensions;
- :func:`runtime_bomb`: ``distribution_params`` gets ``+ 0 * sum(big)`` where ``big`` has
  :data:`BOMB_ELEMENTS` float32 elements (256 GiB), made at run time by Expand (its shape from
  the input's batch, so it cannot be folded at load time), ConstantOfShape or Tile fed by
  constants;
- :func:`nan_output`: ``distribution_params`` gets ``+ NaN`` (or ``+ inf``).

Each is a mutation ``(good file, output path, rng) -> description`` (:mod:`input_fuzz.mutate`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from input_fuzz.hostile_npz import pick

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


ONNX_MUTATIONS = (input_double, input_shape, runtime_bomb, nan_output)
