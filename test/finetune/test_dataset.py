"""YOLO folder checks, the letterbox and the evaluation rule against hand-computed numbers.

Run: /usr/bin/python3 -m unittest discover -s test/finetune -p 'test_*.py'   (from the repository root)
"""
import os
import sys
import tempfile
import unittest

import cv2
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))

from finetune import dataset as ds  # noqa: E402
from finetune import metrics  # noqa: E402


def make_folder(root, items, classes=("car", "van")):
    for sub in ("images", "labels"):
        os.makedirs(os.path.join(root, sub), exist_ok=True)
    with open(os.path.join(root, "classes.txt"), "w") as f:
        f.write("\n".join(classes) + "\n")
    for name, (w, h), labels in items:
        cv2.imwrite(os.path.join(root, "images", name + ".png"), np.full((h, w), 100, np.uint8))
        if labels is not None:
            with open(os.path.join(root, "labels", name + ".txt"), "w") as f:
                f.write(labels)


class Folders(unittest.TestCase):
    def test_bad_items_named_with_file_and_line_and_skipped(self):
        with tempfile.TemporaryDirectory() as d:
            make_folder(d, [
                ("a_good", (64, 32), "0 0.5 0.5 0.25 0.5\n1 0.25 0.25 0.125 0.25\n"),
                ("b_empty", (64, 32), ""),
                ("c_class", (64, 32), "0 0.5 0.5 0.25 0.5\n\n2 0.5 0.5 0.1 0.1\n"),
                ("d_outside", (64, 32), "0 0.95 0.5 0.2 0.5\n"),
                ("e_size", (32, 32), "0 0.5 0.5 0.25 0.5\n"),
                ("f_nolabel", (64, 32), None),
                ("g_fields", (64, 32), "0 0.5 0.5 0.25\n"),
            ])
            problems = ds.Problems()
            classes, samples, size = ds.load_folders([d], problems)
            self.assertEqual(classes, ["car", "van"])
            self.assertEqual(size, (64, 32))
            self.assertEqual([os.path.basename(s.path) for s in samples], ["a_good.png"])
            # pixel boxes: (0.5 +- 0.125) * 64, (0.5 +- 0.25) * 32 and (0.25 +- 0.0625) * 64, (0.25 +- 0.125) * 32
            np.testing.assert_allclose(samples[0].boxes, [[0, 24, 8, 40, 24], [1, 12, 4, 20, 12]])
            msgs = "\n".join(m for _, m in problems.items)
            lab = os.path.join(d, "labels")
            self.assertIn(os.path.join(lab, "b_empty.txt") + ": no boxes", msgs)
            self.assertIn(os.path.join(lab, "c_class.txt") + ":3: class id 2 is not in classes.txt (0..1)", msgs)
            self.assertIn(os.path.join(lab, "d_outside.txt") + ":1: box x 0.8500..1.0500", msgs)
            self.assertIn("e_size.png: 32x32, expected 64x32", msgs)
            self.assertIn("f_nolabel.txt: missing", msgs)
            self.assertIn(os.path.join(lab, "g_fields.txt") + ":1: '0 0.5 0.5 0.25': 4 fields", msgs)
            self.assertEqual(sum(problems.summary().values()), 6)

    def test_different_class_lists_stop_training(self):
        with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
            make_folder(a, [("x", (64, 32), "0 0.5 0.5 0.1 0.1\n")])
            make_folder(b, [("y", (64, 32), "0 0.5 0.5 0.1 0.1\n")], classes=("car", "bus"))
            with self.assertRaisesRegex(ds.DatasetError, "classes.txt lists"):
                ds.load_folders([a, b], ds.Problems())

    def test_missing_classes_file(self):
        with tempfile.TemporaryDirectory() as d:
            with self.assertRaisesRegex(ds.DatasetError, "classes.txt: missing"):
                ds.load_folders([d], ds.Problems())


class Letterbox(unittest.TestCase):
    def test_matches_the_cpp_letterbox(self):
        # 1024x544 into 512x288: scale min(0.5, 0.529) = 0.5 -> 512x272, (288 - 272) / 2 = 8 px bands
        self.assertEqual(ds.letterbox_geometry(1024, 544, 512, 288), (0.5, 0.5, 0.0, 8.0, 512, 272))
        # 1024x544 into 416x416 as test_detector's Letterbox test: 221 rows, 97 px bands
        sx, sy, px, py, rw, rh = ds.letterbox_geometry(1024, 544, 416, 416)
        self.assertEqual((px, py, rw, rh), (0.0, 97.0, 416, 221))

    def test_input_normalised_and_padded(self):
        x, _ = ds.make_input(np.full((544, 1024), 200, np.uint8), 512, 288, (100, 110, 120), (50, 45, 40))
        self.assertEqual(x.shape, (3, 288, 512))
        self.assertAlmostEqual(float(x[0, 100, 100]), (200 - 100) / 50, places=5)
        self.assertAlmostEqual(float(x[2, 0, 0]), (114 - 120) / 40, places=5)  # pad band


class Metrics(unittest.TestCase):
    def test_hand_computed(self):
        # The case test_detector_eval.cpp works out (image pixels).
        gts = [[30, 16, 50, 48], [50, 32, 70, 64], [74, 20, 86, 36], [100, 10, 120, 40]]
        dets = [[30, 16, 50, 48], [90, 16, 110, 48], [74, 20, 86, 36], [16, 4, 24, 12], [50, 32, 70, 64]]
        scores = [0.9, 0.8, 0.6, 0.5, 0.2]
        m, n = metrics.match_image(dets, scores, gts, 0.5, 24)
        self.assertEqual(n, 3)
        self.assertEqual(m, [(0.9, True), (0.8, False), (0.2, True)])
        self.assertAlmostEqual(metrics.average_precision(m, n), 1 / 3 + 1 / 3 * 2 / 3)
        at = [x for x in m if x[0] >= 0.35]
        s = metrics.summarise(at, n)
        self.assertEqual((s["tp"], s["fp"], s["precision"]), (1, 1, 0.5))


if __name__ == "__main__":
    unittest.main()
