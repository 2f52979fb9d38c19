"""Scoring detections against annotated ground truth: recall and precision at an IoU threshold, AP50 and the
precision-recall curve, as the PASCAL VOC / COCO evaluations define them.

Matching (per image, per class): detections are taken in descending score; each is a true positive when its IoU
with a not-yet-matched ground-truth box of its class reaches the threshold (the best such box is taken), else a
false positive (Everingham et al., "The PASCAL Visual Object Classes (VOC) Challenge", IJCV 2010, section 4.2).
AP is the area under the precision-recall curve with precision made monotone (the all-point interpolation of VOC
2010+, the ``voc_ap`` of ``py-faster-rcnn``; COCO's 101-point AP differs by < 1 point).

Annotations: COCO JSON (``images``, ``annotations`` with ``bbox`` ``[x, y, w, h]`` pixels, ``categories``) or a
YOLO txt folder (one ``<image stem>.txt`` per image with ``class cx cy w h`` normalised to [0, 1], and a
``classes.txt`` / ``names`` list, or ``--names``), or a VisDrone-DET ``annotations`` folder (:func:`load_visdrone`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aerodaas.perception.boxes import iou_matrix

__all__ = ["GroundTruth", "load_annotations", "load_visdrone", "VISDRONE_CLASSES", "match", "ClassScore", "score", "summarise"]

IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")


@dataclass
class GroundTruth:
    """Ground truth of one image: ``file`` (name relative to the image folder), ``boxes`` ``(N, 4)`` x0y0x1y1
    pixels and ``classes`` (N names)."""

    file: str
    boxes: np.ndarray
    classes: list[str]


def _image_size(path: Path) -> tuple[int, int]:
    import cv2  # lazy: heavy cv2

    im = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if im is None:
        raise ValueError(f"image {path} cannot be read")
    return im.shape[0], im.shape[1]


#: VisDrone-DET ``object_category`` 1..11 (0 is an ignored region), from the VisDrone2018-DET toolkit's README
VISDRONE_CLASSES = ("pedestrian", "people", "bicycle", "car", "van", "truck", "tricycle", "awning-tricycle", "bus",
                    "motor", "others")


def load_visdrone(path: str | Path, images_dir: str | Path) -> list[GroundTruth]:
    """A VisDrone-DET ``annotations`` folder: one ``<image stem>.txt`` per image, each line ``bbox_left, bbox_top,
    bbox_width, bbox_height, score, object_category, truncation, occlusion`` (pixels; the VisDrone2018-DET toolkit's
    format). Boxes with ``score`` 0 (not evaluated) and category 0 (ignored regions) are left out, so a detection in
    an ignored region counts as a false positive here (the toolkit drops it instead: precision is a lower bound);
    categories 1..11 are :data:`VISDRONE_CLASSES`. Raises ValueError naming the file, line and value."""
    path, images_dir = Path(path), Path(images_dir)
    out: list[GroundTruth] = []
    for img in sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_EXTS):
        lab = path / (img.stem + ".txt")
        if not lab.is_file():
            continue
        boxes, cls = [], []
        for n, ln in enumerate(lab.read_text().splitlines()):
            if not ln.strip():
                continue
            try:
                x, y, w, h, sc, cat = (int(float(v)) for v in ln.replace(" ", "").split(",")[:6])
                if w <= 0 or h <= 0 or not 0 <= cat <= len(VISDRONE_CLASSES):
                    raise ValueError
            except ValueError:
                raise ValueError(f"{lab}:{n + 1}: expected 'left,top,width,height,score,category,...' with a "
                                 f"positive size and a category in 0..{len(VISDRONE_CLASSES)}, got {ln!r}") from None
            if sc == 0 or cat == 0:
                continue
            boxes.append((x, y, x + w, y + h))
            cls.append(VISDRONE_CLASSES[cat - 1])
        out.append(GroundTruth(img.name, np.array(boxes, float).reshape(-1, 4), cls))
    if not out:
        raise ValueError(f"annotations={str(path)!r}: none of its images is in {images_dir}")
    return out


def load_annotations(path: str | Path, images_dir: str | Path, names: list[str] | None = None,
                     format: str = "auto") -> list[GroundTruth]:
    """Read ``path`` (COCO ``.json`` file, a folder of YOLO ``.txt`` files, or with ``format="visdrone"`` a
    VisDrone-DET folder, :func:`load_visdrone`) into one :class:`GroundTruth` per annotated image that exists in
    ``images_dir``. Raises ValueError naming the file and the field for a malformed file, a box with non-positive
    size, an unknown category id, or no image found."""
    if format == "visdrone":
        return load_visdrone(path, images_dir)
    if format not in ("auto", "coco", "yolo"):
        raise ValueError(f"annotation format must be auto, coco, yolo or visdrone, got {format!r}")
    path, images_dir = Path(path), Path(images_dir)
    out: list[GroundTruth] = []
    if path.is_file() and path.suffix.lower() == ".json":
        try:
            doc = json.loads(path.read_text())
            cats = {int(c["id"]): str(c["name"]) for c in doc["categories"]}
            imgs = {int(i["id"]): str(i["file_name"]) for i in doc["images"]}
            per: dict[int, list] = {i: [] for i in imgs}
            for k, a in enumerate(doc["annotations"]):
                x, y, w, h = (float(v) for v in a["bbox"])
                if w <= 0 or h <= 0:
                    raise ValueError(f"annotations[{k}].bbox={a['bbox']} has a non-positive size")
                if int(a["category_id"]) not in cats:
                    raise ValueError(f"annotations[{k}].category_id={a['category_id']} is not in categories")
                per[int(a["image_id"])].append(((x, y, x + w, y + h), cats[int(a["category_id"])]))
        except (KeyError, TypeError, json.JSONDecodeError) as e:
            raise ValueError(f"{path}: not a COCO detection file ({type(e).__name__}: {e})") from None
        for iid, fname in imgs.items():
            if (images_dir / fname).is_file():
                b = per[iid]
                out.append(GroundTruth(fname, np.array([x[0] for x in b], float).reshape(-1, 4), [x[1] for x in b]))
    elif path.is_dir():
        if names is None:
            for cand in ("classes.txt", "names.txt"):
                if (path / cand).is_file():
                    names = [ln.strip() for ln in (path / cand).read_text().splitlines() if ln.strip()]
        if names is None:
            raise ValueError(f"{path}: YOLO labels need class names (a classes.txt in the folder, or --names)")
        for img in sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_EXTS):
            lab = path / (img.stem + ".txt")
            if not lab.is_file():
                continue
            h, w = _image_size(img)
            boxes, cls = [], []
            for n, ln in enumerate(lab.read_text().splitlines()):
                if not ln.strip():
                    continue
                try:
                    c, cx, cy, bw, bh = ln.split()[:5]
                    c, cx, cy, bw, bh = int(c), float(cx), float(cy), float(bw), float(bh)
                    cname = names[c]
                except (ValueError, IndexError):
                    raise ValueError(f"{lab}:{n + 1}: expected 'class cx cy w h' with a known class, got {ln!r}") \
                        from None
                boxes.append(((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h))
                cls.append(cname)
            out.append(GroundTruth(img.name, np.array(boxes, float).reshape(-1, 4), cls))
    else:
        raise ValueError(f"annotations={str(path)!r}: expected a COCO .json file or a folder of YOLO .txt files")
    if not out:
        raise ValueError(f"annotations={str(path)!r}: none of its images is in {images_dir}")
    return out


def match(det_boxes: np.ndarray, det_scores: np.ndarray, gt_boxes: np.ndarray, iou_thr: float) -> np.ndarray:
    """True-positive flag per detection (one image, one class), greedy in descending score (VOC rule above)."""
    tp = np.zeros(len(det_boxes), dtype=bool)
    if len(det_boxes) == 0 or len(gt_boxes) == 0:
        return tp
    ious = iou_matrix(np.asarray(det_boxes, float), np.asarray(gt_boxes, float))
    used = np.zeros(len(gt_boxes), dtype=bool)
    for i in np.argsort(-np.asarray(det_scores), kind="stable"):
        cand = np.where(used, -1.0, ious[i])
        j = int(cand.argmax())
        if cand[j] >= iou_thr:
            tp[i], used[j] = True, True
    return tp


@dataclass
class ClassScore:
    """Scores of one class: ``n_gt`` ground-truth boxes, ``n_det`` detections, ``recall`` and ``precision`` at the
    operating threshold (all detections given), ``ap`` (area under the monotone PR curve), and the curve
    (``curve_recall``, ``curve_precision``, by descending score)."""

    n_gt: int
    n_det: int
    recall: float
    precision: float
    ap: float
    curve_recall: list[float] = field(default_factory=list)
    curve_precision: list[float] = field(default_factory=list)


def score(per_image: list[tuple[list, GroundTruth]], cls: str, iou_thr: float) -> ClassScore:
    """Score class ``cls`` over ``per_image`` pairs ``(detections, ground truth)`` at IoU ``iou_thr``."""
    flags, scores, n_gt = [], [], 0
    for dets, gt in per_image:
        g = gt.boxes[[c == cls for c in gt.classes]] if len(gt.classes) else np.zeros((0, 4))
        ds = [d for d in dets if d.class_name == cls]
        n_gt += len(g)
        db = np.array([d.box for d in ds], float).reshape(-1, 4)
        sc = np.array([d.score for d in ds], float)
        flags.append(match(db, sc, g, iou_thr))
        scores.append(sc)
    tp = np.concatenate(flags) if flags else np.zeros(0, bool)
    sc = np.concatenate(scores) if scores else np.zeros(0)
    return summarise(tp, sc, n_gt)


def summarise(tp: np.ndarray, sc: np.ndarray, n_gt: int) -> ClassScore:
    """:class:`ClassScore` from the true-positive flags ``tp`` ``(D,)`` bool and scores ``sc`` ``(D,)`` of the
    detections that count (any order) and ``n_gt`` ground-truth boxes: recall and precision with every detection
    given, all-point interpolated AP (module docstring)."""
    order = np.argsort(-sc, kind="stable")
    tp = tp[order]
    ctp = np.cumsum(tp)
    rec = ctp / max(n_gt, 1)
    prec = ctp / np.arange(1, len(tp) + 1) if len(tp) else np.zeros(0)
    # all-point interpolated AP (monotone precision envelope)
    mrec = np.concatenate([[0.0], rec, [1.0]])
    mpre = np.concatenate([[0.0], prec, [0.0]])
    for i in range(len(mpre) - 2, -1, -1):
        mpre[i] = max(mpre[i], mpre[i + 1])
    idx = np.flatnonzero(mrec[1:] != mrec[:-1])
    ap = float(np.sum((mrec[idx + 1] - mrec[idx]) * mpre[idx + 1])) if n_gt else 0.0
    return ClassScore(n_gt, int(len(tp)), float(rec[-1]) if len(tp) else 0.0,
                      float(prec[-1]) if len(tp) else 0.0, ap, rec.round(4).tolist(), prec.round(4).tolist())
