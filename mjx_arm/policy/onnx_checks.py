"""Checks of an ONNX policy graph made before onnxruntime sees it.

An ``.onnx`` file is a program: its graph may declare other inputs than the policy contract's,
or build a tensor of billions of elements (onnxruntime folds constants when it opens a model, so
such a graph exhausts memory before the first action). Before a session is created the graph is
read with the ``onnx`` package and:

- its inputs and outputs are checked against the contract: one float32 input ``(obs,)`` or
  ``(batch, obs)``, float32 outputs ``action (.., A)`` and ``distribution_params (.., 2A)`` of the
  input's rank (:class:`OnnxContractError`);
- shape inference (``onnx.shape_inference``, strict, with constant shapes propagated) must give
  every tensor a shape made of fixed sizes and at most one ``batch`` dimension, and no tensor may
  hold more than :data:`MAX_TENSOR_ELEMENTS` per batch row (:class:`OnnxGraphLimitError`).

A shape that inference cannot bound is refused rather than guessed: a size computed from the data
(``Shape`` of the input fed to ``ConstantOfShape``/``Reshape``/``Expand``/``Tile``/``Range``), an
operator without a shape function (a custom domain), or a control-flow operator (``Loop``, ``If``,
``Scan``: their trip count and body shapes come from data). An exported policy is a plain MLP, all
of whose shapes are fixed but the batch, so none of these rules refuses it.

Around these checks: before the file is parsed, its encoding is walked and a graph of too many
nodes or initializers, too much structure, or model-local functions is refused
(:mod:`mjx_arm.policy.onnx_wire`); once parsed, every value must be defined once and every output
named once, tensors must be stored in the file (no external data), a sparse initializer's dense
size counts against the element limit; and once shapes are inferred, the graph's estimated work
per action must be under :data:`mjx_arm.policy.onnx_work.MAX_WORK_PER_ROW`.
"""

from __future__ import annotations

import json
from typing import Any

from mjx_arm.policy.numpy_policy import PolicyFileError, check_metadata
from mjx_arm.policy.onnx_wire import OnnxGraphLimitError
from mjx_arm.policy.onnx_work import check_work

METADATA_KEY = "mjx_arm"
ACTION, PARAMS = "action", "distribution_params"
# Elements of one tensor per batch row: 16 Mi float32 are 64 MiB. An exported policy's largest
# tensor is a 128 x 128 kernel (16 Ki elements); the limit leaves a margin of a thousand.
MAX_TENSOR_ELEMENTS = 2**24
# The file itself: exported policies are a few hundred kB.
MAX_FILE_BYTES = 256 * 2**20


class OnnxContractError(PolicyFileError):
    """An ONNX graph whose inputs or outputs are not those of the policy contract."""


class OnnxRunError(PolicyFileError):
    """onnxruntime failed while running a policy graph."""


def _type_name(onnx: Any, elem_type: int) -> str:
    try:
        return onnx.helper.tensor_dtype_to_np_dtype(elem_type).name
    except (KeyError, ValueError, TypeError):
        return f"type {elem_type}"


def _dims(shape: Any) -> list[int | str | None]:
    """The dims of a TensorShapeProto: int (fixed), str (symbolic) or None (unknown)."""
    out: list[int | str | None] = []
    for d in shape.dim:
        which = d.WhichOneof("value")
        out.append(d.dim_value if which == "dim_value" else d.dim_param or None)
    return out


def _first_misfit(inputs: list, outputs: dict, declared: dict, obs: int, act: int) -> str:
    """The first input or output that breaks the contract, described ("" when none does)."""
    if len(inputs) != 1:
        return f"the graph has {len(inputs)} inputs"
    for name in (ACTION, PARAMS):
        if name not in outputs:
            return f"the graph has no output {name!r}"
    name = inputs[0].name
    kind, dims = declared[name]
    if kind != "float32" or dims is None or len(dims) not in (1, 2) or dims[-1] != obs:
        return f"input {name!r} is {kind} {dims}"
    for out, size in ((ACTION, act), (PARAMS, 2 * act)):
        out_kind, out_dims = declared[out]
        if out_kind != "float32" or out_dims is None or out_dims[-1] != size:
            return f"output {out!r} is {out_kind} {out_dims}"
        if len(out_dims) != len(dims):
            return f"output {out!r} has rank {len(out_dims)}, the input {len(dims)}"
    return ""


