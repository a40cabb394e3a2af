"""A trainable torch model read from the NanoDet ONNX graph.

The COCO NanoDet the setup fetches exists only as an ONNX file converted from
tfjs (scripts/tools/tfjs_to_onnx.py), with no torch source. OnnxNet walks the
graph's nodes in order: Conv weights and biases become nn.Parameters, every
other initializer (shapes, pads, Resize sizes) stays a constant. Only the ops
that graph uses are implemented; any other op is named in the error.

The GFL head ends in three 1x1 convs (one per stride) whose output is split
into class logits and 4 x (reg_max + 1) distance bins. replace_classes() swaps
the class rows for a new class list and keeps the distance rows, so the
exported graph keeps the layout the C++ decoder reads (cls_strideN [1, N, C],
reg_strideN [1, N, 44]).
"""
import numpy as np
import onnx
import torch
import torch.nn.functional as F
from onnx import numpy_helper


def _attrs(node):
    return {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}


def _key(name):
    # nn.ParameterDict keys may not contain '.'
    return name.replace(".", "_")


class OnnxNet(torch.nn.Module):
    def __init__(self, path):
        super().__init__()
        model = onnx.load(path)
        graph = model.graph
        inits = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
        self.nodes = []
        param_names = set()
        for n in graph.node:
            if n.op_type == "Conv":
                param_names.update(i for i in n.input[1:] if i)
            self.nodes.append({"op": n.op_type, "in": list(n.input), "out": list(n.output), "attr": _attrs(n)})
        self.params = torch.nn.ParameterDict(
            {_key(k): torch.nn.Parameter(torch.from_numpy(np.array(inits[k], np.float32))) for k in sorted(param_names)})
        self.consts = {k: v for k, v in inits.items() if k not in param_names}
        self.input_name = graph.input[0].name
        self.output_names = [o.name for o in graph.output]
        dims = graph.input[0].type.tensor_type.shape.dim
        self.onnx_input_hw = (dims[2].dim_value, dims[3].dim_value)
        self.cls_logits = False  # training: give the class outputs before the sigmoid
        self._check_ops()

    def _check_ops(self):
        known = {"Conv", "LeakyRelu", "Relu", "Concat", "Reshape", "Transpose", "Resize", "Add", "Split",
                 "Sigmoid", "Pad", "MaxPool"}
        bad = sorted({n["op"] for n in self.nodes} - known)
        if bad:
            raise ValueError("ONNX graph uses ops this loader does not implement: " + ", ".join(bad))

    # --- structure -------------------------------------------------------------------------
    def first_conv(self):
        return next(n for n in self.nodes if n["op"] == "Conv" and n["in"][0] == self.input_name)

    def head_splits(self):
        """The Split nodes that separate class logits from distance bins, with their 1x1 conv."""
        producer = {o: n for n in self.nodes for o in n["out"]}
        out = []
        for n in self.nodes:
            if n["op"] == "Split" and len(n["attr"].get("split", [])) == 2:
                out.append((n, producer[n["in"][0]]))
        return out

    def num_classes(self):
        return int(self.head_splits()[0][0]["attr"]["split"][0])

    def param(self, name):
        return self.params[_key(name)]

    def layer_params(self, which):
        """Parameters of the first conv ('first') or of the head's 1x1 convs ('last')."""
        convs = [self.first_conv()] if which == "first" else [c for _, c in self.head_splits()]
        return [self.param(i) for c in convs for i in c["in"][1:] if i]

    def replace_classes(self, source_rows):
        """New class rows: source_rows[k] is the old class row to start class k from (None:
        small random weights). Distance-bin rows are kept."""
        nc_new = len(source_rows)
        for split, conv in self.head_splits():
            nc_old, nreg = split["attr"]["split"]
            w, b = self.param(conv["in"][1]).data, self.param(conv["in"][2]).data
            w_new = torch.empty((nc_new + nreg,) + tuple(w.shape[1:]))
            b_new = torch.empty(nc_new + nreg)
            for k, src in enumerate(source_rows):
                if src is None:
                    torch.nn.init.normal_(w_new[k], std=0.01)
                    b_new[k] = -4.6  # prior probability 0.01, as NanoDet initialises its class bias
                else:
                    w_new[k], b_new[k] = w[src], b[src]
            w_new[nc_new:], b_new[nc_new:] = w[nc_old:], b[nc_old:]
            self.params[_key(conv["in"][1])] = torch.nn.Parameter(w_new)
            self.params[_key(conv["in"][2])] = torch.nn.Parameter(b_new)
            split["attr"]["split"] = [nc_new, nreg]

    # --- forward -----------------------------------------------------------------------------
    def _value(self, env, name):
        if name in env:
            return env[name]
        if _key(name) in self.params:
            return self.params[_key(name)]
        return self.consts[name]

    def forward(self, x):
        env = {self.input_name: x}
        in_h, in_w = int(x.shape[2]), int(x.shape[3])  # constants when traced for export
        for n in self.nodes:
            a, ins = n["attr"], n["in"]
            v = [self._value(env, i) if i else None for i in ins]
            op = n["op"]
            if op == "Conv":
                p = a.get("pads", [0, 0, 0, 0])
                if p[0] != p[2] or p[1] != p[3]:
                    raise ValueError("Conv with asymmetric pads is not supported")
                y = F.conv2d(v[0], v[1], v[2] if len(v) > 2 else None, stride=a.get("strides", [1, 1]),
                             padding=(p[0], p[1]), dilation=a.get("dilations", [1, 1]), groups=a.get("group", 1))
            elif op == "LeakyRelu":
                y = F.leaky_relu(v[0], a.get("alpha", 0.01))
            elif op == "Relu":
                y = F.relu(v[0])
            elif op == "Add":
                y = v[0] + v[1]
            elif op == "Concat":
                y = torch.cat(v, dim=a["axis"])
            elif op == "Sigmoid":
                # The class sigmoids are the graph's only ones; training wants the logits.
                y = v[0] if self.cls_logits else torch.sigmoid(v[0])
            elif op == "Split":
                y = torch.split(v[0], list(a["split"]), dim=a.get("axis", 0))
            elif op == "Reshape":
                shape = [int(s) for s in v[1]]
                # [1, C, -1]: flatten the grid; batch and channel count taken from the tensor so
                # the head works for any batch size and class count.
                y = v[0].flatten(2) if len(shape) == 3 and shape[2] == -1 else v[0].reshape(shape)
            elif op == "Transpose":
                y = v[0].permute(*a["perm"])
            elif op == "Pad":
                y = self._pad(v, a)
            elif op == "MaxPool":
                p = a.get("pads", [0, 0, 0, 0])
                y = F.max_pool2d(v[0], a["kernel_shape"], a.get("strides", [1, 1]), padding=(p[0], p[1]))
            elif op == "Resize":
                y = self._resize(v, a, in_h, in_w)
            if isinstance(y, (tuple, list)):
                for name, t in zip(n["out"], y):
                    env[name] = t
            else:
                env[n["out"][0]] = y
        return [env[o] for o in self.output_names]

    def _pad(self, v, a):
        pads = [int(p) for p in v[1]]
        value = float(v[2]) if len(v) > 2 and v[2] is not None else 0.0
        if a.get("mode", b"constant") not in (b"constant", "constant") or any(pads[:2]) or any(pads[4:6]):
            raise ValueError("Pad: only constant padding of H and W is supported")
        # ONNX [x1_begin, x2_begin, ..., x1_end, ...] -> F.pad (W_begin, W_end, H_begin, H_end)
        return F.pad(v[0], (pads[3], pads[7], pads[2], pads[6]), value=value)

    def _resize(self, v, a, in_h, in_w):
        sizes = v[3] if len(v) > 3 and v[3] is not None and np.size(v[3]) == 4 else None
        if sizes is None:
            raise ValueError("Resize without sizes is not supported")
        if a.get("mode") not in (b"linear", "linear") or a.get("coordinate_transformation_mode") not in (
                b"half_pixel", "half_pixel"):
            raise ValueError("Resize: only linear / half_pixel is supported")
        # The graph's sizes are fixed for its own input size; scale them to this input so the
        # model trains and exports at any multiple of 32.
        h0, w0 = self.onnx_input_hw
        out = (int(round(int(sizes[2]) * in_h / h0)), int(round(int(sizes[3]) * in_w / w0)))
        return F.interpolate(v[0], size=out, mode="bilinear", align_corners=False)
