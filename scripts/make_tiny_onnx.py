#!/usr/bin/env python3
"""Tiny ONNX models whose outputs are known exactly, for nodes/tests/onnx_models.rs.

No registry ships street segmentation or depth weights small enough for a test, so these stand in
for SegFormer/Mask2Former and DepthAnything/DepthPro: 1x1 convolutions, a few hundred bytes each.
With the test's normalisation (mean 0, std 1, so a channel is pixel / 255):

  seg_logits.onnx  input  pixel_values [1, 3, height, width] (any size)
                   output logits [1, 4, height, width]: classes 0, 1, 2 score the red, green and
                   blue channels, class 3 scores a constant 0.5, so the argmax is the dominant
                   channel when it is above 0.5, else class 3.
  seg_ids.onnx     input  pixel_values [1, 3, 4, 4] (fixed size)
                   output labels [1, 4, 4] int64: the argmax of the same logits.
  depth.onnx       input  pixel_values [1, 3, height, width] (any size)
                   output predicted_depth [1, 1, height, width] = 2 * red + 1 (exact in float32:
                   one non-zero weight, a power of two, and a bias).

Writes nodes/tests/fixtures/onnx/. Byte-identical on every run.

    pip install onnx numpy && python3 scripts/make_tiny_onnx.py
"""
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OUT = Path(__file__).resolve().parent.parent / "nodes" / "tests" / "fixtures" / "onnx"
OPSET = 17
# IR 8 (ONNX 1.13): loadable by every ONNX Runtime the `ort` crate accepts (1.17 and later).
IR_VERSION = 8


def conv_model(name, weights, bias, input_hw, extra_nodes=(), output=None):
    """pixel_values -> Conv 1x1 (weights [C, 3], bias [C]) -> optional extra nodes -> output."""
    w = np.asarray(weights, dtype=np.float32).reshape(len(weights), 3, 1, 1)
    b = np.asarray(bias, dtype=np.float32)
    h, wd = input_hw
    inp = helper.make_tensor_value_info("pixel_values", TensorProto.FLOAT, [1, 3, h, wd])
    nodes = [helper.make_node("Conv", ["pixel_values", "W", "B"], ["conv"], kernel_shape=[1, 1])]
    nodes += list(extra_nodes)
    out_name, out_type, out_shape = output or ("conv", TensorProto.FLOAT, [1, len(weights), h, wd])
    if out_name != nodes[-1].output[0]:
        nodes.append(helper.make_node("Identity", [nodes[-1].output[0]], [out_name]))
    graph = helper.make_graph(
        nodes,
        name,
        [inp],
        [helper.make_tensor_value_info(out_name, out_type, out_shape)],
        initializer=[numpy_helper.from_array(w, "W"), numpy_helper.from_array(b, "B")],
    )
    model = helper.make_model(
        graph,
        producer_name="kodama make_tiny_onnx.py",
        opset_imports=[helper.make_opsetid("", OPSET)],
    )
    model.ir_version = IR_VERSION
    onnx.checker.check_model(model, full_check=True)
    return model


# Classes 0-2: the red, green, blue channel; class 3: a constant 0.5.
SEG_W = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]
SEG_B = [0, 0, 0, 0.5]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    models = {
        "seg_logits.onnx": conv_model(
            "seg_logits",
            SEG_W,
            SEG_B,
            ("height", "width"),
            output=("logits", TensorProto.FLOAT, [1, 4, "height", "width"]),
        ),
        "seg_ids.onnx": conv_model(
            "seg_ids",
            SEG_W,
            SEG_B,
            (4, 4),
            extra_nodes=[helper.make_node("ArgMax", ["conv"], ["labels"], axis=1, keepdims=0)],
            output=("labels", TensorProto.INT64, [1, 4, 4]),
        ),
        "depth.onnx": conv_model(
            "depth",
            [[2, 0, 0]],
            [1],
            ("height", "width"),
            output=("predicted_depth", TensorProto.FLOAT, [1, 1, "height", "width"]),
        ),
    }
    for name, model in models.items():
        path = OUT / name
        onnx.save(model, path)
        print(f"{path.relative_to(OUT.parent.parent.parent.parent)}: {path.stat().st_size} bytes")


if __name__ == "__main__":
    main()
