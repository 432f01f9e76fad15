"""An ONNX graph from elsewhere, checked before ONNX Runtime loads it: only the operators pecli's exports use, and
no constant or constant-shaped tensor larger than an export ever holds.

A downloaded zoo may hold a graph built to exhaust memory (``ConstantOfShape`` of ``[10^6, 10^6]``) or to loop
(``Loop``, ``Scan``, ``If``). :func:`check_graph` refuses, in one line: other operators, functions, subgraphs,
sparse, external, NaN or infinite constants, a constant of more than 2^24 elements, a size (``ConstantOfShape``,
``Expand``, ``Reshape``, ``Tile``, ``Range``) that constants decide (folded through ``Concat``, ``Mul``, ... ) above
2^24 elements, and any whole-number constant above 65 536 on the way to a size. What remains are sizes computed from the
inputs' shapes, which the sidecar bounds (:class:`pecli.runtime.ExportedModel`), times small constants. The check
needs the ``onnx`` package (``pecli[export]``); a robot with only ``onnxruntime`` plays its own exports and skips it.
"""

from __future__ import annotations

import math
from typing import Any

from pecli.errors import ExportError

MAX_MODEL_BYTES = 256 << 20  # an export is kilobytes to a few megabytes
MAX_ELEMENTS = 1 << 24  # elements of one constant, or of a tensor a constant shape asks for (64 MiB of float32)

# every operator of pecli's exports, for each belief kind (and a margin of plain elementwise ones)
ALLOWED_OPS = frozenset(
    {
        "Abs",
        "Add",
        "And",
        "Cast",
        "Clip",
        "Concat",
        "Constant",
        "ConstantOfShape",
        "Conv",
        "Cos",
        "CumSum",
        "Div",
        "Elu",
        "Equal",
        "Exp",
        "Expand",
        "Flatten",
        "Floor",
        "Gather",
        "GatherElements",
        "Gemm",
        "Greater",
        "GreaterOrEqual",
        "Identity",
        "LSTM",
        "Less",
        "LessOrEqual",
        "Log",
        "MatMul",
        "Max",
        "MaxPool",
        "Min",
        "Mul",
        "Neg",
        "Not",
        "Or",
        "Pow",
        "Range",
        "Reciprocal",
        "ReduceMax",
        "ReduceMean",
        "ReduceMin",
        "ReduceSum",
        "Relu",
        "Reshape",
        "Shape",
        "Sigmoid",
        "Sign",
        "Sin",
        "Slice",
        "Softmax",
        "Softplus",
        "Sqrt",
        "Squeeze",
        "Sub",
        "Tanh",
        "Tile",
        "Transpose",
        "Unsqueeze",
        "Where",
    }
)
# operators whose output size a constant input decides: (the input's index, what it holds)
SIZED_BY = {"ConstantOfShape": (0, "shape"), "Expand": (1, "shape"), "Reshape": (1, "shape"), "Tile": (1, "repeats")}


def _elements(dims: Any) -> int:
    return math.prod(max(abs(int(d)), 1) for d in dims)


# the operators through which a shape is computed from constants: folded here to see the size it asks for
FOLDED = {"Identity", "Cast", "Concat", "Unsqueeze", "Squeeze", "Mul", "Add", "Sub", "Neg", "Abs", "Max", "Min"}
MAX_DIM = 65_536  # one dimension a constant may ask for (a layer's width; the largest an export has is far less)


