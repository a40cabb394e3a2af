"""Fine-tunes the COCO NanoDet on labelled grayscale fisheye frames (the paper's Sec. III-B).

Step 1 trains only the first conv and the head's last 1x1 convs (whose class rows are
replaced by the dataset's classes); step 2 trains every layer. After each epoch: validation
precision / recall / AP on a held-out folder (with --val-every N: every N-th epoch and each
step's last), an atomic checkpoint (tmp + rename), an ONNX
export checked to load in OpenCV's dnn and renamed into place, and the training curve PNG.
An interrupted run therefore leaves the last good checkpoint and a model that loads.
"""
import argparse
import json
import math
import os
import random
import signal
import sys
import time
import warnings

import cv2
import numpy as np
import torch
import torchvision

from . import dataset as ds
from . import gfl, metrics
from .onnx_torch import OnnxNet

MEAN = (103.53, 116.28, 123.675)  # config/detector/nanodet.yaml (BGR)
STD = (57.375, 57.12, 58.395)
STRIDES = (8, 16, 32)
REG_MAX = 10
COCO_NAMES = "/usr/share/darknet/data/coco.names"
# A new class starts from the COCO class row nearest to it (unknown names: car).
COCO_START = {"car": "car", "van": "car", "suv": "car", "pickup": "truck", "truck": "truck", "lorry": "truck",
              "bus": "bus", "vehicle": "car", "motorbike": "motorbike", "motorcycle": "motorbike",
              "bicycle": "bicycle", "train": "train", "person": "person"}


def cache_dir():
    base = os.environ.get("FISHEYE_MAPPING_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "fisheye_mapping")
    return base


def parse_size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not WIDTHxHEIGHT")
    if w <= 0 or h <= 0 or w % 32 or h % 32:
        raise argparse.ArgumentTypeError(f"'{text}': width and height must be positive multiples of 32")
    return w, h


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="finetune_detector",
        description="Fine-tune the COCO NanoDet on YOLO-format folders of grayscale fisheye frames "
                    "(images/NAME.png, labels/NAME.txt with 'class cx cy w h' normalised, classes.txt).")
    p.add_argument("train", nargs="+", help="training folder(s)")
    p.add_argument("--val", required=True, action="append",
                   help="validation folder (a different drive seed than the training folders); repeatable")
    p.add_argument("--base-model", default=os.path.join(cache_dir(), "models", "nanodet-416.onnx"),
                   help="COCO NanoDet ONNX to start from (default: %(default)s)")
    p.add_argument("--out-dir", default=os.path.join(cache_dir(), "models", "finetuned"),
                   help="outputs: model, checkpoint, curve, log (default: %(default)s)")
    p.add_argument("--name", default="nanodet-fisheye", help="output file stem (default: %(default)s)")
    p.add_argument("--input-size", type=parse_size, default=(512, 288),
                   help="network input WIDTHxHEIGHT, multiples of 32 (default 512x288: the 1024x544 "
                        "frames at half size)")
    p.add_argument("--epochs1", type=int, default=10, help="step 1 epochs, first + last layers (default 10)")
    p.add_argument("--epochs2", type=int, default=20, help="step 2 epochs, all layers (default 20)")
    # The paper's 1e-4 / 1e-5 are for 2,609 images x 10 / 20 epochs; the default run here makes
    # about 1/9 of those updates, so both rates are ten times the paper's.
    p.add_argument("--lr1", type=float, default=1e-3, help="step 1 Adam learning rate (default 1e-3; paper 1e-4)")
    p.add_argument("--lr2", type=float, default=1e-4, help="step 2 Adam learning rate (default 1e-4; paper 1e-5)")
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--max-images", type=int, default=300,
                   help="training images used, evenly spaced (default 300: about 15-25 minutes on 2 cores; 0: all)")
    p.add_argument("--max-val-images", type=int, default=40, help="validation images used (default 40; 0: all)")
    p.add_argument("--keep-empty", action="store_true",
                   help="use images with empty label files as background-only frames (default: skip them)")
    p.add_argument("--val-every", type=int, default=1,
                   help="validate after every N-th epoch and after each step's last one (default 1: every "
                        "epoch); validation does not change the weights, it only costs time")
    p.add_argument("--score-threshold", type=float, default=0.3, help="validation score threshold (default 0.3)")
    p.add_argument("--min-height", type=float, default=24.0,
                   help="validation: boxes shorter than this (image pixels) are ignored (default 24)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (default: all cores)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--resume", action="store_true", help="continue from OUT_DIR/NAME.ckpt")
    p.add_argument("--max-minutes", type=float, default=0,
                   help="stop cleanly (checkpoint + model kept) after this many minutes (default: no limit)")
    a = p.parse_args(argv)
    for k in ("epochs1", "epochs2", "batch", "val_every"):
        if getattr(a, k) < (1 if k in ("batch", "val_every") else 0):
            p.error(f"--{k.replace('_', '-')} must be positive, got {getattr(a, k)}")
    return a