def _declared(onnx: Any, value: Any) -> tuple[str, list | None]:
    """(element type name, dims or None) of a graph input or output."""
    tensor = value.type.tensor_type if value.type.HasField("tensor_type") else None
    if tensor is None:
        return value.type.WhichOneof("value") or "no type", None
    dims = _dims(tensor.shape) if tensor.HasField("shape") else None
    return _type_name(onnx, tensor.elem_type), dims


def model_metadata(model: Any, source: str) -> dict[str, Any]:
    """The checked ``mjx_arm`` metadata stored in ``model.metadata_props``.

    Raises:
        PolicyFileError: none, not JSON, or not a policy's; ContractVersionError: another version.
    """
    props = {p.key: p.value for p in model.metadata_props}
    if METADATA_KEY not in props:
        raise PolicyFileError(f"{source} is not an mjx_arm policy file (no metadata)")
    try:
        metadata = json.loads(props[METADATA_KEY])
    except (ValueError, RecursionError) as exc:
        raise PolicyFileError(f"{source}: its metadata is not valid JSON ({exc})") from exc
    check_metadata(metadata, source)
    return metadata


def check_contract(onnx: Any, model: Any, metadata: dict[str, Any], source: str) -> tuple[str, int]:
    """Check the graph's declared inputs and outputs against the contract.

    Returns:
        (the input's name, its rank: 1 for ``(obs,)``, 2 for ``(batch, obs)``).

    Raises:
        OnnxContractError: what was declared, and what is expected.
    """
    obs = sum(int(n) for _, n in metadata["obs_layout"])
    act = int(metadata["action_size"])
    inits = {t.name for t in model.graph.initializer}
    inputs = [v for v in model.graph.input if v.name not in inits]
    outputs = {v.name: v for v in model.graph.output}
    expected = (
        f"expected one float32 input (obs,) or (batch, obs) with obs = {obs}, and float32 outputs "
        f"{ACTION!r} (.., {act}) and {PARAMS!r} (.., {2 * act}) of the input's rank; export the "
        "policy again (mjx-arm export RUN_DIR -o POLICY)"
    )
    declared = {v.name: _declared(onnx, v) for v in [*inputs, *outputs.values()]}
    shown = ", ".join(f"{k}: {t} {d}" for k, (t, d) in declared.items())
    wrong = _first_misfit(inputs, outputs, declared, obs, act)
    if wrong:
        report = f"{source}: the graph declares {shown or 'nothing'}; {expected}"
        problem = OnnxContractError(report)
        problem.headline = (
            f"{source}: {wrong}, expected one float32 input (batch, {obs}) and float32 "
            f"{ACTION!r} (.., {act}); export the policy again"
        )
        raise problem
    dims = declared[inputs[0].name][1]
    return inputs[0].name, len(dims)


def _value_shapes(model: Any) -> dict[str, list | None]:
    """Name -> dims of every typed value of an inferred graph (None: no shape)."""
    graph = model.graph
    shapes: dict[str, list | None] = {}
    for v in [*graph.input, *graph.value_info, *graph.output]:
        tensor = v.type.tensor_type if v.type.HasField("tensor_type") else None
        has_shape = tensor is not None and tensor.HasField("shape")
        shapes[v.name] = _dims(tensor.shape) if has_shape else None
    for t in graph.initializer:
        shapes[t.name] = list(t.dims)
    for sparse in graph.sparse_initializer:  # its dense size: onnxruntime densifies it
        shapes[sparse.values.name] = list(sparse.dims)
    return shapes


def _row_elements(dims: list | None, batch: str | int | None) -> int | None:
    """Elements per batch row of ``dims``; None when they cannot be bounded."""
    if dims is None:
        return None
    count, batches = 1, 0
    for d in dims:
        if isinstance(d, int) and d > 0 and d != batch:
            count *= d
        elif d == batch and batch is not None:
            batches += 1
        elif d == 0:
            return 0
        else:
            return None
    return count if batches <= 1 else None


