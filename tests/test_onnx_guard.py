"""An ONNX graph from elsewhere is checked before ONNX Runtime loads it: an export's operators and sizes only."""

from __future__ import annotations

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from pecli.errors import ExportError  # noqa: E402
from pecli.onnx_guard import MAX_MODEL_BYTES, check_graph  # noqa: E402


def graph(nodes: list, initializers: list | None = None) -> bytes:
    """A one-output model of ``nodes`` (the last one's output ``y``), with an input ``obs``."""
    made = helper.make_graph(
        nodes,
        "g",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["n", 4])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)],
        initializer=initializers or [],
    )
    return helper.make_model(made, opset_imports=[helper.make_opsetid("", 17)]).SerializeToString()


def huge_header() -> TensorProto:
    """A constant whose header claims 10^9 elements (its data is never there: the header alone is refused)."""
    tensor = TensorProto(name="w", data_type=TensorProto.FLOAT)
    tensor.dims.extend([10**9])
    return tensor


def with_sparse_or_external(kind: str) -> bytes:
    """A graph with a sparse constant of 10^12 elements, or a constant read from another file."""
    model = onnx.load_from_string(graph([helper.make_node("Relu", ["obs"], ["y"])]))
    if kind == "sparse":
        values = numpy_helper.from_array(np.ones(1, np.float32), "s")
        indices = numpy_helper.from_array(np.zeros(1, np.int64), "i")
        model.graph.sparse_initializer.append(helper.make_sparse_tensor(values, indices, [10**6, 10**6]))
    else:
        tensor = numpy_helper.from_array(np.ones(4, np.float32), "w")
        tensor.ClearField("raw_data")
        tensor.data_location = TensorProto.EXTERNAL
        tensor.external_data.add(key="location", value="weights.bin")
        model.graph.initializer.append(tensor)
    return model.SerializeToString()


def test_a_small_plain_graph_passes() -> None:
    check_graph(graph([helper.make_node("Relu", ["obs"], ["y"])]))


@pytest.mark.parametrize(
    ("model", "says"),
    [
        (
            graph(
                [helper.make_node("ConstantOfShape", ["shape"], ["y"])],
                [numpy_helper.from_array(np.array([10**6, 10**6], np.int64), "shape")],
            ),
            "ConstantOfShape of",
        ),
        (
            graph(
                [
                    helper.make_node(
                        "Constant", [], ["shape"], value=numpy_helper.from_array(np.array([10**5, 10**5]))
                    ),
                    helper.make_node("Expand", ["obs", "shape"], ["y"]),
                ]
            ),
            "Expand of",
        ),
        (
            graph(
                [helper.make_node("Tile", ["obs", "r"], ["y"])],
                [numpy_helper.from_array(np.array([10**4, 10**4], np.int64), "r")],
            ),
            "Tile of repeats",
        ),
        (
            graph(
                [helper.make_node("Range", ["a", "b", "c"], ["y"])],
                [numpy_helper.from_array(np.array(0.0, np.float32), name) for name in "a"]
                + [
                    numpy_helper.from_array(np.array(1e12, np.float32), "b"),
                    numpy_helper.from_array(np.array(1.0, np.float32), "c"),
                ],
            ),
            "a Range of",
        ),
        (graph([helper.make_node("Loop", ["m", "cond"], ["y"])]), "the operator Loop"),
        (graph([helper.make_node("Relu", ["obs"], ["y"], domain="com.evil")]), "another domain"),
        (graph([helper.make_node("Add", ["obs", "w"], ["y"])], [huge_header()]), "a constant of shape"),
        (
            graph(
                [
                    helper.make_node("Constant", [], ["a"], value=numpy_helper.from_array(np.array([10**6, 10**6]))),
                    helper.make_node("Identity", ["a"], ["b"]),
                    helper.make_node("ConstantOfShape", ["b"], ["y"]),
                ]
            ),
            "Identity of",
        ),
        (
            graph(
                [
                    helper.make_node("Constant", [], ["a"], value_ints=[4096]),
                    helper.make_node("Concat", ["a", "a", "a"], ["b"], axis=0),
                    helper.make_node("ConstantOfShape", ["b"], ["y"]),
                ]
            ),
            "ConstantOfShape of shape",
        ),
        (
            graph(
                [
                    helper.make_node("Shape", ["obs"], ["s"]),
                    helper.make_node("Constant", [], ["k"], value_ints=[10**7]),
                    helper.make_node("Concat", ["s", "k"], ["b"], axis=0),
                    helper.make_node("Expand", ["obs", "b"], ["y"]),
                ]
            ),
            "value_ints",
        ),
        (
            graph(
                [helper.make_node("Add", ["obs", "w"], ["y"])],
                [numpy_helper.from_array(np.full(4, np.nan, np.float32), "w")],
            ),
            "the constant w of NaN or infinite values",
        ),
        (
            graph(
                [
                    helper.make_node("Constant", [], ["w"], value=numpy_helper.from_array(np.array([np.inf]))),
                    helper.make_node("Add", ["obs", "w"], ["y"]),
                ]
            ),
            "a constant of NaN or infinite values",
        ),
        (graph([helper.make_node("Elu", ["obs"], ["y"], alpha=float("nan"))]), "Elu with alpha NaN or infinite"),
        (with_sparse_or_external("sparse"), "sparse constants"),
        (with_sparse_or_external("external"), "stored in another file"),
        (b"\x00not a model", "not an ONNX model"),
        (b"\x00" * (MAX_MODEL_BYTES + 1), "more than an export ever is"),
    ],
)
def test_what_no_export_holds_is_refused_in_one_line(model: bytes, says: str) -> None:
    with pytest.raises(ExportError, match=says) as refused:
        check_graph(model, "x.onnx")
    assert "\n" not in str(refused.value)
