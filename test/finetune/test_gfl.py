"""GFL head pieces against hand-computed numbers.

Run: /usr/bin/python3 -m unittest discover -s test/finetune -t .   (from the repository root)
"""
import math
import os
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))

try:
    import torch
    from finetune import gfl
except ImportError as e:  # python3-torch is optional (only fine-tuning needs it)
    raise unittest.SkipTest(f"needs python3-torch: {e}")

REG_MAX = 10


def one_hot_bins(bin_per_side):
    """Bin logits that put all mass on one bin per side (left, top, right, bottom)."""
    reg = torch.full((4, REG_MAX + 1), -1e4)
    for side, b in enumerate(bin_per_side):
        reg[side, b] = 0.0
    return reg.reshape(1, -1)


class AnchorsAndDecode(unittest.TestCase):
    def test_anchor_points_row_major_per_stride(self):
        p = gfl.anchor_points(16, 16, [8, 16])
        expected = [[4, 4, 8], [12, 4, 8], [4, 12, 8], [12, 12, 8], [8, 8, 16]]
        self.assertEqual(p.tolist(), expected)

    def test_anchor_grid_rounds_up_like_the_cpp_decoder(self):
        # 40 px wide at stride 16: ceil(40 / 16) = 3 columns; 24 high: 2 rows
        self.assertEqual(gfl.anchor_points(40, 24, [16]).shape[0], 6)

    def test_decode_one_hot_bins(self):
        # point (12, 4) stride 8; left bin 2 -> 16 px, top 0 -> 0, right 10 -> 80, bottom 5 -> 40
        box = gfl.decode(one_hot_bins([2, 0, 10, 5]), torch.tensor([[12.0, 4.0, 8.0]]), REG_MAX)
        self.assertEqual(box.tolist(), [[12 - 16, 4 - 0, 12 + 80, 4 + 40]])

    def test_decode_is_the_softmax_expectation(self):
        reg = torch.full((4, REG_MAX + 1), -1e4)
        reg[:, 0], reg[:, 1] = 0.0, math.log(3.0)  # p = 1/4, 3/4 -> expectation 0.75 bins
        reg[3] = 0.0  # uniform over 0..10 -> 5 bins
        box = gfl.decode(reg.reshape(1, -1), torch.tensor([[100.0, 50.0, 16.0]]), REG_MAX)[0]
        for got, want in zip(box.tolist(), [100 - 12, 50 - 12, 100 + 12, 50 + 80]):
            self.assertAlmostEqual(got, want, places=4)

    def test_box_distance_round_trip(self):
        pts = torch.tensor([[20.0, 30.0, 8.0]])
        boxes = torch.tensor([[10.0, 5.0, 50.0, 45.0]])
        self.assertEqual(gfl.box_to_distance(pts, boxes).tolist(), [[10, 25, 30, 15]])
        self.assertEqual(gfl.distance_to_box(pts, gfl.box_to_distance(pts, boxes)).tolist(), boxes.tolist())


