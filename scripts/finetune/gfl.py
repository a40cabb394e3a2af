"""NanoDet's GFL head in torch: anchor points, box decode, ATSS assignment and the losses.

Conventions match the C++ decoder (src/core/detection/detector.cpp, decodeNanoDet):
anchor point of grid cell (i, j) at ((j + center_offset) * stride, (i + center_offset) * stride),
cells row-major per stride, strides concatenated in order; each side's distance is the
expectation of a softmax over reg_max + 1 bins, times the stride.
Boxes are (x_min, y_min, x_max, y_max) in network-input pixels.
"""
import math

import torch
import torch.nn.functional as F


def anchor_points(input_w, input_h, strides, center_offset=0.5):
    """[N, 3] rows (cx, cy, stride) over all strides, in the decoder's order."""
    rows = []
    for s in strides:
        gw, gh = math.ceil(input_w / s), math.ceil(input_h / s)
        ys, xs = torch.meshgrid(torch.arange(gh, dtype=torch.float32), torch.arange(gw, dtype=torch.float32),
                                indexing="ij")
        cx = (xs.reshape(-1) + center_offset) * s
        cy = (ys.reshape(-1) + center_offset) * s
        rows.append(torch.stack([cx, cy, torch.full_like(cx, float(s))], 1))
    return torch.cat(rows, 0)


def distribution_to_distance(reg, reg_max):
    """[..., 4 * (reg_max + 1)] bin logits -> [..., 4] distances in units of the stride."""
    p = F.softmax(reg.reshape(*reg.shape[:-1], 4, reg_max + 1), dim=-1)
    return (p * torch.arange(reg_max + 1, dtype=p.dtype)).sum(-1)


def distance_to_box(points, dist):
    """points [N, 3] (cx, cy, stride), dist [N, 4] in pixels (left, top, right, bottom)."""
    return torch.stack([points[:, 0] - dist[:, 0], points[:, 1] - dist[:, 1],
                        points[:, 0] + dist[:, 2], points[:, 1] + dist[:, 3]], 1)


def box_to_distance(points, boxes):
    """The inverse of distance_to_box, in pixels."""
    return torch.stack([points[:, 0] - boxes[:, 0], points[:, 1] - boxes[:, 1],
                        boxes[:, 2] - points[:, 0], boxes[:, 3] - points[:, 1]], 1)


def decode(reg, points, reg_max):
    """Bin logits [N, 4 * (reg_max + 1)] -> boxes [N, 4] in input pixels."""
    return distance_to_box(points, distribution_to_distance(reg, reg_max) * points[:, 2:3])


