"""Tiled (sliced) inference for small objects in large frames, after SAHI (Akyon, Altinuc, Temizel, "Slicing Aided
Hyper Inference and Fine-tuning for Small Object Detection", ICIP 2022; ``obss/sahi``: ``sahi/slicing.py``
``get_slice_bboxes`` and ``sahi/postprocess/combine.py``).

The frame is cut into ``tile`` x ``tile`` pixel slices overlapping by ``overlap`` (a fraction of the tile), the last
slice of each row/column shifted back to end at the image border (as ``get_slice_bboxes`` does); the full frame is
optionally added (SAHI's ``perform_standard_pred``). Every slice goes through the detector (in one onnxruntime call
per ``max_batch`` slices when the model's batch is dynamic, ``detect_batch``), boxes are shifted to frame pixels
and merged across slices:

* ``"nms"``: class-agnostic (or per the detector's own grouping when ``agnostic=False``) greedy NMS at
  ``match_threshold`` IoU -- SAHI's ``NMSPostprocess``;
* ``"greedynmm"``: greedy non-maximum *merging* -- boxes are visited best score first; every remaining box whose
  overlap with the kept one exceeds ``match_threshold`` is merged into it (the union box, the higher score) --
  SAHI's ``GreedyNMMPostprocess`` with its default metric ``IOS`` (intersection over the smaller box area), which
  joins the halves of an object cut at a slice border.

``sahi`` itself pulls in ``shapely``, ``pybboxes``, ``fire``, ``terminaltables`` and its own model wrappers; the
slicing and merging it defines are ~60 lines, written here on our detectors.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from aerodaas.model.types import Detection

__all__ = ["Tiling", "slice_boxes", "merge_detections", "TiledDetector"]


@dataclass
class Tiling:
    """Tiled inference options: ``tile`` (pixels, square slice side, >= 32), ``overlap`` (fraction of the tile in
    [0, 0.9)), ``full_frame`` (also run the whole frame, letterboxed), ``merge`` (``"nms"`` or ``"greedynmm"``),
    ``match_threshold`` (IoU for nms, IOS for greedynmm, in (0, 1]), ``agnostic`` (merge across classes).
    Checked where it is written (``Tiling(tile=16)`` raises ValueError naming the field and the value), and again by
    :meth:`check` in the pre-flight, before Ray starts, for a field changed afterwards."""

    tile: int = 640
    overlap: float = 0.2
    full_frame: bool = True
    merge: str = "greedynmm"
    match_threshold: float = 0.5
    agnostic: bool = True

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """Raises ValueError naming the field and the value."""
        if not isinstance(self.tile, int) or isinstance(self.tile, bool) or not 32 <= self.tile <= 8192:
            raise ValueError(f"tiling.tile must be an integer number of pixels within [32, 8192], got {self.tile!r}")
        if not isinstance(self.overlap, (int, float)) or not 0.0 <= float(self.overlap) < 0.9:
            raise ValueError(f"tiling.overlap must be a fraction within [0, 0.9), got {self.overlap!r}")
        if self.merge not in ("nms", "greedynmm"):
            raise ValueError(f"tiling.merge must be 'nms' or 'greedynmm', got {self.merge!r}")
        if not isinstance(self.match_threshold, (int, float)) or not 0.0 < float(self.match_threshold) <= 1.0:
            raise ValueError(f"tiling.match_threshold must be within (0, 1], got {self.match_threshold!r}")
        for f in ("full_frame", "agnostic"):
            if not isinstance(getattr(self, f), bool):
                raise ValueError(f"tiling.{f} must be True or False, got {getattr(self, f)!r}")


def slice_boxes(h: int, w: int, tile: int, overlap: float) -> list[tuple[int, int, int, int]]:
    """Slices ``(x0, y0, x1, y1)`` (pixels) covering an ``h`` x ``w`` image, as SAHI ``get_slice_bboxes``: step
    ``tile - int(overlap * tile)``, a slice running past the border is shifted back to end on it, and a side
    shorter than ``tile`` is one slice of the whole side."""
    step = max(1, tile - int(overlap * tile))
    out = []
    ys = list(range(0, max(h - tile, 0) + 1, step)) or [0]
    xs = list(range(0, max(w - tile, 0) + 1, step)) or [0]
    if ys[-1] + tile < h:
        ys.append(h - tile)
    if xs[-1] + tile < w:
        xs.append(w - tile)
    for y in ys:
        for x in xs:
            out.append((x, y, min(x + tile, w), min(y + tile, h)))
    return out


def _overlap(box: np.ndarray, rest: np.ndarray, metric: str) -> np.ndarray:
    w = np.maximum(0.0, np.minimum(box[2], rest[:, 2]) - np.maximum(box[0], rest[:, 0]))
    h = np.maximum(0.0, np.minimum(box[3], rest[:, 3]) - np.maximum(box[1], rest[:, 1]))
    inter = w * h
    a = (box[2] - box[0]) * (box[3] - box[1])
    b = (rest[:, 2] - rest[:, 0]) * (rest[:, 3] - rest[:, 1])
    if metric == "ios":
        return inter / np.maximum(np.minimum(a, b), 1e-9)
    return inter / np.maximum(a + b - inter, 1e-9)


def merge_detections(dets: list[Detection], merge: str = "greedynmm", match_threshold: float = 0.5,
                     agnostic: bool = True) -> list[Detection]:
    """Merge detections from overlapping slices (frame pixels), best score first (see the module docstring for
    ``"nms"`` / ``"greedynmm"``); ``agnostic=False`` merges only within a class. Returns a new list sorted by
    descending score."""
    if not dets:
        return []
    boxes = np.array([d.box for d in dets], dtype=np.float64)
    scores = np.array([d.score for d in dets])
    cls = np.array([0 if agnostic else d.class_id for d in dets])
    order = list(np.argsort(-scores, kind="stable"))
    metric = "ios" if merge == "greedynmm" else "iou"
    out = []
    alive = np.ones(len(dets), dtype=bool)
    for i in order:
        if not alive[i]:
            continue
        alive[i] = False
        rest = np.flatnonzero(alive & (cls == cls[i]))
        box = boxes[i].copy()
        if rest.size:
            hit = rest[_overlap(boxes[i], boxes[rest], metric) > match_threshold]
            alive[hit] = False
            if merge == "greedynmm" and hit.size:
                box[:2] = np.minimum(box[:2], boxes[hit, :2].min(axis=0))
                box[2:] = np.maximum(box[2:], boxes[hit, 2:].max(axis=0))
        d = dets[i]
        out.append(Detection(class_id=d.class_id, class_name=d.class_name, score=d.score,
                             box=(float(box[0]), float(box[1]), float(box[2]), float(box[3]))))
    return out


class TiledDetector:
    """Wraps a detector (:class:`aerodaas.perception.detect.YoloxDetector` and kin) to detect by slices (:class:`Tiling`);
    same interface: ``detect(image) -> list[Detection]`` on ``(H, W, 3)`` uint8 BGR frames, ``detect_batch``,
    ``last_timing`` (ms, summed over the slices), ``batch_dynamic``, ``last_batch``, ``last_batched``."""

    def __init__(self, detector, tiling: Tiling, max_batch: int = 16) -> None:
        tiling.check()
        self.detector, self.tiling, self.max_batch = detector, tiling, int(max_batch)
        self.batch_dynamic = False  # frames are looped; the slices of one frame share onnxruntime calls
        self.last_timing = dict(detector.last_timing)
        self.last_batch, self.last_batched, self.last_slices = 1, 0, 0

    def __getattr__(self, item):
        return getattr(self.__dict__["detector"], item)

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Detections in frame pixels after slicing and merging; raises ValueError as the wrapped detector."""
        t = self.tiling
        h, w = image_bgr.shape[:2]
        slices = slice_boxes(h, w, t.tile, t.overlap)
        crops = [np.ascontiguousarray(image_bgr[y0:y1, x0:x1]) for x0, y0, x1, y1 in slices]
        offsets = list(slices)
        if t.full_frame and (len(slices) > 1):
            crops.append(image_bgr)
            offsets.append((0, 0, w, h))
        t0 = time.perf_counter()
        per = self.detector.detect_batch(crops, max_batch=self.max_batch)
        timing = dict(self.detector.last_timing)
        self.last_batch = self.detector.last_batch
        self.last_slices = len(crops)
        t1 = time.perf_counter()
        allds = []
        for (x0, y0, _, _), ds in zip(offsets, per):
            for d in ds:
                b = d.box
                allds.append(Detection(class_id=d.class_id, class_name=d.class_name, score=d.score,
                                       box=(b[0] + x0, b[1] + y0, b[2] + x0, b[3] + y0)))
        out = merge_detections(allds, t.merge, t.match_threshold, t.agnostic)
        timing["postprocess_ms"] = timing.get("postprocess_ms", 0.0) + (time.perf_counter() - t1) * 1e3
        timing["total_ms"] = (time.perf_counter() - t0) * 1e3
        self.last_timing = timing
        return out

    __call__ = detect

    def detect_batch(self, images: list[np.ndarray], max_batch: int = 8) -> list[list[Detection]]:
        """:meth:`detect` for each image, in order; ``last_timing`` summed over them."""
        out, total = [], {"preprocess_ms": 0.0, "inference_ms": 0.0, "postprocess_ms": 0.0}
        for im in images:
            out.append(self.detect(im))
            for k in total:
                total[k] += self.last_timing.get(k, 0.0)
        self.last_timing, self.last_batched = total, 0
        return out
