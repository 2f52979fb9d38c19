"""Detection scores broken down by object size and by what a data set records per frame (view angle, altitude).

Size: the COCO area ranges (``pycocotools`` ``COCOeval`` ``Params.areaRng``): small < 32², medium 32²..96², large
>= 96², the area being the box's width x height in pixels of the frame as scored (the stored image; with ``aerodaas
bench detect --frame-width`` the resized one). Scoring within one range follows ``COCOeval.evaluateImg``: ground-truth
boxes outside the range are *ignored*, not removed; detections are matched in descending score, to a counted box
first; a detection matched to an ignored box, or unmatched with its own area outside the range, is left out (neither
true nor false positive). Recall of a bucket is therefore the share of its boxes found, precision the share of the
detections of that size (or found on a box of that size) that are right.

Per frame: :class:`FrameMeta` from the file name. HIT-UAV (Suo et al., "HIT-UAV: A high-altitude infrared thermal
dataset for Unmanned Aerial Vehicle-based object detection", Scientific Data 10, 227, 2023) names its images
``T_H_A_S_N.jpg``: ``T`` day (0) or night (1), ``H`` flight altitude in metres (60..130), ``A`` camera angle in
degrees from the horizon (30..90, 90 = nadir), ``S`` unused, ``N`` frame number (e.g. ``0_100_30_0_03280.jpg``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from aerodaas.perception.boxes import iou_matrix
from aerodaas.perception.scoring import ClassScore, GroundTruth, summarise

__all__ = ["SIZE_BUCKETS", "FrameMeta", "FRAME_META_SOURCES", "hit_uav_meta", "frame_meta", "score_area"]

#: (name, lowest area, area bound) in square pixels, half-open [low, bound): COCO's small, medium, large
SIZE_BUCKETS: tuple[tuple[str, float, float], ...] = (("small", 0.0, 32.0 ** 2), ("medium", 32.0 ** 2, 96.0 ** 2),
                                                      ("large", 96.0 ** 2, float("inf")))

_HIT_UAV = re.compile(r"^([01])_(\d+)_(\d+)_(\d+)_(\d+)\.[A-Za-z]+$")

#: values of ``--frame-meta``: ``auto`` (HIT-UAV when every file name has its pattern), ``hit-uav``, ``none``
FRAME_META_SOURCES = ("auto", "hit-uav", "none")


@dataclass(frozen=True)
class FrameMeta:
    """What a data set records about one frame: ``altitude_m`` (metres above ground) and ``view_angle_deg`` (camera
    angle from the horizon, degrees; 90 looks straight down); None where not recorded."""

    altitude_m: float | None = None
    view_angle_deg: float | None = None


def hit_uav_meta(file_name: str) -> FrameMeta | None:
    """Altitude and camera angle from a HIT-UAV file name (module docstring), None if the name has not its form."""
    m = _HIT_UAV.match(file_name)
    if m is None:
        return None
    return FrameMeta(altitude_m=float(m.group(2)), view_angle_deg=float(m.group(3)))


def frame_meta(files: list[str], source: str = "auto") -> dict[str, FrameMeta]:
    """:class:`FrameMeta` per file name for ``source`` (:data:`FRAME_META_SOURCES`); ``auto`` reads HIT-UAV names
    when every one of ``files`` has that form, else records nothing ({}). Raises ValueError naming ``--frame-meta``
    for an unknown source, or for ``hit-uav`` and a file name without the pattern."""
    if source not in FRAME_META_SOURCES:
        raise ValueError(f"--frame-meta must be one of {', '.join(FRAME_META_SOURCES)}, got {source!r}")
    if source == "none" or not files:
        return {}
    metas = {f: hit_uav_meta(f) for f in files}
    bad = [f for f, m in metas.items() if m is None]
    if bad and source == "hit-uav":
        raise ValueError(f"--frame-meta hit-uav: file name {bad[0]!r} is not T_H_A_S_N.<ext> (HIT-UAV)")
    return {} if bad else {f: m for f, m in metas.items() if m is not None}


def _areas(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, float).reshape(-1, 4)
    return (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])


def _match_ignoring(db: np.ndarray, sc: np.ndarray, gb: np.ndarray, g_ignore: np.ndarray, d_out: np.ndarray,
                    iou_thr: float) -> tuple[np.ndarray, np.ndarray]:
    """(true-positive flags, counted flags) per detection of one image and class, ``COCOeval.evaluateImg``'s rule."""
    tp = np.zeros(len(db), bool)
    counted = ~d_out.copy()
    if len(db) == 0 or len(gb) == 0:
        return tp, counted
    ious = iou_matrix(db, gb)
    used = np.zeros(len(gb), bool)
    for i in np.argsort(-sc, kind="stable"):
        for pool in (~g_ignore, g_ignore):  # a counted box first, an ignored one only if no counted box matches
            cand = np.where(used | ~pool, -1.0, ious[i])
            j = int(cand.argmax())
            if cand[j] >= iou_thr:
                used[j] = True
                tp[i] = not g_ignore[j]
                counted[i] = not g_ignore[j]
                break
    return tp, counted


def score_area(per_image: list[tuple[list, GroundTruth]], cls: str, iou_thr: float, low: float,
               bound: float) -> ClassScore:
    """Score class ``cls`` over ``(detections, ground truth)`` pairs counting only boxes with ``low <= area <
    bound`` (square pixels), COCO's ignore rule (module docstring); the curve is left empty."""
    flags, scores, n_gt = [], [], 0
    for dets, gt in per_image:
        g = gt.boxes[[c == cls for c in gt.classes]] if len(gt.classes) else np.zeros((0, 4))
        ga = _areas(g)
        g_ignore = (ga < low) | (ga >= bound)
        n_gt += int((~g_ignore).sum())
        ds = [d for d in dets if d.class_name == cls]
        db = np.array([d.box for d in ds], float).reshape(-1, 4)
        sc = np.array([d.score for d in ds], float)
        da = _areas(db)
        tp, counted = _match_ignoring(db, sc, np.asarray(g, float).reshape(-1, 4), g_ignore,
                                      (da < low) | (da >= bound), iou_thr)
        flags.append(tp[counted])
        scores.append(sc[counted])
    tp = np.concatenate(flags) if flags else np.zeros(0, bool)
    sc = np.concatenate(scores) if scores else np.zeros(0)
    s = summarise(tp, sc, n_gt)
    return ClassScore(s.n_gt, s.n_det, s.recall, s.precision, s.ap)
