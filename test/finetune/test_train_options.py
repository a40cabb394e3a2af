"""train.py's --val-every: option checks and the curve of a history with unvalidated epochs.

Run: /usr/bin/python3 -m unittest discover -s test/finetune -t .   (from the repository root)
"""
import contextlib
import io
import os
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))

try:
    import torch  # noqa: F401
    import matplotlib  # noqa: F401
    from finetune import train
except ImportError as e:  # python3-torch is optional (only fine-tuning needs it)
    raise unittest.SkipTest(f"needs python3-torch and python3-matplotlib: {e}")


class ValEvery(unittest.TestCase):
    def test_default_validates_every_epoch(self):
        self.assertEqual(train.parse_args(["t", "--val", "v"]).val_every, 1)

    def test_zero_is_refused_by_name(self):
        err = io.StringIO()
        with contextlib.redirect_stderr(err), self.assertRaises(SystemExit):
            train.parse_args(["t", "--val", "v", "--val-every", "0"])
        self.assertIn("--val-every must be positive", err.getvalue())

    def test_curve_with_unvalidated_epochs(self):
        none = {"precision": None, "recall": None, "ap": None}
        history = [{"step": 1, "epoch": 0, "epoch_total": 1, "loss": 1.0, **none},
                   {"step": 1, "epoch": 1, "epoch_total": 2, "loss": 0.9, "precision": 0.5, "recall": 0.4, "ap": 0.3},
                   {"step": 2, "epoch": 0, "epoch_total": 3, "loss": 0.8, **none},
                   {"step": 2, "epoch": 1, "epoch_total": 4, "loss": 0.7, "precision": 0.6, "recall": 0.5, "ap": 0.4}]
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "curve.png")
            train.plot_curve(path, history)
            with open(path, "rb") as f:
                self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")


if __name__ == "__main__":
    unittest.main()
