"""YOLOX's training loss: SimOTA label assignment, IoU loss on boxes, BCE on objectness and on IoU-aware classes.

Follows Ge et al., "YOLOX: Exceeding YOLO Series in 2021" (arXiv:2107.08430, section 2.1 "SimOTA") and the
reference implementation ``yolox/models/yolo_head.py`` (``get_assignments``, ``simota_matching``): an anchor is a
candidate for a ground-truth box when its centre lies in the box or within 2.5 strides of the box's centre; its cost is
``cls_cost + 3 * (-log IoU)`` (+1e5 outside both regions); each box takes the ``k`` cheapest anchors where ``k`` is
the sum of its 10 best IoUs (at least 1), and an anchor claimed by several boxes keeps the cheapest. Losses, as there:
``5 * (1 - IoU^2)`` per positive (the reference's default ``iou`` loss type), BCE objectness over every anchor
(target 1 on positives), BCE classes on positives with the matched IoU as target, all divided by the positives.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from torch.nn import functional as F

__all__ = ["YoloxLoss", "LossParts", "decode_maps", "box_iou", "UNLABELLED_IGNORE"]

#: objectness x class probability from which an unassigned anchor of a class its source does not label is ignored
UNLABELLED_IGNORE = 0.3


@dataclass(frozen=True)
class LossParts:
    """One batch's loss and its parts (floats, for the progress bar): total, iou, obj, cls, positives per image."""

    total: float
    iou: float
    obj: float
    cls: float
    positives: float


def decode_maps(maps: list[torch.Tensor], strides: tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor,
                                                                               torch.Tensor]:
    """Flatten the per-stride raw maps ``(B, 5 + nc, h, w)`` into ``(B, A, 5 + nc)`` with boxes decoded to
    ``(cx, cy, w, h)`` input pixels (``xy = (p + grid) * stride``, ``wh = exp(p) * stride``), and return it with the
    anchor centres ``(A, 2)`` and strides ``(A,)`` in pixels."""
    outs, centres, strides_a = [], [], []
    for m, s in zip(maps, strides):
        b, c, h, w = m.shape
        yv, xv = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
        grid = torch.stack((xv, yv), dim=-1).reshape(-1, 2).to(m.dtype)
        p = m.flatten(2).permute(0, 2, 1)
        xy = (p[..., :2] + grid) * s
        wh = torch.exp(p[..., 2:4].clamp(max=10.0)) * s
        outs.append(torch.cat([xy, wh, p[..., 4:]], dim=-1))
        centres.append((grid + 0.5) * s)
        strides_a.append(torch.full((h * w,), float(s), dtype=m.dtype))
    return torch.cat(outs, 1), torch.cat(centres), torch.cat(strides_a)


