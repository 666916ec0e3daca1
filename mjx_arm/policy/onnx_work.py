"""An estimate of the arithmetic one run of an ONNX policy graph does, per batch row.

Each tensor being bounded does not bound the work: 3,000 ``MatMul`` nodes that reuse one
2048 x 2048 weight hold no tensor over 4 Mi elements yet take 12.6 G multiply-adds per action
(3.5 s per policy step on a 2-core CPU, and 32 s to open). So the work is estimated from the
shapes shape inference gave, node by node, in multiply-adds (or plain element operations):

- ``MatMul`` (and ``MatMulInteger``, ``QLinearMatMul``): output elements x the contracted size;
- ``Gemm``: output elements x the contracted size (``transA`` read);
- ``Conv``, ``ConvInteger``, ``QLinearConv``, ``ConvTranspose``: the larger of the output and
  the input elements x the kernel's elements per output channel;
- ``Einsum``: the product of its inputs' elements (at least its loop space);
- ``LSTM``, ``GRU``, ``RNN``: the sequence length x the elements of the weights ``W`` and ``R``;
- any other operator: its inputs' and outputs' elements together (elementwise work, a
  reduction's reads, a copy).

The sum over the nodes, per batch row, must stay under :data:`MAX_WORK_PER_ROW`. An exported
policy of the default network (three hidden layers of 128 on 22 observations) does 40 thousand,
one of three layers of 256 150 thousand; the limit, 2^26 (67 M, tens of milliseconds per action
on one core), leaves a margin of over four hundred, and passes three layers of 4096, the widest
the tensor limit (:data:`mjx_arm.policy.onnx_checks.MAX_TENSOR_ELEMENTS`) lets through. The
same sum bounds the elements of all the graph's tensors together, so it also bounds what
onnxruntime can keep alive at once (2^26 float32 are 256 MiB per row).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from mjx_arm.policy.onnx_wire import OnnxGraphLimitError

MAX_WORK_PER_ROW = 2**26


class OnnxWorkLimitError(OnnxGraphLimitError):
    """An ONNX graph whose estimated work per action is over :data:`MAX_WORK_PER_ROW`."""


Rows = Callable[[str], int]  # name -> elements per batch row (0 for a missing optional input)


def _dims(shapes: dict, name: str) -> list:
    return list(shapes.get(name) or [])


def _last_fixed(dims: list, index: int) -> int:
    """``dims[index]`` where it is a fixed size, else 1 (a batch dimension counts per row)."""
    try:
        value = dims[index]
    except IndexError:
        return 1
    return value if isinstance(value, int) and value > 0 else 1


def _attribute(node: Any, name: str, default: int = 0) -> int:
    return next((a.i for a in node.attribute if a.name == name), default)


def _matmul(node: Any, shapes: dict, rows: Rows) -> int:
    a = node.input[0]
    dims = _dims(shapes, a)
    inner = _last_fixed(dims, -1)
    return sum(rows(o) for o in node.output) * inner


def _gemm(node: Any, shapes: dict, rows: Rows) -> int:
    dims = _dims(shapes, node.input[0])
    inner = _last_fixed(dims, 0 if _attribute(node, "transA") else -1)
    return sum(rows(o) for o in node.output) * inner


def _conv(node: Any, shapes: dict, rows: Rows) -> int:
    weight = {"QLinearConv": 3}.get(node.op_type, 1)
    kernel = _dims(shapes, node.input[weight])[1:]
    per_channel = math.prod(d for d in kernel if isinstance(d, int) and d > 0)
    data = max(rows(node.input[0]), sum(rows(o) for o in node.output))
    return data * per_channel


def _einsum(node: Any, shapes: dict, rows: Rows) -> int:
    return math.prod(max(rows(i), 1) for i in node.input if i)


def _recurrent(node: Any, shapes: dict, rows: Rows) -> int:
    sequence = _last_fixed(_dims(shapes, node.input[0]), 0)
    weights = rows(node.input[1]) + rows(node.input[2])
    return sequence * weights


ESTIMATES: dict[str, Callable[[Any, dict, Rows], int]] = {
    "MatMul": _matmul,
    "MatMulInteger": _matmul,
    "QLinearMatMul": _matmul,
    "Gemm": _gemm,
    "Conv": _conv,
    "ConvInteger": _conv,
    "QLinearConv": _conv,
    "ConvTranspose": _conv,
    "Einsum": _einsum,
    "LSTM": _recurrent,
    "GRU": _recurrent,
    "RNN": _recurrent,
}


def node_work(node: Any, shapes: dict, rows: Rows) -> int:
    """The estimated work of one node per batch row (see the module docstring)."""
    estimate = ESTIMATES.get(node.op_type)
    if estimate is not None and len(node.input) > 1:
        return estimate(node, shapes, rows)
    return sum(rows(n) for n in [*node.input, *node.output] if n)


def check_work(nodes: Any, shapes: dict, rows: Rows, source: str) -> int:
    """The graph's estimated work per batch row (the sum of :func:`node_work`).

    Raises:
        OnnxWorkLimitError: over :data:`MAX_WORK_PER_ROW`, naming the heaviest operator.
    """
    total, heaviest, worst = 0, None, -1
    for node in nodes:
        work = node_work(node, shapes, rows)
        total += work
        if work > worst:
            heaviest, worst = node, work
    if total > MAX_WORK_PER_ROW:
        what = f"{heaviest.op_type} {heaviest.name or list(heaviest.output)}"
        raise OnnxWorkLimitError(
            f"{source}: its graph of {len(nodes):,} nodes would do about {total:,} operations per "
            f"action (the heaviest node, {what}, {worst:,}), over the limit of "
            f"{MAX_WORK_PER_ROW:,} (2^26); refused before onnxruntime opens it"
        )
    return total
