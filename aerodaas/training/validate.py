"""Validation during training: recall, precision and AP50 of a PyTorch YOLOX module on fixed validation tiles.

The tiles are cut once, reproducibly (:class:`aerodaas.training.augment.TileSampler` with the scale and crop steps
only: no view or sensor augmentation), so successive epochs are scored on the same pixels. Scoring is
:func:`aerodaas.perception.scoring.score` (PASCAL VOC matching at IoU 0.5, all-point AP); detections are the decoded
head after class-aware NMS (OpenCV's ``cv2.dnn.NMSBoxes``) at ``score_threshold``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from aerodaas.model.types import Detection
from aerodaas.perception.scoring import GroundTruth, score
from aerodaas.training.augment import Augment, TileSampler
from aerodaas.training.labels.images import LabelledImage
from aerodaas.training.loss import decode_maps
from aerodaas.training.onnx_module import STRIDES

__all__ = ["ValTiles", "ClassMetrics", "evaluate", "decode_detections"]


@dataclass(frozen=True)
class ClassMetrics:
    """One class on the validation tiles: ground-truth count, recall and precision at the score threshold, AP50."""

    name: str
    n_gt: int
    recall: float
    precision: float
    ap50: float


@dataclass
class ValTiles:
    """Fixed validation tiles: ``images`` ``(N, tile, tile, 3)`` uint8 BGR and per tile ``(M, 5)`` targets."""

    images: np.ndarray
    targets: list[np.ndarray]

    @classmethod
    def cut(cls, items: list[LabelledImage], n: int, tile: int, seed: int) -> "ValTiles":
        """``n`` tiles from ``items`` (scale and crop only), the same for the same seed."""
        aug = Augment(tile=tile, p_oblique=0.0, p_grey=0.0, p_blur=0.0, p_jpeg=0.0)
        sampler = TileSampler(items, aug, cache_mb=512)
        rng = np.random.default_rng(seed)
        imgs, tg = [], []
        for _ in range(n):
            im, t = sampler.sample_plain(rng)
            imgs.append(im)
            tg.append(t)
        return cls(np.stack(imgs), tg)


def decode_detections(maps: list[torch.Tensor], names: list[str], score_threshold: float,
                      nms_iou: float = 0.45) -> list[list[Detection]]:
    """Per image of the batch, the detections of the raw head ``maps`` (x0 y0 x1 y1 input pixels)."""
    pred, _, _ = decode_maps([m.float() for m in maps], STRIDES)
    pred = pred.detach().numpy()
    out = []
    for p in pred:
        obj = 1 / (1 + np.exp(-p[:, 4:5]))
        cls = 1 / (1 + np.exp(-p[:, 5:]))
        sc = obj * cls
        c = sc.argmax(1)
        s = sc[np.arange(len(sc)), c]
        keep = s >= score_threshold
        p, c, s = p[keep], c[keep], s[keep]
        boxes = np.concatenate([p[:, :2] - p[:, 2:4] / 2, p[:, 2:4]], axis=1)  # x, y, w, h
        # class-aware NMS: offset each class's boxes so that classes never overlap
        off = boxes.copy()
        off[:, :2] += c[:, None] * 10000.0
        idx = cv2.dnn.NMSBoxes(off.tolist(), s.tolist(), score_threshold, nms_iou) if len(s) else []
        dets = []
        for i in np.asarray(idx).reshape(-1):
            x, y, w, h = boxes[i]
            dets.append(Detection(class_id=int(c[i]), class_name=names[int(c[i])], score=float(min(s[i], 1.0)),
                                  box=(float(x), float(y), float(x + w), float(y + h))))
        out.append(dets)
    return out


def evaluate(model: torch.nn.Module, val: ValTiles, names: list[str], score_threshold: float = 0.3,
             batch: int = 16) -> list[ClassMetrics]:
    """Score ``model`` on ``val`` per class (see the module docstring)."""
    pairs = []
    model.eval()
    with torch.no_grad():
        for i in range(0, len(val.images), batch):
            x = torch.from_numpy(val.images[i:i + batch]).permute(0, 3, 1, 2).float()
            x = x.contiguous(memory_format=torch.channels_last)
            dets = decode_detections(model(x), names, min(score_threshold, 0.01))
            for k, d in enumerate(dets):
                t = val.targets[i + k]
                gt = GroundTruth(f"tile{i + k}", t[:, 1:5].astype(float), [names[int(c)] for c in t[:, 0]])
                pairs.append((d, gt))
    out = []
    for ci, name in enumerate(names):
        full = score(pairs, name, 0.5)
        at = score([([x for x in d if x.score >= score_threshold], g) for d, g in pairs], name, 0.5)
        out.append(ClassMetrics(name, full.n_gt, at.recall, at.precision, full.ap))
    return out