def box_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Pairwise IoU of ``(N, 4)`` and ``(M, 4)`` ``(cx, cy, w, h)`` boxes: ``(N, M)``."""
    a0, a1 = a[:, None, :2] - a[:, None, 2:] / 2, a[:, None, :2] + a[:, None, 2:] / 2
    b0, b1 = b[None, :, :2] - b[None, :, 2:] / 2, b[None, :, :2] + b[None, :, 2:] / 2
    inter = (torch.min(a1, b1) - torch.max(a0, b0)).clamp(min=0).prod(-1)
    return inter / (a[:, None, 2:].prod(-1) + b[None, :, 2:].prod(-1) - inter + 1e-9)


class YoloxLoss:
    """SimOTA assignment and YOLOX losses (see the module docstring for the source).

    Args:
        n_classes: classes of the head.
        strides: the head's strides in pixels (8, 16, 32).
        center_radius: the centre region's radius in strides (2.5 in YOLOX).
    """

    def __init__(self, n_classes: int, strides: tuple[int, ...] = (8, 16, 32), center_radius: float = 2.5) -> None:
        self.nc = n_classes
        self.strides = strides
        self.radius = center_radius

    def __call__(self, maps: list[torch.Tensor], targets: list[torch.Tensor],
                 labelled: torch.Tensor | None = None) -> tuple[torch.Tensor, LossParts]:
        """``maps``: the model's raw per-stride outputs; ``targets``: per image ``(N, 5)`` float ``(class, x0, y0,
        x1, y1)`` in input pixels; ``labelled``: ``(B, nc)`` bool, the classes each image's source labels
        exhaustively (None: all). Where a class is not labelled, anchors the model already takes for that class
        (objectness x class probability >= ``UNLABELLED_IGNORE``, not assigned to a box) are left out of the
        objectness loss instead of being taught as background. Returns the loss to back-propagate and its parts."""
        pred, centres, strides = decode_maps(maps, self.strides)
        obj_t = torch.zeros(pred.shape[:2], dtype=pred.dtype)
        obj_w = torch.ones(pred.shape[:2], dtype=pred.dtype)
        if labelled is not None and not bool(labelled.all()):
            with torch.no_grad():
                prob = torch.sigmoid(pred[..., 4:5]) * torch.sigmoid(pred[..., 5:])  # (B, A, nc)
                unl = (prob * (~labelled)[:, None, :].to(prob.dtype)).amax(-1)
                obj_w[unl >= UNLABELLED_IGNORE] = 0.0
        box_p, box_t, cls_p, cls_t = [], [], [], []
        n_pos = 0
        for i, t in enumerate(targets):
            if len(t) == 0:
                continue
            gt = torch.cat([(t[:, 1:3] + t[:, 3:5]) / 2, (t[:, 3:5] - t[:, 1:3]).clamp(min=1.0)], dim=1)
            with torch.no_grad():
                pos, gt_idx, ious = self._assign(pred[i].detach(), gt, t[:, 0].long(), centres, strides)
            if pos.numel() == 0:
                continue
            n_pos += pos.numel()
            obj_t[i, pos] = 1.0
            obj_w[i, pos] = 1.0
            box_p.append(pred[i, pos, :4])
            box_t.append(gt[gt_idx])
            cls_p.append(pred[i, pos, 5:])
            cls_t.append(F.one_hot(t[gt_idx, 0].long(), self.nc).to(pred.dtype) * ious[:, None])
        denom = max(n_pos, 1)
        loss_obj = F.binary_cross_entropy_with_logits(pred[..., 4], obj_t, weight=obj_w, reduction="sum") / denom
        if n_pos:
            bp, bt = torch.cat(box_p), torch.cat(box_t)
            iou = box_iou(bp, bt).diagonal()
            loss_iou = 5.0 * (1 - iou ** 2).sum() / denom
            loss_cls = F.binary_cross_entropy_with_logits(torch.cat(cls_p), torch.cat(cls_t), reduction="sum") / denom
        else:
            loss_iou = loss_cls = pred.sum() * 0.0
        total = loss_iou + loss_obj + loss_cls
        parts = LossParts(total.item(), loss_iou.item(), loss_obj.item(), loss_cls.item(), n_pos / max(len(targets), 1))
        return total, parts

    def _assign(self, pred: torch.Tensor, gt: torch.Tensor, gt_cls: torch.Tensor, centres: torch.Tensor,
                strides: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """SimOTA for one image: the positive anchors, the box each matched, and its IoU."""
        g0, g1 = gt[:, None, :2] - gt[:, None, 2:] / 2, gt[:, None, :2] + gt[:, None, 2:] / 2
        c = centres[None]
        in_box = ((c > g0) & (c < g1)).all(-1)
        r = (self.radius * strides)[None, :, None]
        in_ctr = ((c > gt[:, None, :2] - r) & (c < gt[:, None, :2] + r)).all(-1)
        cand = (in_box | in_ctr).any(0)
        if not cand.any():
            return torch.empty(0, dtype=torch.long), torch.empty(0, dtype=torch.long), torch.empty(0)
        cidx = torch.nonzero(cand).squeeze(1)
        p = pred[cidx]
        ious = box_iou(gt, p[:, :4])  # (G, C)
        cls_prob = (torch.sigmoid(p[:, 5:]) * torch.sigmoid(p[:, 4:5])).sqrt()  # (C, nc)
        onehot = F.one_hot(gt_cls, self.nc).to(p.dtype)  # (G, nc)
        cls_cost = F.binary_cross_entropy(cls_prob[None].expand(len(gt), -1, -1).clamp(1e-6, 1 - 1e-6),
                                          onehot[:, None].expand(-1, len(cidx), -1), reduction="none").sum(-1)
        both = in_box[:, cidx] & in_ctr[:, cidx]
        cost = cls_cost + 3.0 * -torch.log(ious + 1e-8) + 1e5 * (~both)
        k = torch.topk(ious, min(10, ious.shape[1]), dim=1).values.sum(1).int().clamp(min=1)
        match = torch.zeros_like(cost, dtype=torch.bool)
        for g in range(len(gt)):
            match[g, torch.topk(cost[g], int(min(k[g], cost.shape[1])), largest=False).indices] = True
        multi = match.sum(0) > 1
        if multi.any():
            best = cost[:, multi].argmin(0)
            match[:, multi] = False
            match[best, torch.nonzero(multi).squeeze(1)] = True
        anchor_has = match.any(0)
        gt_idx = match[:, anchor_has].float().argmax(0)
        pos_ious = ious[gt_idx, torch.nonzero(anchor_has).squeeze(1)]
        return cidx[anchor_has], gt_idx, pos_ious