# --- data ---------------------------------------------------------------------------------------
def report_problems(problems, what):
    counts = problems.summary()
    if not counts:
        return
    print(f"{what}: skipped items:", ", ".join(f"{n} {k}" for k, n in counts.items()))
    for kind in counts:
        msgs = [m for k, m in problems.items if k == kind]
        for m in msgs[:5]:
            print(f"  {kind}: {m}")
        if len(msgs) > 5:
            print(f"  ... and {len(msgs) - 5} more {kind}")


def to_batch(samples, args, augment, rng):
    nw, nh = args.input_size
    xs, gts = [], []
    for s in samples:
        grey, boxes = s.grey, s.boxes.copy()
        if augment:
            if rng.random() < 0.5:  # mirror: the fisheye image is symmetric about its vertical axis
                grey = grey[:, ::-1].copy()
                w = grey.shape[1]
                boxes[:, [1, 3]] = w - boxes[:, [3, 1]]
            gain, offset = rng.uniform(0.7, 1.3), rng.uniform(-25, 25)
            grey = np.clip(grey.astype(np.float32) * gain + offset, 0, 255).astype(np.uint8)
        x, (sx, sy, px, py) = ds.make_input(grey, nw, nh, MEAN, STD)
        b = boxes.copy()
        b[:, [1, 3]] = b[:, [1, 3]] * sx + px
        b[:, [2, 4]] = b[:, [2, 4]] * sy + py
        xs.append(x)
        gts.append(torch.from_numpy(b))
    return torch.from_numpy(np.stack(xs)), gts


def split_outputs(outs):
    """The graph's outputs (cls per stride, then reg per stride) -> cls [B, N, C], reg [B, N, 44]."""
    k = len(outs) // 2
    return torch.cat(outs[:k], 1), torch.cat(outs[k:], 1)


# --- validation -----------------------------------------------------------------------------------
@torch.no_grad()
def detect(net, points, sample, args):
    nw, nh = args.input_size
    x, (sx, sy, px, py) = ds.make_input(sample.grey, nw, nh, MEAN, STD)
    cls, reg = split_outputs(net(torch.from_numpy(x)[None]))
    scores, labels = cls[0].max(1)
    keep = scores >= args.score_threshold
    if not keep.any():
        return np.zeros((0, 4)), np.zeros(0)
    boxes = gfl.decode(reg[0, keep], points[keep], REG_MAX)
    k = torchvision.ops.batched_nms(boxes, scores[keep], labels[keep], 0.5)
    b, s = boxes[k].numpy(), scores[keep][k].numpy()
    h, w = sample.grey.shape[:2]
    b[:, [0, 2]] = ((b[:, [0, 2]] - px) / sx).clip(0, w)
    b[:, [1, 3]] = ((b[:, [1, 3]] - py) / sy).clip(0, h)
    return b, s