def _refuse_subgraphs(onnx: Any, model: Any, source: str) -> None:
    """Refuse a node that runs a subgraph (``Loop``, ``If``, ``Scan``: control flow)."""
    graph_attr = (onnx.AttributeProto.GRAPH, onnx.AttributeProto.GRAPHS)
    for node in model.graph.node:
        if any(a.type in graph_attr for a in node.attribute):
            raise OnnxGraphLimitError(
                f"{source}: operator {node.op_type} {node.name or list(node.output)} runs a "
                "subgraph, whose sizes come from data; a policy graph has no control flow"
            )


def check_bounded(onnx: Any, model: Any, input_name: str, source: str) -> int:
    """Refuse a graph with control flow, a tensor whose shape inference cannot bound, one of
    more than :data:`MAX_TENSOR_ELEMENTS` elements per batch row, or more estimated work per
    action than :data:`~mjx_arm.policy.onnx_work.MAX_WORK_PER_ROW` (see the module docstring).

    Returns:
        The graph's estimated work per batch row (:func:`~mjx_arm.policy.onnx_work.check_work`).

    Raises:
        OnnxGraphLimitError: naming the tensor, its shape, and the limit; OnnxWorkLimitError
            (one) naming the estimated work and the heaviest node.
    """
    _refuse_subgraphs(onnx, model, source)
    try:
        inferred = onnx.shape_inference.infer_shapes(model, strict_mode=True, data_prop=True)
    except Exception as exc:  # onnx raises InferenceError, ValidationError, RuntimeError
        raise OnnxGraphLimitError(f"{source}: shape inference failed ({exc})") from exc
    shapes = _value_shapes(inferred)
    input_dims = shapes.get(input_name) or []
    symbolic = len(input_dims) == 2 and isinstance(input_dims[0], str)
    batch = input_dims[0] if symbolic else None
    names = list(shapes) + [o for n in inferred.graph.node for o in n.output if o]
    rows = {name: _bounded_rows(shapes.get(name), batch, name, source) for name in names}
    return check_work(inferred.graph.node, shapes, lambda n: rows.get(n, 0), source)


def _bounded_rows(dims: list | None, batch: str | None, name: str, source: str) -> int:
    """Elements per batch row of the tensor ``name`` of shape ``dims``, checked.

    Raises:
        OnnxGraphLimitError: a shape that cannot be bounded, or over the element limit.
    """
    rows = _row_elements(dims, batch)
    if rows is None:
        raise OnnxGraphLimitError(
            f"{source}: tensor {name!r} has a shape that cannot be bounded before running "
            f"({dims if dims is not None else 'unknown'}): sizes computed from data, an "
            "operator without shape inference, or a second batch dimension are refused"
        )
    if rows > MAX_TENSOR_ELEMENTS:
        raise OnnxGraphLimitError(
            f"{source}: tensor {name!r} of shape {dims} holds {rows} elements per batch row, "
            f"over the limit of {MAX_TENSOR_ELEMENTS} (2^24); refused before allocation"
        )
    return rows


def check_definitions(onnx: Any, model: Any, source: str) -> None:
    """Every graph output named once, every value defined once (by an input, an initializer
    or one node), every tensor's numbers in the file itself (no external data).

    Raises:
        OnnxContractError: an output named twice; PolicyFileError: a value defined twice, or
            a tensor stored outside the file.
    """
    graph = model.graph
    outputs = [v.name for v in graph.output]
    twice = sorted({n for n in outputs if outputs.count(n) > 1})
    if twice:
        raise OnnxContractError(f"{source}: the graph names the output(s) {twice} more than once")
    tensors = [*graph.initializer, *(s.values for s in graph.sparse_initializer)]
    names = {t.name for t in graph.initializer}
    defined = [v.name for v in graph.input if v.name not in names] + [t.name for t in tensors]
    defined += [o for node in graph.node for o in node.output if o]
    seen: set[str] = set()
    for name in defined:
        if name in seen:
            raise PolicyFileError(f"{source}: the graph defines the value {name!r} twice")
        seen.add(name)
    external = onnx.TensorProto.EXTERNAL
    for tensor in tensors:
        if tensor.data_location == external or len(tensor.external_data):
            raise PolicyFileError(
                f"{source}: tensor {tensor.name!r} keeps its numbers in another file; a policy "
                "file holds its own (export it again: mjx-arm export RUN_DIR -o POLICY)"
            )
