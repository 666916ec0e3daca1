"""A look at an ONNX file's protobuf encoding before anything parses it.

Parsing an ONNX model costs memory out of proportion to its size where the file is mostly
graph structure: a graph of a million ``Identity`` nodes (28 bytes each on disk) takes about
130 bytes of memory per byte of file to load, infer shapes and open in onnxruntime (measured on
100,000 nodes: a 2.8 MB file, 366 MB of memory). Tensor payloads (``raw_data`` and packed
numbers) cost about their own size. So before the file is parsed its encoding is walked (the
model's fields, the graph's, each initializer's; a node is skipped whole, never decoded) and it
is refused when:

- the graph has more entries of a kind than :data:`GRAPH_LIMITS` allows (nodes, initializers,
  declared values), counted on the wire;
- its structure, every byte but the initializers' payloads, is over
  :data:`MAX_STRUCTURE_BYTES`;
- it holds model-local functions or training graphs (an exported policy has neither; a
  function's body is expanded where it is called, so a few bytes of calls can stand for any
  number of nodes).

An exported policy of this project (three hidden layers) has 20 nodes, 15 initializers and
about 6 kB of structure, most of it its metadata's JSON: the limits leave margins of two hundred
(nodes) and more.
"""

from __future__ import annotations

from typing import Any

from mjx_arm.policy.numpy_policy import PolicyFileError

MAX_STRUCTURE_BYTES = 2**20
# entries of the GraphProto, per field name
GRAPH_LIMITS = {
    "node": 4096,
    "initializer": 4096,
    "sparse_initializer": 16,
    "input": 4096,  # files of IR version < 4 list every initializer as an input too
    "output": 64,
    "value_info": 16384,
    "quantization_annotation": 4096,
    "metadata_props": 256,
}
# fields of the ModelProto a policy file must not hold (what each is, for the message)
REFUSED_MODEL_FIELDS = {
    "functions": "model-local functions (a policy graph calls only standard operators)",
    "training_info": "training graphs (a policy file holds only the inference graph)",
}
# TensorProto fields that hold a tensor's numbers (packed or raw bytes)
PAYLOAD_FIELDS = (
    "raw_data",
    "float_data",
    "int32_data",
    "int64_data",
    "double_data",
    "uint64_data",
)
_VARINT, _FIXED64, _BYTES, _FIXED32 = 0, 1, 2, 5


class OnnxGraphLimitError(PolicyFileError):
    """An ONNX graph over a limit: its size, its entries, a tensor's elements, its work, or a
    shape that cannot be bounded."""


class OnnxSizeError(OnnxGraphLimitError):
    """An ONNX file whose graph is over a limit on its entries or its structure, or that holds
    model-local functions: refused before it is parsed."""


def _varint(data: memoryview, at: int) -> tuple[int, int]:
    """The varint at ``data[at:]`` and the offset after it."""
    value, shift = 0, 0
    while True:
        if at >= len(data) or shift > 63:
            raise ValueError("a truncated or overlong varint")
        byte = data[at]
        value |= (byte & 0x7F) << shift
        at, shift = at + 1, shift + 7
        if byte < 0x80:
            return value, at


def fields(data: memoryview, start: int, end: int):
    """``(field number, wire type, value start, value end)`` of each field of the message
    encoded in ``data[start:end]``; a varint's value is not decoded (start..end spans it).

    Raises:
        ValueError: an encoding that is not protobuf's (truncated, a group, a bad wire type).
    """
    at = start
    while at < end:
        key, at = _varint(data, at)
        number, wire = key >> 3, key & 7
        if wire == _VARINT:
            _, after = _varint(data, at)
        elif wire == _BYTES:
            size, at = _varint(data, at)
            after = at + size
        elif wire in (_FIXED64, _FIXED32):
            after = at + (8 if wire == _FIXED64 else 4)
        else:
            raise ValueError(f"wire type {wire} of field {number} (groups are not ONNX's)")
        if after > end or number == 0:
            raise ValueError(f"field {number} runs past the end of its message")
        yield number, wire, at, after
        at = after


def _numbers(message: Any) -> dict[int, str]:
    return {f.number: f.name for f in message.DESCRIPTOR.fields}


def check_encoding(onnx: Any, data: bytes, source: str) -> None:
    """Walk the encoding of an ONNX model (``onnx``: the package, for its field numbers) and
    refuse it before parsing (see the module docstring).

    Raises:
        OnnxSizeError: over a limit, or model-local functions / training graphs.
        PolicyFileError: not a protobuf encoding.
    """
    view = memoryview(data)
    model, graph = _numbers(onnx.ModelProto), _numbers(onnx.GraphProto)
    tensor = _numbers(onnx.TensorProto)
    counts = dict.fromkeys(GRAPH_LIMITS, 0)
    payload = 0
    try:
        for number, wire, start, end in fields(view, 0, len(view)):
            name = model.get(number)
            if name in REFUSED_MODEL_FIELDS and wire == _BYTES:
                raise OnnxSizeError(
                    f"{source} holds {REFUSED_MODEL_FIELDS[name]}: refused, export the policy "
                    "again (mjx-arm export RUN_DIR -o POLICY)"
                )
            if name == "graph" and wire == _BYTES:
                payload += _walk_graph(view, start, end, graph, tensor, counts, source)
    except OnnxSizeError:
        raise
    except ValueError as exc:  # the encoding is not protobuf's
        raise PolicyFileError(f"cannot read {source} as an ONNX model: {exc}") from exc
    structure = len(data) - payload
    if structure > MAX_STRUCTURE_BYTES:
        raise OnnxSizeError(
            f"{source}: its graph structure (all but the initializers' numbers) is {structure:,} "
            f"bytes, over the limit of {MAX_STRUCTURE_BYTES:,}; refused before parsing"
        )


def _walk_graph(view, start: int, end: int, graph: dict, tensor: dict, counts, source) -> int:
    """Count the entries of one encoded GraphProto into ``counts`` (refusing one over its
    limit, :class:`OnnxSizeError`); returns the bytes of its initializers' payloads."""
    payload = 0
    for number, wire, begin, after in fields(view, start, end):
        name = graph.get(number)
        if name not in counts or wire != _BYTES:
            continue
        counts[name] += 1
        if counts[name] > GRAPH_LIMITS[name]:
            raise OnnxSizeError(
                f"{source}: its graph has more than {GRAPH_LIMITS[name]} entries of "
                f"{name!r}, the limit for a policy graph (an exported one has a few dozen); "
                "refused before parsing"
            )
        if name == "initializer":
            for field, kind, low, high in fields(view, begin, after):
                if kind == _BYTES and tensor.get(field) in PAYLOAD_FIELDS:
                    payload += high - low
    return payload
