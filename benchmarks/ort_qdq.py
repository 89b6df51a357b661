#!/usr/bin/python3
"""ONNX Runtime's int8 for a float ONNX model, without onnxruntime's Python quantizer (which ships
through pip only): static post-training quantization in ONNX's QDQ form, as
onnxruntime.quantization.quantize_static writes it with QuantFormat.QDQ and MinMax calibration:
uint8 activations per tensor, int8 weights per output channel (symmetric), int32 biases; a ReLU
after a quantized Conv or Add is folded into its output's range. ONNX Runtime fuses each
DequantizeLinear -> op -> QuantizeLinear group into its int8 kernels (QLinearConv, QLinearAdd,
QLinearConcat, ...) when it loads the model.

  ort_qdq.py augment MODEL OUT            MODEL with every float activation a graph output, for
                                          calibration (benchmarks/ort_bench.mjs --ranges runs it)
  ort_qdq.py quantize MODEL RANGES OUT    the QDQ model from the ranges seen ({tensor: [min, max]})

MODEL should be ONNX Runtime's own basic optimisation of the exported model (ort_bench.mjs
--optimized writes it): constants folded, so that every Conv weight is an initializer.
"""
import json
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper, shape_inference

# Ops whose float activations (inputs and output) are quantized; MaxPool and Resize keep their
# input's scale (ONNX Runtime then runs them on the 8-bit values).
QUANTIZED = {"Conv", "Add", "Mul", "Concat", "MaxPool", "Resize", "Sigmoid", "GlobalAveragePool"}
SAME_SCALE = {"MaxPool", "Resize"}


def float_tensors(model):
    """Names of the float activations (inferred types)."""
    inferred = shape_inference.infer_shapes(model)
    g = inferred.graph
    types = {v.name: v.type.tensor_type.elem_type for v in list(g.value_info) + list(g.input) + list(g.output)}
    inits = {i.name for i in g.initializer}
    return {n for n, t in types.items() if t == TensorProto.FLOAT and n not in inits}


def activation_inputs(node, floats, inits):
    """The inputs of `node` that get quantized: its float activations (Resize: the image only)."""
    names = node.input[:1] if node.op_type in ("Resize", "Conv") else node.input
    return [n for n in names if n in floats and n not in inits]


def quantized_nodes(graph, floats, inits):
    out = []
    for node in graph.node:
        if node.op_type not in QUANTIZED:
            continue
        ins = activation_inputs(node, floats, inits)
        # Add / Mul with a constant (the heads' 0.3 x + 0.01): left in float, as they are cheap.
        if node.op_type in ("Add", "Mul") and len(ins) != len(node.input):
            continue
        if node.op_type == "Conv" and node.input[1] not in inits:
            continue
        out.append(node)
    return out


def augment(src, dst):
    model = onnx.load(src)
    floats = float_tensors(model)
    have = {o.name for o in model.graph.output}
    for node in model.graph.node:
        for name in node.output:
            if name in floats and name not in have:
                model.graph.output.append(helper.make_tensor_value_info(name, TensorProto.FLOAT, None))
                have.add(name)
    onnx.save(model, dst)


def fold_relus(graph, quantized, consumers):
    """Conv/Add -> Relu, the Relu the output's only consumer: the Relu goes, its output becomes the op's
    (quantized to [0, max], where the Relu's clipping happens)."""
    outputs = {o.name for o in graph.output}
    ids = {id(n) for n in quantized}
    drop = []
    for node in graph.node:
        if id(node) not in ids or node.op_type not in ("Conv", "Add"):
            continue
        users = consumers.get(node.output[0], [])
        if len(users) == 1 and users[0].op_type == "Relu" and node.output[0] not in outputs:
            node.output[0] = users[0].output[0]
            drop.append(users[0])
    for d in drop:
        graph.node.remove(d)


def params(lo, hi):
    lo, hi = min(0.0, float(lo)), max(0.0, float(hi))
    if hi - lo < 1e-4:
        hi = lo + 1e-4 * 255
    scale = (hi - lo) / 255.0
    return np.float32(scale), np.uint8(min(255, max(0, round(-lo / scale))))


def dequantized_constant(name, q, scale, new_inits, new_nodes):
    """q (integers, per output channel: dimension 0) with its scales, as an initializer read through a
    DequantizeLinear (zero points 0); returns the name of the float tensor it gives."""
    new_inits += [numpy_helper.from_array(q, name), numpy_helper.from_array(scale, name + "_scale"),
                  numpy_helper.from_array(np.zeros(q.shape[0], q.dtype), name + "_zero_point")]
    new_nodes.append(helper.make_node("DequantizeLinear", [name, name + "_scale", name + "_zero_point"], [name + "_dq"],
                                      name=name + "_DQ", axis=0))
    return name + "_dq"