def _fold(node: Any, values: list[Any]) -> Any:
    """The value of a shape-computing ``node`` whose inputs are the constant ``values``; None if not foldable."""
    import numpy as np

    if any(v is None for v in values) or any(v.size > 64 for v in values):
        return None
    op = node.op_type
    if op in ("Identity", "Cast"):
        return values[0]
    if op == "Concat":
        return np.concatenate([v.reshape(-1) for v in values])
    if op in ("Unsqueeze", "Squeeze"):
        return values[0].reshape(-1)
    if op == "Neg":
        return -values[0]
    if op == "Abs":
        return np.abs(values[0])
    if op in ("Mul", "Add", "Sub", "Max", "Min") and len(values) == 2:
        with np.errstate(all="ignore"):
            a, b = (v.astype(np.float64) for v in values)
            return {"Mul": np.multiply, "Add": np.add, "Sub": np.subtract, "Max": np.maximum, "Min": np.minimum}[op](
                a, b
            )
    return None


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
        proto = onnx.load_from_string(model)
    except Exception as exc:  # protobuf's own errors for bytes that are no model
        raise ExportError(f"{source}: not an ONNX model ({type(exc).__name__})") from None
    graph = proto.graph

    def refuse(what: str) -> ExportError:
        return ExportError(
            f"{source}: {what}, which no pecli export has: pecli loads graphs from elsewhere only "
            "with what its own exports hold"
        )

    if proto.functions or graph.sparse_initializer:
        raise refuse("functions or sparse constants")
    if any(node.domain not in ("", "ai.onnx") for node in graph.node):
        raise refuse("operators of another domain than ONNX's own")
    constants: dict[str, Any] = {}
    for tensor in graph.initializer:
        if tensor.data_location == onnx.TensorProto.EXTERNAL or tensor.external_data:
            raise refuse("a constant stored in another file")
        if _elements(tensor.dims) > MAX_ELEMENTS:
            raise refuse(f"a constant of shape {list(tensor.dims)[:8]}")
        if not _finite(numpy_helper.to_array(tensor)):
            raise refuse(f"the constant {tensor.name[:40]} of NaN or infinite values")
        constants[tensor.name] = numpy_helper.to_array(tensor) if _elements(tensor.dims) <= 64 else None
    for node in graph.node:
        if node.op_type not in ALLOWED_OPS:
            raise refuse(f"the operator {node.op_type[:40]}")
        for attribute in node.attribute:
            if attribute.type in (
                onnx.AttributeProto.SPARSE_TENSOR,
                onnx.AttributeProto.SPARSE_TENSORS,
                onnx.AttributeProto.GRAPH,
                onnx.AttributeProto.GRAPHS,
            ):
                raise refuse("a sparse constant or a subgraph")
            tensors = [attribute.t] if attribute.type == onnx.AttributeProto.TENSOR else list(attribute.tensors)
            if any(t.data_location == onnx.TensorProto.EXTERNAL or t.external_data for t in tensors):
                raise refuse("a constant stored in another file")
            if (
                any(_elements(t.dims) > MAX_ELEMENTS for t in tensors)
                or max(len(attribute.ints), len(attribute.floats), len(attribute.strings)) > MAX_ELEMENTS
            ):
                raise refuse("a constant larger than any export holds")
            if not all(map(math.isfinite, [attribute.f, *attribute.floats])):
                raise refuse(f"{node.op_type} with {attribute.name} NaN or infinite")
            if attribute.type == onnx.AttributeProto.INTS and any(abs(v) > MAX_DIM for v in attribute.ints):
                raise refuse(f"{node.op_type} with {attribute.name} {list(attribute.ints)[:8]}")
        if node.op_type == "Constant":
            if not all(_finite(numpy_helper.to_array(t)) for t in _tensors_of(node, onnx)):
                raise refuse("a constant of NaN or infinite values")
            constants[node.output[0]] = _constant(node, onnx, numpy_helper)
        elif node.op_type in FOLDED:
            constants[node.output[0]] = _fold(node, [constants.get(name) for name in node.input])
        if node.op_type in FOLDED or node.op_type in SIZED_BY:  # a shape in the making: no huge whole number in it
            for name in node.input:
                value = constants.get(name)
                if value is not None and value.dtype.kind in "iu" and (abs(value) > MAX_DIM).any():
                    raise refuse(f"{node.op_type} of {value.reshape(-1)[:8].tolist()}")
        sized = SIZED_BY.get(node.op_type)
        if sized is not None and len(node.input) > sized[0]:
            _check_size(node, sized, constants.get(node.input[sized[0]]), refuse)
        if node.op_type == "Range" and all(constants.get(name) is not None for name in node.input[:3]):
            start, limit, delta = (float(constants[name].reshape(-1)[0]) for name in node.input[:3])
            if delta == 0 or not math.isfinite((limit - start) / delta) or (limit - start) / delta > MAX_ELEMENTS:
                raise refuse(f"a Range of {start:g} to {limit:g} by {delta:g}")


def _finite(array: Any) -> bool:
    """Whether a constant holds no NaN or infinity (a network's weights never do)."""
    import numpy as np

    return array.dtype.kind not in "fc" or bool(np.isfinite(array).all())


def _tensors_of(node: Any, onnx: Any) -> list[Any]:
    """The tensors a node's attributes hold."""
    found = []
    for attribute in node.attribute:
        if attribute.type == onnx.AttributeProto.TENSOR:
            found.append(attribute.t)
        found.extend(attribute.tensors)
    return found


def _constant(node: Any, onnx: Any, numpy_helper: Any) -> Any:
    """A ``Constant`` node's value, if small enough to matter for a shape (else None)."""
    import numpy as np

    for attribute in node.attribute:
        if attribute.type == onnx.AttributeProto.TENSOR:
            return numpy_helper.to_array(attribute.t) if _elements(attribute.t.dims) <= 64 else None
        if attribute.name in ("value_int", "value_ints", "value_float", "value_floats"):
            value = onnx.helper.get_attribute_value(attribute)
            return np.asarray(value).reshape(-1) if np.asarray(value).size <= 64 else None
    return None


def _check_size(node: Any, sized: tuple[int, str], value: Any, refuse: Any) -> None:
    """The size a constant (or folded) shape input asks of ``node``, bounded."""
    if value is None:
        return  # computed from the inputs at run time (bounded by the sidecar's sizes)
    values = value.reshape(-1)
    if (
        values.size > 64
        or _elements(v for v in values if math.isfinite(float(v))) > MAX_ELEMENTS
        or not all(math.isfinite(float(v)) for v in values)
    ):
        raise refuse(f"{node.op_type} of {sized[1]} {values[:8].tolist()}{'...' if values.size > 8 else ''}")
