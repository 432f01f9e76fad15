"""An ONNX graph from elsewhere, checked before ONNX Runtime loads it: only the operators pecli's exports use, and
no constant or constant-shaped tensor larger than an export ever holds.

A downloaded zoo may hold a graph built to exhaust memory (``ConstantOfShape`` of ``[10^6, 10^6]``) or to loop
(``Loop``, ``Scan``, ``If``). :func:`check_graph` refuses both in one line. Shapes a graph computes from its inputs
are bounded by the sidecar's input sizes, which :class:`pecli.runtime.ExportedModel` checks. The check needs the
``onnx`` package (``pecli[export]``); a robot running only ``onnxruntime`` plays its own exports and skips it.
"""

from __future__ import annotations

import math
from typing import Any

from pecli.errors import ExportError

MAX_MODEL_BYTES = 256 << 20  # an export is kilobytes to a few megabytes
MAX_ELEMENTS = 1 << 24  # elements of one constant, or of a tensor a constant shape asks for (64 MiB of float32)

# every operator of pecli's exports, for each belief kind (and a margin of plain elementwise ones)
ALLOWED_OPS = frozenset({
    "Abs", "Add", "And", "Cast", "Clip", "Concat", "Constant", "ConstantOfShape", "Conv", "Cos", "CumSum", "Div",
    "Elu", "Equal", "Exp", "Expand", "Flatten", "Floor", "Gather", "GatherElements", "Gemm", "Greater",
    "GreaterOrEqual", "Identity", "LSTM", "Less", "LessOrEqual", "Log", "MatMul", "Max", "MaxPool", "Min", "Mul", "Neg",
    "Not", "Or", "Pow", "Range", "Reciprocal", "ReduceMax", "ReduceMean", "ReduceMin", "ReduceSum", "Relu", "Reshape",
    "Shape", "Sigmoid", "Sign", "Sin", "Slice", "Softmax", "Softplus", "Sqrt", "Squeeze", "Sub", "Tanh", "Tile",
    "Transpose", "Unsqueeze", "Where",
})
# operators whose output size a constant input decides: (the input's index, what it holds)
SIZED_BY = {"ConstantOfShape": (0, "shape"), "Expand": (1, "shape"), "Reshape": (1, "shape"), "Tile": (1, "repeats")}


def _elements(dims: Any) -> int:
    return math.prod(max(int(d), 1) for d in dims)


def check_graph(model: bytes, source: str = "model") -> None:
    """:class:`ExportError` in one line if ``model`` (serialised ONNX) is larger, or uses other operators or
    larger constants, than a pecli export; nothing (the check skipped) without the ``onnx`` package."""
    if len(model) > MAX_MODEL_BYTES:
        raise ExportError(f"{source}: {len(model):,} bytes, more than an export ever is ({MAX_MODEL_BYTES:,})")
    try:
        import onnx
        from onnx import numpy_helper
    except ImportError:
        return
    try:
        graph = onnx.load_from_string(model).graph
    except Exception as exc:  # protobuf's own errors for bytes that are no model
        raise ExportError(f"{source}: not an ONNX model ({type(exc).__name__})") from None
    if graph.node and any(node.domain not in ("", "ai.onnx") for node in graph.node):
        raise ExportError(f"{source}: uses operators of another domain than ONNX's own, which no pecli export does")
    constants: dict[str, Any] = {}
    for tensor in graph.initializer:
        if _elements(tensor.dims) > MAX_ELEMENTS:
            raise ExportError(f"{source}: a constant of shape {list(tensor.dims)}, larger than any export holds")
        constants[tensor.name] = tensor
    for node in graph.node:
        if node.op_type not in ALLOWED_OPS:
            raise ExportError(f"{source}: uses the operator {node.op_type[:40]}, which no pecli export does: pecli "
                              "loads graphs from elsewhere only with the operators of its own exports")
        for attribute in node.attribute:
            if attribute.type == onnx.AttributeProto.TENSOR and _elements(attribute.t.dims) > MAX_ELEMENTS:
                raise ExportError(f"{source}: a constant of shape {list(attribute.t.dims)}, larger than any export "
                                  "holds")
            if attribute.type == onnx.AttributeProto.TENSOR and node.op_type == "Constant":
                constants[node.output[0]] = attribute.t
        if node.op_type in SIZED_BY:
            index, what = SIZED_BY[node.op_type]
            if len(node.input) > index and node.input[index] in constants:
                values = numpy_helper.to_array(constants[node.input[index]]).reshape(-1)
                if values.size > 64 or _elements(abs(int(v)) for v in values) > MAX_ELEMENTS:
                    raise ExportError(f"{source}: {node.op_type} of {what} {values[:8].tolist()}"
                                      f"{'...' if values.size > 8 else ''}, larger than any export computes")
        if node.op_type == "Range" and all(name in constants for name in node.input[:3]):
            start, limit, delta = (float(numpy_helper.to_array(constants[name]).reshape(-1)[0])
                                   for name in node.input[:3])
            if delta == 0 or not math.isfinite((limit - start) / delta) or (limit - start) / delta > MAX_ELEMENTS:
                raise ExportError(f"{source}: a Range of {start:g} to {limit:g} by {delta:g}, larger than any export "
                                  "computes")