def quantize(src, ranges_file, dst):
    model = onnx.load(src)
    g = model.graph
    ranges = json.load(open(ranges_file))
    floats = float_tensors(model)
    inits = {i.name: i for i in g.initializer}
    quantized = quantized_nodes(g, floats, inits)
    consumers = {}
    for node in g.node:
        for name in node.input:
            consumers.setdefault(name, []).append(node)
    fold_relus(g, quantized, consumers)

    # Each quantized activation: its scale and zero point (MaxPool / Resize outputs: their input's).
    qp = {}
    for node in quantized:
        for name in activation_inputs(node, floats, inits):
            if name not in qp:
                qp[name] = params(*ranges[name])
    for node in quantized:
        out = node.output[0]
        if node.op_type in SAME_SCALE and node.input[0] in qp:
            qp[out] = qp[node.input[0]]
        elif out not in qp:
            qp[out] = params(*ranges[out])

    new_nodes, new_inits = [], []
    for name, (scale, zp) in qp.items():
        s, z = f"{name}_scale", f"{name}_zero_point"
        new_inits += [numpy_helper.from_array(np.array(scale, np.float32), s),
                      numpy_helper.from_array(np.array(zp, np.uint8), z)]
        new_nodes += [helper.make_node("QuantizeLinear", [name, s, z], [name + "_q"], name=name + "_Q"),
                      helper.make_node("DequantizeLinear", [name + "_q", s, z], [name + "_dq"], name=name + "_DQ")]
    for node in g.node:  # every consumer of a quantized tensor reads it through its DequantizeLinear
        for k, name in enumerate(node.input):
            if name in qp:
                node.input[k] = name + "_dq"

    # Conv weights int8 per output channel, biases int32 at input scale x weight scale.
    for node in quantized:
        if node.op_type != "Conv":
            continue
        w = numpy_helper.to_array(inits[node.input[1]]).astype(np.float32)
        w_scale = np.maximum(np.abs(w).reshape(w.shape[0], -1).max(axis=1) / 127.0, 1e-12).astype(np.float32)
        wq = np.clip(np.round(w / w_scale.reshape(-1, *([1] * (w.ndim - 1)))), -127, 127).astype(np.int8)
        # (Named after the node: ONNX Runtime shares equal constants between nodes, and each node's
        # quantized copy is its own.)
        node.input[1] = dequantized_constant(node.output[0] + "_weight_int8", wq, w_scale, new_inits, new_nodes)
        if len(node.input) > 2 and node.input[2] in inits:
            b = numpy_helper.to_array(inits[node.input[2]]).astype(np.float32)
            x_scale = qp[node.input[0][: -len("_dq")]][0]
            b_scale = (x_scale * w_scale).astype(np.float32)
            bq = np.round(b / b_scale).astype(np.int32)
            node.input[2] = dequantized_constant(node.output[0] + "_bias_int32", bq, b_scale, new_inits, new_nodes)

    # The float weights no longer read go; the new nodes go before the first reader (topological
    # order: a QuantizeLinear right after the node making its tensor).
    used = {n for node in list(g.node) + new_nodes for n in node.input}
    keep = [i for i in g.initializer if i.name in used]
    del g.initializer[:]
    g.initializer.extend(keep + [i for i in new_inits if i.name in used])
    producers = {}
    for node in new_nodes:
        producers.setdefault(node.input[0], []).append(node)
    ordered = []

    def emit(node):
        ordered.append(node)
        for out in node.output:
            for after in producers.pop(out, []):
                emit(after)

    for name in [i.name for i in g.input] + list(inits):
        for after in producers.pop(name, []):
            emit(after)
    for node in list(g.node):
        emit(node)
    for rest in producers.values():  # weights' DequantizeLinear nodes (their inputs are initializers)
        ordered = rest + ordered
    del g.node[:]
    g.node.extend(ordered)
    onnx.checker.check_model(model)
    onnx.save(model, dst)
    print(f"ort_qdq: {len(qp)} quantized activations, {sum(n.op_type == 'Conv' for n in quantized)} int8 convolutions")


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "augment":
        augment(sys.argv[2], sys.argv[3])
    elif len(sys.argv) == 5 and sys.argv[1] == "quantize":
        quantize(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        sys.exit(__doc__)