class Assignment(unittest.TestCase):
    # One stride-8 level over a 256 x 256 input: anchor centres at 4 + 8k.
    pts = gfl.anchor_points(256, 256, [8])

    def index(self, cx, cy):
        return ((cy - 4) // 8) * 32 + (cx - 4) // 8

    def test_box_centred_on_an_anchor_takes_that_anchor_only(self):
        # gt 32 x 32 centred on the anchor at (116, 116). topk 5: that anchor and its 4 neighbours.
        # Anchor boxes are 40 x 40 (5 x stride). IoU centre: 1024 / 1600 = 0.64;
        # neighbours: 28 * 32 = 896 / (1600 + 1024 - 896) = 0.5185.
        # mean 0.5428, unbiased std 0.0543 -> threshold 0.597: only the centre anchor passes.
        a = gfl.atss_assign(self.pts, [8], torch.tensor([[100.0, 100.0, 132.0, 132.0]]), topk=5)
        self.assertEqual(torch.nonzero(a >= 0).squeeze(1).tolist(), [self.index(116, 116)])
        self.assertEqual(int(a[self.index(116, 116)]), 0)

    def test_anchor_outside_the_box_is_not_positive(self):
        # A flat box 8 high between anchor rows 108 and 116 (y 109..115): the candidates' centres
        # (rows 108 / 116) are all outside it, so nothing is assigned although IoUs pass.
        a = gfl.atss_assign(self.pts, [8], torch.tensor([[100.0, 109.0, 132.0, 115.0]]), topk=5)
        self.assertEqual(int((a >= 0).sum()), 0)

    def test_shared_anchor_goes_to_the_higher_iou(self):
        # Two equal boxes on the same centre anchor: IoU ties, then a larger second box whose
        # anchor IoU is higher (40 x 40 box == anchor box, IoU 1) wins the shared anchor.
        boxes = torch.tensor([[100.0, 100.0, 132.0, 132.0], [96.0, 96.0, 136.0, 136.0]])
        a = gfl.atss_assign(self.pts, [8], boxes, topk=5)
        self.assertEqual(int(a[self.index(116, 116)]), 1)

    def test_no_boxes_no_positives(self):
        a = gfl.atss_assign(self.pts, [8], torch.zeros((0, 4)))
        self.assertTrue(bool((a == -1).all()))


class Losses(unittest.TestCase):
    def test_dfl_uniform_bins(self):
        # uniform logits: p = 1/11 in every bin, so -0.7 log p - 0.3 log p = log 11 per side
        loss = gfl.distribution_focal_loss(torch.zeros(1, 4 * (REG_MAX + 1)), torch.full((1, 4), 2.3), REG_MAX)
        self.assertAlmostEqual(float(loss), math.log(11), places=5)

    def test_dfl_exact_bin_is_near_zero(self):
        loss = gfl.distribution_focal_loss(one_hot_bins([3, 3, 3, 3]) * 1.0, torch.full((1, 4), 3.0), REG_MAX)
        self.assertLess(float(loss), 1e-3)

    def test_qfl_negative_at_half(self):
        # logit 0 -> sigma 0.5, target 0: BCE log 2 times |0.5 - 0|^2 = 0.25 log 2, for 3 classes
        loss = gfl.quality_focal_loss(torch.zeros(1, 3), torch.tensor([-1]), torch.tensor([0.0]))
        self.assertAlmostEqual(float(loss), 3 * 0.25 * math.log(2), places=6)

    def test_qfl_positive_at_its_quality_is_the_entropy_only_on_other_classes(self):
        # target IoU 0.5 on class 1: that class's term is scaled by |0.5 - 0.5|^2 = 0
        loss = gfl.quality_focal_loss(torch.zeros(1, 2), torch.tensor([1]), torch.tensor([0.5]))
        self.assertAlmostEqual(float(loss), 0.25 * math.log(2), places=6)

    def test_giou(self):
        same = gfl.giou_loss(torch.tensor([[0.0, 0, 2, 2]]), torch.tensor([[0.0, 0, 2, 2]]))
        self.assertAlmostEqual(float(same), 0.0, places=5)
        # disjoint unit boxes 1 apart: IoU 0, enclosing 3, union 2 -> GIoU -1/3, loss 4/3
        apart = gfl.giou_loss(torch.tensor([[0.0, 0, 1, 1]]), torch.tensor([[2.0, 0, 3, 1]]))
        self.assertAlmostEqual(float(apart), 4 / 3, places=5)

    def test_gfl_loss_falls_when_fitting_one_box(self):
        # A free tensor of logits and bins learns one box: the loss must drop (sanity of gradients).
        pts = gfl.anchor_points(64, 64, [8, 16, 32])
        cls = torch.full((1, pts.shape[0], 2), -4.0, requires_grad=True)
        reg = torch.zeros((1, pts.shape[0], 4 * (REG_MAX + 1)), requires_grad=True)
        gt = [torch.tensor([[1.0, 10.0, 12.0, 40.0, 36.0]])]
        opt = torch.optim.Adam([cls, reg], lr=0.1)
        first = None
        for _ in range(60):
            loss, parts = gfl.gfl_loss(cls, reg, pts, [8, 16, 32], gt, REG_MAX)
            first = first if first is not None else float(loss)
            opt.zero_grad()
            loss.backward()
            opt.step()
        self.assertGreater(parts["pos"], 0)
        self.assertLess(float(loss), 0.3 * first)


if __name__ == "__main__":
    unittest.main()