def validate(net, points, samples, args):
    net.cls_logits = False
    matches, n_gt = [], 0
    for s in samples:
        b, sc = detect(net, points, s, args)
        m, g = metrics.match_image(b, sc, s.boxes[:, 1:], 0.5, args.min_height)
        matches += m
        n_gt += g
    net.cls_logits = True
    return metrics.summarise(matches, n_gt)


# --- outputs ----------------------------------------------------------------------------------------
def atomic_write(path, write):
    tmp = path + ".tmp"
    write(tmp)
    os.replace(tmp, path)


def export_onnx(net, path, args):
    """Exports with the base graph's input / output names; the file only replaces the previous
    one once OpenCV's dnn (the reader the C++ Detector uses) has loaded it."""
    nw, nh = args.input_size
    net.cls_logits = False
    tmp = path + ".tmp"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tracer's notes on constant sizes: intended (fixed input)
        torch.onnx.export(net, torch.zeros(1, 3, nh, nw), tmp, opset_version=11, input_names=[net.input_name],
                          output_names=net.output_names, do_constant_folding=True)
    net.cls_logits = True
    cv_net = cv2.dnn.readNetFromONNX(tmp)
    if cv_net.empty():
        raise RuntimeError(f"{tmp}: exported model does not load in OpenCV dnn")
    os.replace(tmp, path)


def write_model_yaml(path, onnx_path, names_path, classes, args):
    nw, nh = args.input_size
    text = (f"# Written by scripts/finetune_detector: NanoDet fine-tuned on grayscale fisheye frames.\n"
            f"format: onnx\nmodel: {onnx_path}\ninput_size: [{nw}, {nh}]\nhead: nanodet\n"
            f"strides: [8, 16, 32]\nreg_max: {REG_MAX}\ncenter_offset: 0.5\nclass_names: {names_path}\n"
            f"swap_rb: false\nmean: {list(MEAN)}\nstd: {list(STD)}\nletterbox: true\npad_value: 114\n"
            f"score_threshold: {args.score_threshold}\nnms_threshold: 0.5\n"
            f"moving_classes: [{', '.join(classes)}]\npersons_moving: false\n")
    atomic_write(path, lambda t: open(t, "w").write(text))


def plot_curve(path, history):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ep = [h["epoch_total"] for h in history]
    val = [h for h in history if h.get("precision") is not None]  # --val-every: validated epochs only
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(ep, [h["loss"] for h in history], "o-", label="train loss")
    ax[0].set_xlabel("epoch")
    ax[0].set_ylabel("GFL loss")
    ax[0].legend()
    for k in ("precision", "recall", "ap"):
        ax[1].plot([h["epoch_total"] for h in val], [h[k] for h in val], "o-", label=k)
    ax[1].set_xlabel("epoch")
    ax[1].set_ylim(0, 1.02)
    ax[1].legend()
    ax[1].set_title("validation (IoU 0.5)")
    steps = [h["epoch_total"] for h in history if h["step"] == 2]
    if steps:
        for a in ax:
            a.axvline(steps[0] - 0.5, color="grey", ls="--")
    fig.tight_layout()
    atomic_write(path, lambda t: fig.savefig(t, format="png", dpi=80))
    plt.close(fig)


# --- model ------------------------------------------------------------------------------------------
def build_model(args, classes):
    net = OnnxNet(args.base_model)
    with open(COCO_NAMES) as f:
        coco = [line.strip() for line in f if line.strip()]
    if net.num_classes() != len(coco):
        raise ds.DatasetError(f"{args.base_model}: {net.num_classes()} classes, expected COCO's {len(coco)}")
    rows = [coco.index(COCO_START.get(c.lower(), "car")) for c in classes]
    net.replace_classes(rows)
    net.cls_logits = True
    return net


def set_trainable(net, step):
    first_last = {id(p) for p in net.layer_params("first") + net.layer_params("last")}
    for p in net.parameters():
        p.requires_grad = step == 2 or id(p) in first_last
    return [p for p in net.parameters() if p.requires_grad]


