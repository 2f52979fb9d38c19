"""How much a frame is worth labelling: the shipped detector at its normal input against a stronger pass of the
same model, and the detections near the score threshold.

Both passes run at ``score_threshold - margin`` so the detections just below the threshold are seen. With ``b`` the
normal pass's detections at or above ``score_threshold`` and ``s`` the stronger pass's, matched one to one within a
class at IoU >= 0.5 (greedily, best IoU first):

* ``disagreement`` = unmatched boxes of ``b`` and of ``s`` (an object one pass sees and the other does not);
* ``uncertain`` = sum over the detections of both passes with ``|score - score_threshold| < margin`` of
  ``1 - |score - score_threshold| / margin`` (a detection at the threshold counts 1, one ``margin`` away 0);
* ``informativeness`` = ``disagreement + uncertain``: uncertainty sampling by disagreement of two views of one
  model (query by committee, Seung, Opper and Sompolinsky, COLT 1992) plus margin sampling around the operating
  threshold (Scheffer, Decomain and Wrobel, IDA 2001).

Both run the model as the apps do, never enlarging a frame to fill its input (``upscale=False``: a 640x480
camera's frames go in at 480x640, a 1080p camera's are shrunk to the model's input). The stronger pass
(:func:`build_detectors` ``strong``): ``"enlarged"`` (:class:`Enlarged`) runs the model on the frame at 1.5 times the
scale of the normal pass (far, small objects get more pixels); ``"tiles"`` cuts the frame into 640 px slices
overlapping by 0.2 at their native resolution plus the whole frame (:class:`aerodaas.perception.tiling.TiledDetector`). The pre-labels of a
frame are both passes' boxes at or above the threshold merged by class-aware NMS at IoU 0.5
(:func:`aerodaas.perception.tiling.merge_detections`), the higher score kept.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from aerodaas.labelling.sources import LabelInputError
from aerodaas.model.types import Detection
from aerodaas.perception.boxes import iou_matrix
from aerodaas.perception.detect import AerialDetector, DETECTORS, make_detector
from aerodaas.perception.tiling import Tiling, TiledDetector, merge_detections

__all__ = ["Detectors", "Enlarged", "build_detectors", "informativeness", "prelabels", "STRONG_PASSES", "MATCH_IOU"]

#: the stronger passes :func:`build_detectors` knows
STRONG_PASSES = ("enlarged", "tiles")
#: IoU at which two boxes of one class are the same object (matching and merging)
MATCH_IOU = 0.5
#: the stronger pass's input over the normal one (``"enlarged"``)
ENLARGE = 1.5
#: slice side (pixels) of the ``"tiles"`` pass
TILE_PX = 640


@dataclass
class Detectors:
    """The two passes and their settings: ``base`` (the model at its normal input), ``strong``, the
    ``score_threshold`` and ``margin`` (both in [0, 1]), ``class_names`` (the model's), ``classes`` (the ones
    kept, in the model's order) and ``model_version`` (``<name>@<first 12 hex digits of the file's sha256>``)."""

    base: Any
    strong: Any
    score_threshold: float
    margin: float
    class_names: list[str]
    classes: list[str]
    model_version: str
    strong_kind: str

    def detect(self, image: np.ndarray) -> tuple[list[Detection], list[Detection]]:
        """Both passes' detections on an ``(H, W, 3) uint8 BGR`` image, boxes in its pixels."""
        return self.base.detect(image), self.strong.detect(image)


class Enlarged:
    """The ``"enlarged"`` stronger pass: ``detector`` (built with ``upscale=False``) on the frame resized to
    :data:`ENLARGE` times the scale ``base`` sees it at (``base``'s input over the frame, at most 1: a frame that
    fits the input is seen at its own size), boxes mapped back to the frame's pixels. ``detect`` takes an
    ``(H, W, 3) uint8 BGR`` frame like the detectors it wraps."""

    def __init__(self, base: Any, detector: Any) -> None:
        self.base, self.detector = base, detector

    def detect(self, image: np.ndarray) -> list[Detection]:
        """``detector``'s detections on the enlarged frame, boxes in ``image``'s pixels."""
        h, w = image.shape[:2]
        ih, iw = self.base.input_hw
        k = ENLARGE * min(1.0, ih / h, iw / w)
        nw, nh = max(1, round(w * k)), max(1, round(h * k))
        dets = self.detector.detect(cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR))
        sx, sy = w / nw, h / nh
        return [d.model_copy(update={"box": (d.box[0] * sx, d.box[1] * sy, d.box[2] * sx, d.box[3] * sy)})
                for d in dets]


def _sha12(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:12]


def _round32(v: float) -> int:
    return max(32, int(round(v / 32.0)) * 32)


