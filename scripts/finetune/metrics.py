"""Precision, recall and AP at an IoU threshold, the rule detector_eval (src/tools/detector_eval.cpp) uses.

Every class counts as "vehicle". Boxes shorter than min_height pixels are ignored on both
sides: a short ground-truth box is no miss, a detection matched to one is no false positive,
and an unmatched short detection is no false positive either. Detections are matched greedily
in descending score, preferring an unmatched counted box over an ignored one.
"""
import numpy as np


def iou_matrix(a, b):
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(-1)
    area = lambda x: np.clip(x[:, 2:] - x[:, :2], 0, None).prod(-1)
    union = area(a)[:, None] + area(b)[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0)


def match_image(dets, scores, gts, iou_thr=0.5, min_height=24.0):
    """dets [D, 4], scores [D], gts [G, 4] (x_min, y_min, x_max, y_max, image pixels).
    Returns ([(score, is_tp)] of the counted detections, number of counted ground-truth boxes)."""
    dets, gts = np.asarray(dets, float).reshape(-1, 4), np.asarray(gts, float).reshape(-1, 4)
    counted = (gts[:, 3] - gts[:, 1]) >= min_height
    ious = iou_matrix(dets, gts)
    used = np.zeros(len(gts), bool)
    out = []
    for d in np.argsort(-np.asarray(scores), kind="stable"):
        best, best_key = -1, None
        for g in range(len(gts)):
            if used[g] or ious[d, g] < iou_thr:
                continue
            key = (counted[g], ious[d, g])  # counted boxes first, then the higher IoU
            if best_key is None or key > best_key:
                best, best_key = g, key
        if best >= 0:
            used[best] = True
            if counted[best]:
                out.append((float(scores[d]), True))
        elif dets[d, 3] - dets[d, 1] >= min_height:
            out.append((float(scores[d]), False))
    return out, int(counted.sum())


def summarise(matches, n_gt):
    """matches: [(score, is_tp)] over a dataset. Returns precision, recall, AP (all-point
    interpolated area under the precision-recall curve) and the TP / FP counts."""
    tp = sum(1 for _, t in matches if t)
    fp = len(matches) - tp
    precision = tp / (tp + fp) if tp + fp else 1.0
    recall = tp / n_gt if n_gt else 1.0
    ap = average_precision(matches, n_gt)
    return {"precision": precision, "recall": recall, "ap": ap, "tp": tp, "fp": fp, "gt": n_gt}


def average_precision(matches, n_gt):
    if n_gt == 0:
        return 1.0 if not matches else 0.0
    order = sorted(matches, key=lambda m: -m[0])
    tps = np.cumsum([1 if t else 0 for _, t in order])
    fps = np.cumsum([0 if t else 1 for _, t in order])
    rec = np.concatenate([[0.0], tps / n_gt])
    prec = np.concatenate([[1.0], tps / np.maximum(tps + fps, 1)])
    # precision envelope (monotone non-increasing from the right), then sum over recall steps
    for i in range(len(prec) - 2, -1, -1):
        prec[i] = max(prec[i], prec[i + 1])
    return float(np.sum((rec[1:] - rec[:-1]) * prec[1:]))