class Interrupted(BaseException):  # not swallowed by a library's "except Exception"
    pass


def main(argv):
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    rng = random.Random(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(args.threads or os.cpu_count() or 1)
    if not os.path.isfile(args.base_model):
        print(f"finetune_detector: base model {args.base_model} missing (scripts/setup makes it)", file=sys.stderr)
        return 2
    try:
        tp = ds.Problems()
        classes, train, size = ds.load_folders(args.train, tp, max_items=args.max_images or None,
                                               keep_empty=args.keep_empty)
        report_problems(tp, "training data")
        vp = ds.Problems()
        vclasses, val, _ = ds.load_folders(args.val, vp, expected_size=size, max_items=args.max_val_images or None)
        report_problems(vp, "validation data")
        if vclasses != classes:
            raise ds.DatasetError(f"validation classes {vclasses} differ from training classes {classes}")
        if not train:
            raise ds.DatasetError("no usable training images (see the skipped items above)")
        if not val:
            raise ds.DatasetError("no usable validation images (see the skipped items above)")
        net = build_model(args, classes)
    except (ds.DatasetError, ValueError) as e:
        print(f"finetune_detector: {e}; training not started", file=sys.stderr)
        return 2
    nw, nh = args.input_size
    n_boxes = sum(len(s.boxes) for s in train)
    print(f"classes {classes}; training {len(train)} images ({n_boxes} boxes) from {', '.join(args.train)}; "
          f"validation {len(val)} images from {', '.join(args.val)}; frames {size[0]}x{size[1]}, input {nw}x{nh}")

    os.makedirs(args.out_dir, exist_ok=True)
    stem = os.path.join(args.out_dir, args.name)
    paths = {k: stem + ext for k, ext in (("onnx", ".onnx"), ("ckpt", ".ckpt"), ("png", "-curve.png"),
                                          ("names", ".names"), ("yaml", ".yaml"), ("log", "-log.json"))}
    atomic_write(paths["names"], lambda t: open(t, "w").write("\n".join(classes) + "\n"))
    write_model_yaml(paths["yaml"], paths["onnx"], paths["names"], classes, args)
    points = gfl.anchor_points(nw, nh, STRIDES)

    history, start_step, start_epoch = [], 1, 0
    if args.resume and os.path.isfile(paths["ckpt"]):
        ck = torch.load(paths["ckpt"])
        if ck["classes"] != classes or tuple(ck["input_size"]) != (nw, nh):
            print(f"finetune_detector: {paths['ckpt']} was trained for classes {ck['classes']} at "
                  f"{ck['input_size']}, not {classes} at {nw}x{nh}; not resumed", file=sys.stderr)
            return 2
        net.load_state_dict(ck["model"])
        history, start_step, start_epoch = ck["history"], ck["step"], ck["epoch"] + 1
        if start_epoch >= (args.epochs1 if start_step == 1 else args.epochs2):
            start_step, start_epoch = start_step + 1, 0
        print(f"resumed from {paths['ckpt']}: step {start_step}, epoch {start_epoch + 1}")

    stop = []

    def on_signal(signum, frame):
        # Only noted here: raised inside a torch op it would surface as a RuntimeError. The
        # loop stops at the next batch boundary, leaving the last epoch's files as they are.
        stop.append(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    t_start = time.time()
    try:
        for step in (1, 2):
            if step < start_step:
                continue
            epochs, lr = (args.epochs1, args.lr1) if step == 1 else (args.epochs2, args.lr2)
            params = set_trainable(net, step)
            opt = torch.optim.Adam(params, lr=lr)
            if args.resume and step == start_step and start_epoch > 0 and "optim" in ck and ck["step"] == step:
                opt.load_state_dict(ck["optim"])
            print(f"step {step}: {'first and last layers' if step == 1 else 'all layers'} "
                  f"({sum(p.numel() for p in params)} parameters), Adam lr {lr}, {epochs} epochs")
            for epoch in range(start_epoch if step == start_step else 0, epochs):
                t0 = time.time()
                order = list(range(len(train)))
                rng.shuffle(order)
                losses = []
                nb = math.ceil(len(order) / args.batch)
                for bi in range(nb):
                    x, gts = to_batch([train[i] for i in order[bi * args.batch:(bi + 1) * args.batch]], args, True, rng)
                    cls, reg = split_outputs(net(x))
                    loss, parts = gfl.gfl_loss(cls, reg, points, STRIDES, gts, REG_MAX)
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
                    losses.append(float(loss))
                    if not history and epoch == 0 and bi == min(2, nb - 1):
                        # timed over the first batches: the very first one also pays torch's warm-up
                        per_batch = (time.time() - t0) / (bi + 1)
                        est = estimate_minutes(per_batch, nb, args)
                        print(f"  {per_batch:.1f} s per batch of {args.batch}: the run should take about {est:.0f} "
                              f"min (validation and export add a little)", flush=True)
                    if stop:
                        raise Interrupted(stop[0])
                    if args.max_minutes and time.time() - t_start > args.max_minutes * 60:
                        raise Interrupted(f"--max-minutes {args.max_minutes}")
                if stop:
                    raise Interrupted(stop[0])
                # Validation only every --val-every epochs and at the end of each step; the
                # weights are the same either way (it draws no random numbers).
                if (epoch + 1) % args.val_every == 0 or epoch + 1 == epochs:
                    v = validate(net, points, val, args)
                else:
                    v = {k: None for k in ("precision", "recall", "ap", "tp", "fp", "gt")}
                h = {"step": step, "epoch": epoch, "epoch_total": len(history) + 1, "loss": float(np.mean(losses)),
                     "seconds": time.time() - t0, **v}
                history.append(h)
                if v["precision"] is None:
                    print(f"step {step} epoch {epoch + 1}/{epochs}: loss {h['loss']:.3f}  (not validated: "
                          f"--val-every {args.val_every})  {h['seconds']:.0f} s", flush=True)
                else:
                    print(f"step {step} epoch {epoch + 1}/{epochs}: loss {h['loss']:.3f}  val precision "
                          f"{v['precision']:.3f} recall {v['recall']:.3f} AP50 {v['ap']:.3f} "
                          f"(TP {v['tp']} FP {v['fp']} of {v['gt']})  {h['seconds']:.0f} s", flush=True)
                ck = {"model": net.state_dict(), "optim": opt.state_dict(), "step": step, "epoch": epoch,
                      "history": history, "classes": classes, "input_size": [nw, nh]}
                atomic_write(paths["ckpt"], lambda t: torch.save(ck, t))
                export_onnx(net, paths["onnx"], args)
                atomic_write(paths["log"], lambda t: open(t, "w").write(json.dumps(history, indent=1)))
                plot_curve(paths["png"], history)
            print(f"step {step} done: model {paths['onnx']}")
    except Interrupted as e:
        if history:
            print(f"finetune_detector: interrupted ({e}) in step {step}; last good checkpoint {paths['ckpt']} "
                  f"(epoch {len(history)}), model {paths['onnx']} (rerun with --resume to continue)", file=sys.stderr)
        else:
            print(f"finetune_detector: interrupted ({e}) before the first epoch ended; nothing written "
                  f"besides {paths['yaml']}", file=sys.stderr)
        return 130
    print(f"done in {(time.time() - t_start) / 60:.1f} min: model {paths['onnx']}, model YAML {paths['yaml']}, "
          f"curve {paths['png']}")
    return 0


def estimate_minutes(batch_seconds, batches, args):
    # Step 1 back-propagates through the frozen middle without its weight gradients: about 0.8 of step 2.
    return batch_seconds * batches * (0.8 * args.epochs1 + args.epochs2) / 60 * 1.08