def box_iou(a, b):
    """Pairwise IoU, a [N, 4], b [M, 4] -> [N, M]."""
    area_a = (a[:, 2] - a[:, 0]).clamp(min=0) * (a[:, 3] - a[:, 1]).clamp(min=0)
    area_b = (b[:, 2] - b[:, 0]).clamp(min=0) * (b[:, 3] - b[:, 1]).clamp(min=0)
    lt = torch.max(a[:, None, :2], b[None, :, :2])
    rb = torch.min(a[:, None, 2:], b[None, :, 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    union = area_a[:, None] + area_b[None, :] - inter
    return torch.where(union > 0, inter / union.clamp(min=1e-9), torch.zeros_like(inter))


def giou_loss(pred, target):
    """1 - GIoU of matched rows."""
    lt = torch.max(pred[:, :2], target[:, :2])
    rb = torch.min(pred[:, 2:], target[:, 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    area_p = (pred[:, 2:] - pred[:, :2]).clamp(min=0).prod(-1)
    area_t = (target[:, 2:] - target[:, :2]).clamp(min=0).prod(-1)
    union = area_p + area_t - inter + 1e-7
    enclose = (torch.max(pred[:, 2:], target[:, 2:]) - torch.min(pred[:, :2], target[:, :2])).clamp(min=0).prod(-1)
    return 1 - (inter / union - (enclose - union) / (enclose + 1e-7))


def atss_assign(points, strides, gt_boxes, topk=9, anchor_scale=5.0):
    """ATSS (Zhang et al. 2020) as NanoDet uses it, for one image.

    Each anchor point stands for a square box of anchor_scale * stride. For every ground-truth
    box, the topk anchors per stride whose centres are closest to the box centre are candidates;
    those with IoU >= mean + std of the candidates' IoUs and with the centre inside the box are
    positive. An anchor positive for several boxes takes the one with the highest IoU.
    Returns [N] long: index of the assigned box, -1 for background.
    """
    n = points.shape[0]
    assigned = torch.full((n,), -1, dtype=torch.long)
    if gt_boxes.numel() == 0:
        return assigned
    half = points[:, 2:3] * anchor_scale / 2
    anchors = torch.cat([points[:, :2] - half, points[:, :2] + half], 1)
    ious = box_iou(anchors, gt_boxes)  # [N, G]
    gt_c = (gt_boxes[:, :2] + gt_boxes[:, 2:]) / 2
    dist = torch.cdist(points[:, :2], gt_c)  # [N, G]
    cand = []
    for s in strides:
        idx = torch.nonzero(points[:, 2] == s).squeeze(1)
        k = min(topk, idx.numel())
        cand.append(idx[dist[idx].topk(k, dim=0, largest=False).indices])  # [k, G]
    cand = torch.cat(cand, 0)
    g = torch.arange(gt_boxes.shape[0])
    cand_iou = ious[cand, g[None, :]]
    thr = cand_iou.mean(0) + cand_iou.std(0, unbiased=True)
    cx, cy = points[cand, 0], points[cand, 1]
    inside = ((cx > gt_boxes[None, :, 0]) & (cx < gt_boxes[None, :, 2]) &
              (cy > gt_boxes[None, :, 1]) & (cy < gt_boxes[None, :, 3]))
    positive = (cand_iou >= thr[None, :]) & inside
    best = torch.full((n, gt_boxes.shape[0]), -1.0)
    rows, cols = torch.nonzero(positive, as_tuple=True)
    best[cand[rows, cols], cols] = ious[cand[rows, cols], cols]
    max_iou, arg = best.max(1)
    assigned[max_iou >= 0] = arg[max_iou >= 0]
    return assigned


def quality_focal_loss(logits, target_cls, target_score, beta=2.0):
    """QFL (Li et al. 2020): sigmoid BCE towards the IoU on the positive's class, 0 elsewhere,
    scaled by |sigma - target|^beta. logits [N, C]; target_cls [N] (-1 background); target_score [N]."""
    sig = logits.sigmoid()
    target = torch.zeros_like(logits)
    pos = target_cls >= 0
    target[pos, target_cls[pos]] = target_score[pos]
    bce = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return (bce * (sig - target).abs().pow(beta)).sum()


def distribution_focal_loss(reg, target_dist, reg_max):
    """DFL: cross-entropy to the two bins either side of the target distance (units of the
    stride), weighted by closeness. reg [P, 4 * (reg_max + 1)], target_dist [P, 4] -> [P]."""
    logits = reg.reshape(-1, reg_max + 1)
    t = target_dist.reshape(-1).clamp(0, reg_max - 0.01)
    left = t.floor().long()
    w_left = (left + 1).float() - t
    loss = (F.cross_entropy(logits, left, reduction="none") * w_left +
            F.cross_entropy(logits, left + 1, reduction="none") * (1 - w_left))
    return loss.reshape(-1, 4).mean(1)


def gfl_loss(cls_logits, reg, points, strides, gt, reg_max, w_qfl=1.0, w_dfl=0.25, w_giou=2.0):
    """Loss of a batch. cls_logits [B, N, C], reg [B, N, 4 * (reg_max + 1)];
    gt: per image a tensor [G, 5] (class, x_min, y_min, x_max, y_max) in input pixels.
    Returns total and its parts (detached floats), normalised by the number of positives."""
    q_sum = d_sum = g_sum = 0.0
    n_pos, w_sum = 0, 0.0
    for b in range(cls_logits.shape[0]):
        boxes = gt[b][:, 1:] if gt[b].numel() else torch.zeros((0, 4))
        assigned = atss_assign(points, strides, boxes)
        pos = torch.nonzero(assigned >= 0).squeeze(1)
        target_cls = torch.full((points.shape[0],), -1, dtype=torch.long)
        score = torch.zeros(points.shape[0])
        if pos.numel():
            tb = boxes[assigned[pos]]
            target_cls[pos] = gt[b][assigned[pos], 0].long()
            pred_box = decode(reg[b, pos], points[pos], reg_max)
            iou = box_iou(pred_box.detach(), tb).diagonal()
            score[pos] = iou.clamp(min=0)
            # Box losses weighted by the predicted confidence, as NanoDet does.
            weight = cls_logits[b, pos].detach().sigmoid().max(1).values
            g_sum = g_sum + (giou_loss(pred_box, tb) * weight).sum()
            target_dist = box_to_distance(points[pos], tb) / points[pos, 2:3]
            d_sum = d_sum + (distribution_focal_loss(reg[b, pos], target_dist, reg_max) * weight).sum()
            w_sum += float(weight.sum())
            n_pos += pos.numel()
        q_sum = q_sum + quality_focal_loss(cls_logits[b], target_cls, score)
    n = max(n_pos, 1)
    wn = max(w_sum, 1e-6)
    q = q_sum / n
    d = d_sum / wn if n_pos else torch.zeros(())
    g = g_sum / wn if n_pos else torch.zeros(())
    total = w_qfl * q + w_dfl * d + w_giou * g
    return total, {"qfl": float(q), "dfl": float(d), "giou": float(g), "pos": n_pos}