def build_detectors(model: str = "aerial_nano", classes: Sequence[str] | None = None, score_threshold: float = 0.3,
                    margin: float = 0.15, strong: str = "enlarged", threads: int = 1) -> Detectors:
    """The normal and the stronger pass of ``model`` (a name of :data:`aerodaas.perception.detect.DETECTORS` or a
    path to a YOLOX ONNX file with class names in its metadata), keeping ``classes`` (default: all of the model's).

    Raises :class:`LabelInputError` naming the value for an unknown model or class, a threshold or margin outside
    [0, 1], or an unknown ``strong`` (:data:`STRONG_PASSES`)."""
    if not 0.0 < float(score_threshold) < 1.0:
        raise LabelInputError(f"--score {score_threshold}: must be within (0, 1)")
    if not 0.0 < float(margin) <= float(score_threshold):
        raise LabelInputError(f"--margin {margin}: must be within (0, score threshold {score_threshold}]")
    if strong not in STRONG_PASSES:
        raise LabelInputError(f"--strong {strong!r}: must be one of {list(STRONG_PASSES)}")
    low = float(score_threshold) - float(margin)
    is_file = model.endswith(".onnx") or os.sep in model
    if is_file and not Path(model).is_file():
        raise LabelInputError(f"--model {model!r}: no such file")
    if not is_file and model not in DETECTORS:
        raise LabelInputError(f"--model {model!r}: not a known model ({', '.join(sorted(DETECTORS))}) "
                              "nor an .onnx file")

    def make(**kw):  # never enlarging a frame, as the apps run the model (a 640x480 camera's frames at 480x640)
        if is_file:
            return AerialDetector(model_path=model, intra_op_threads=threads, upscale=False, **kw)
        return make_detector(model, intra_op_threads=threads, upscale=False, **kw)

    probe = make(score_threshold=low)
    names = list(probe.class_names)
    if classes:
        unknown = [c for c in classes if c not in names]
        if unknown:
            raise LabelInputError(f"--classes {','.join(classes)}: unknown class(es) {unknown}; the model "
                                  f"{model!r} has {names}")
    keep = [n for n in names if not classes or n in classes]
    base = probe if keep == names else make(score_threshold=low, classes=keep)
    if strong == "enlarged":
        h, w = base.input_hw
        stronger = Enlarged(base, make(score_threshold=low, classes=keep,
                                       input_size=(_round32(h * ENLARGE), _round32(w * ENLARGE))))
    else:
        tiles = make(score_threshold=low, classes=keep, input_size=(TILE_PX, TILE_PX))
        stronger = TiledDetector(tiles, Tiling(tile=TILE_PX, overlap=0.2, full_frame=True, merge="greedynmm",
                                               agnostic=False))
    name = Path(model).stem if is_file else model
    return Detectors(base, stronger, float(score_threshold), float(margin), names, keep,
                     f"{name}@{_sha12(base.model_path)}", strong)


def _above(dets: Sequence[Detection], thr: float) -> list[Detection]:
    return [d for d in dets if d.score >= thr]


def _matched(a: list[Detection], b: list[Detection]) -> int:
    """Pairs of one class at IoU >= :data:`MATCH_IOU`, matched one to one, best IoU first."""
    if not a or not b:
        return 0
    iou = iou_matrix(np.array([d.box for d in a]), np.array([d.box for d in b]))
    same = np.array([[x.class_name == y.class_name for y in b] for x in a])
    iou = np.where(same, iou, 0.0)
    n = 0
    while iou.size and iou.max() >= MATCH_IOU:
        i, j = np.unravel_index(int(np.argmax(iou)), iou.shape)
        iou[i, :], iou[:, j] = 0.0, 0.0
        n += 1
    return n


def informativeness(base: Sequence[Detection], strong: Sequence[Detection], score_threshold: float,
                    margin: float) -> dict[str, float]:
    """``{"informativeness", "disagreement", "uncertain", "n_base", "n_strong"}`` of one frame from its two
    passes' detections (module docstring for the formula; ``n_*``: detections at or above the threshold)."""
    b, s = _above(base, score_threshold), _above(strong, score_threshold)
    m = _matched(b, s)
    disagreement = float(len(b) + len(s) - 2 * m)
    uncertain = float(sum(1.0 - abs(d.score - score_threshold) / margin for d in [*base, *strong]
                          if abs(d.score - score_threshold) < margin))
    return {"informativeness": disagreement + uncertain, "disagreement": disagreement, "uncertain": uncertain,
            "n_base": float(len(b)), "n_strong": float(len(s))}


def prelabels(base: Sequence[Detection], strong: Sequence[Detection], score_threshold: float) -> list[Detection]:
    """The pre-labels of a frame: both passes' detections at or above ``score_threshold`` merged by class-aware
    NMS at IoU :data:`MATCH_IOU` (the higher score kept), best score first."""
    return merge_detections([*_above(base, score_threshold), *_above(strong, score_threshold)], "nms", MATCH_IOU,
                            agnostic=False)
