#!/usr/bin/env python3
"""Builds a tiny ONNX model whose outputs are fixed tensors, for the head-decoder tests.

usage: make_const_onnx.py OUT.onnx INPUT_SHAPE VALUES.txt [VALUES2.txt ...]

INPUT_SHAPE like 1,3,64,64. Each VALUES file: first line the output shape
(comma separated), then the values in row-major order (whitespace separated).
Network: input -> GlobalAveragePool -> Conv 1x1 (zero weights, bias = values)
-> Reshape(shape), one branch per output, so OpenCV DNN runs a real graph whose
output does not depend on the image.
"""
import sys

import numpy as np
from onnx import TensorProto, checker, helper, numpy_helper, save


def main():
    out_path, in_shape = sys.argv[1], [int(v) for v in sys.argv[2].split(",")]
    nodes, inits, outputs = [], [], []
    nodes.append(helper.make_node("GlobalAveragePool", ["images"], ["pooled"]))
    for k, path in enumerate(sys.argv[3:]):
        with open(path) as f:
            shape = [int(v) for v in f.readline().split(",")]
            vals = np.array(f.read().split(), dtype=np.float32)
        if vals.size != int(np.prod(shape)):
            sys.exit(f"{path}: {vals.size} values for shape {shape}")
        n = vals.size
        inits.append(numpy_helper.from_array(np.zeros((n, in_shape[1], 1, 1), np.float32), f"w{k}"))
        inits.append(numpy_helper.from_array(vals, f"b{k}"))
        inits.append(numpy_helper.from_array(np.array(shape, np.int64), f"s{k}"))
        nodes.append(helper.make_node("Conv", ["pooled", f"w{k}", f"b{k}"], [f"c{k}"], kernel_shape=[1, 1]))
        nodes.append(helper.make_node("Reshape", [f"c{k}", f"s{k}"], [f"out{k}"]))
        outputs.append(helper.make_tensor_value_info(f"out{k}", TensorProto.FLOAT, shape))
    graph = helper.make_graph(nodes, "const_head",
                              [helper.make_tensor_value_info("images", TensorProto.FLOAT, in_shape)],
                              outputs, inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)])
    model.ir_version = 6
    checker.check_model(model)
    save(model, out_path)


if __name__ == "__main__":
    main()
