"""Training tiles cut from labelled frames, with the augmentations a drone's camera calls for.

Each sample is one ``tile x tile`` crop (BGR uint8) with its boxes, made as:

1. **scale (altitude)**: the frame is resized so that its median object measures a size drawn log-uniformly from
   ``object_px`` (default 8-96 px; a frame without objects: a scale drawn from 0.25-1.0), which covers a camera from
   low hover to survey altitude whatever the source's resolution;
2. **crop**: a window of the tile size, centred near a random object with probability ``p_object`` (else anywhere),
   padded with 114 (the letterbox grey of YOLOX's pre-processing) where the frame is smaller;
3. **view**: a random perspective warp (``p_oblique``: the far edge shrunk by up to ``max_tilt``, as a camera pitched
   from nadir towards the horizon sees the ground), a rotation by a multiple of 90 degrees and flips (a nadir view
   has no "up");
4. **sensor**: grey scale (``p_grey``; a thermal camera's frames are grey already), Gaussian or motion blur
   (``p_blur``), JPEG re-encoding at quality 30-90 (``p_jpeg``), brightness/contrast/saturation jitter.

Boxes are transformed with the image (a warped box becomes the bounding box of its warped corners) and dropped when
less than ``min_visible`` of their area remains or they end up smaller than ``min_box_px``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aerodaas.training.labels.images import LabelledImage

__all__ = ["Augment", "TileSampler", "read_bgr"]


@dataclass(frozen=True)
class Augment:
    """Augmentation settings (see the module docstring); probabilities in [0, 1], sizes in pixels."""

    tile: int = 416
    object_px: tuple[float, float] = (8.0, 96.0)
    p_object: float = 0.85
    p_oblique: float = 0.3
    max_tilt: float = 0.45
    p_grey: float = 0.15
    p_blur: float = 0.2
    p_jpeg: float = 0.3
    min_visible: float = 0.45
    min_box_px: float = 3.0


def read_bgr(path) -> np.ndarray:
    """``(H, W, 3)`` uint8 BGR of an image file (grey images replicated to three channels). Raises OSError when
    the file cannot be decoded."""
    im = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if im is None:
        raise OSError(f"{path}: image cannot be read")
    return im


def _visible(boxes: np.ndarray, before: np.ndarray, size: int, aug: Augment) -> np.ndarray:
    clipped = boxes.copy()
    clipped[:, 0::2] = clipped[:, 0::2].clip(0, size)
    clipped[:, 1::2] = clipped[:, 1::2].clip(0, size)
    area = lambda b: (b[:, 2] - b[:, 0]).clip(0) * (b[:, 3] - b[:, 1]).clip(0)  # noqa: E731
    keep = (area(clipped) >= aug.min_visible * np.maximum(before, 1e-6)) & \
           ((clipped[:, 2] - clipped[:, 0]) >= aug.min_box_px) & ((clipped[:, 3] - clipped[:, 1]) >= aug.min_box_px)
    return keep, clipped


class TileSampler:
    """Draws augmented training tiles from a labelled set, reproducibly for a seed.

    ``weights`` (one per item) multiply each frame's chance of being drawn (e.g. to balance sources).
    ``sample(rng)`` returns ``(tile (tile, tile, 3) uint8 BGR, targets (N, 5) float32 (class, x0, y0, x1, y1) px)``.
    Frames are decoded once and kept (``cache_mb`` bounds the cache; least recently used frames are dropped).
    """

    def __init__(self, items: list[LabelledImage], aug: Augment, cache_mb: int = 2048,
                 weights: np.ndarray | None = None, n_classes: int = 1) -> None:
        if not items:
            raise ValueError("TileSampler needs at least one labelled image")
        self.items = items
        self.aug = aug
        self.n_classes = n_classes
        self._last = 0
        self._cache: dict[int, np.ndarray] = {}
        self._cache_bytes = 0
        self._limit = cache_mb * 2 ** 20
        # frames with objects are drawn three times as often as empty ones
        w = np.array([3.0 if len(it.boxes) else 1.0 for it in items])
        if weights is not None:
            w = w * np.asarray(weights, float)
        self._p = w / w.sum()

    def _frame(self, i: int) -> np.ndarray:
        im = self._cache.pop(i, None)
        if im is None:
            im = read_bgr(self.items[i].path)
            self._cache_bytes += im.nbytes
            while self._cache_bytes > self._limit and self._cache:
                old = self._cache.pop(next(iter(self._cache)))
                self._cache_bytes -= old.nbytes
        self._cache[i] = im
        return im

    def sample(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One augmented tile and its targets (class docstring)."""
        return self._draw(rng, augment=True)

    def sample_labelled(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`sample` plus the ``(nc,)`` bool mask of the classes the tile's source labels exhaustively."""
        tile, targets = self._draw(rng, augment=True)
        lab = self.items[self._last].labelled
        return tile, targets, (np.ones(self.n_classes, bool) if lab is None else lab)

    def sample_plain(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One tile with the scale and crop steps only (validation)."""
        return self._draw(rng, augment=False)

    def _draw(self, rng: np.random.Generator, augment: bool) -> tuple[np.ndarray, np.ndarray]:
        i = int(rng.choice(len(self.items), p=self._p))
        self._last = i
        it, img = self.items[i], self._frame(i)
        a = self.aug
        boxes, cls = it.boxes.astype(np.float32), it.classes.astype(np.float32)
        if len(boxes):
            med = float(np.median(np.sqrt((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))))
            want = float(np.exp(rng.uniform(np.log(a.object_px[0]), np.log(a.object_px[1]))))
            s = want / max(med, 1.0)
        else:
            s = float(rng.uniform(0.25, 1.0))
        s = float(np.clip(s, 0.05, 4.0))
        # crop window in the source frame's pixels (size tile / s), placed near an object or anywhere
        win = a.tile / s
        h, w = img.shape[:2]
        if len(boxes) and rng.random() < a.p_object:
            b = boxes[rng.integers(len(boxes))]
            cx = (b[0] + b[2]) / 2 + rng.uniform(-0.4, 0.4) * win
            cy = (b[1] + b[3]) / 2 + rng.uniform(-0.4, 0.4) * win
        else:
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        x0 = float(np.clip(cx - win / 2, min(0.0, w - win), max(0.0, w - win)))
        y0 = float(np.clip(cy - win / 2, min(0.0, h - win), max(0.0, h - win)))
        m = np.array([[s, 0, -x0 * s], [0, s, -y0 * s], [0, 0, 1]], np.float64)
        if augment:
            m = self._view(rng) @ m
        tile = cv2.warpPerspective(img, m, (a.tile, a.tile), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=(114, 114, 114))
        out = self._boxes(boxes, cls, m)
        return (self._sensor(tile, rng) if augment else tile), out

    def _view(self, rng: np.random.Generator) -> np.ndarray:
        """A homography of the tile onto itself: oblique tilt, rotation by k * 90 degrees, flip."""
        a, t = self.aug, float(self.aug.tile)
        src = np.float32([[0, 0], [t, 0], [t, t], [0, t]])
        dst = src.copy()
        if rng.random() < a.p_oblique:
            k = rng.uniform(0.1, a.max_tilt) * t / 2  # the far (top) edge shrinks
            dst[0, 0] += k
            dst[1, 0] -= k
            dst[0, 1] = dst[1, 1] = rng.uniform(0, 0.25) * t
        h = cv2.getPerspectiveTransform(src, dst).astype(np.float64)
        rot = int(rng.integers(4))
        c = t / 2
        for _ in range(rot):
            h = np.array([[0, -1, 2 * c], [1, 0, 0], [0, 0, 1]], np.float64) @ h  # 90 degrees about the centre
        if rng.random() < 0.5:
            h = np.array([[-1, 0, t], [0, 1, 0], [0, 0, 1]], np.float64) @ h
        return h

    def _boxes(self, boxes: np.ndarray, cls: np.ndarray, m: np.ndarray) -> np.ndarray:
        if not len(boxes):
            return np.zeros((0, 5), np.float32)
        corners = np.stack([boxes[:, [0, 1]], boxes[:, [2, 1]], boxes[:, [2, 3]], boxes[:, [0, 3]]], axis=1)
        pts = cv2.perspectiveTransform(corners.reshape(-1, 1, 2).astype(np.float64), m).reshape(-1, 4, 2)
        nb = np.concatenate([pts.min(1), pts.max(1)], axis=1)
        before = (nb[:, 2] - nb[:, 0]) * (nb[:, 3] - nb[:, 1])
        keep, clipped = _visible(nb, before, self.aug.tile, self.aug)
        return np.concatenate([cls[keep, None], clipped[keep]], axis=1).astype(np.float32)

    def _sensor(self, tile: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        a = self.aug
        if rng.random() < a.p_grey:
            tile = cv2.cvtColor(cv2.cvtColor(tile, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
        else:
            hsv = cv2.cvtColor(tile, cv2.COLOR_BGR2HSV).astype(np.float32)
            hsv[..., 1] *= rng.uniform(0.6, 1.4)
            hsv[..., 2] = hsv[..., 2] * rng.uniform(0.7, 1.3) + rng.uniform(-20, 20)
            tile = cv2.cvtColor(hsv.clip(0, 255).astype(np.uint8), cv2.COLOR_HSV2BGR)
        if rng.random() < a.p_blur:
            if rng.random() < 0.5:
                tile = cv2.GaussianBlur(tile, (0, 0), rng.uniform(0.5, 1.5))
            else:
                k = int(rng.integers(3, 8))
                kern = np.zeros((k, k), np.float32)
                kern[k // 2] = 1.0 / k
                if rng.random() < 0.5:
                    kern = kern.T
                tile = cv2.filter2D(tile, -1, kern)
        if rng.random() < a.p_jpeg:
            ok, buf = cv2.imencode(".jpg", tile, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(30, 91))])
            if ok:
                tile = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return tile
