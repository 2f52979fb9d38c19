#!/usr/bin/env python3
"""What a reviewer would change in ``aerodaas label frames``' pre-labels (docs/results/detection.md, "Pre-labels
against a reviewer's boxes"), with AU-AIR's own annotation of its 80-frame sample standing in for the reviewer.
A benchmark helper; production code never imports it.

Every frame gets the pre-labels ``aerodaas label frames`` writes at its defaults, as its selection pass makes them
(:mod:`aerodaas.labelling.select`, ``_score``): the shipped model and its stronger pass
(:func:`aerodaas.labelling.scoring.build_detectors` defaults: score 0.3, margin 0.15, ``enlarged``) merged by
:func:`aerodaas.labelling.scoring.prelabels`, turned into Label Studio tasks by
:func:`aerodaas.labelling.prelabels.label_studio_tasks`; each task's ``predictions`` are read back into pixel boxes.
Every frame is scored (no selection: two of the sample's frames have the same difference hash, and the selection
would drop one as a near-duplicate). Per class, pre-labels and AU-AIR boxes are matched one to
one, best IoU first (the rule of :mod:`aerodaas.labelling.scoring`), down to IoU ``--moved-iou`` (0.5):

* kept: a pair at IoU >= ``--kept-iou`` (0.9), a box the reviewer leaves as it is;
* moved: a pair at IoU in [0.5, 0.9), a box the reviewer drags or resizes;
* removed: a pre-label left unmatched, deleted by the reviewer;
* added: an AU-AIR box left unmatched, drawn by the reviewer.

The same counts with pairs down to IoU 0.3 are in ``match_iou_0.3`` (AU-AIR's boxes are loose: a pre-label on the
right object can fall below 0.5). AU-AIR is CC BY-NC-SA 2.0: used for this measurement only, nothing is kept but
the counts.

    python docs/bench/prelabel_review.py                  # label frames' defaults -> prelabel_review_auair.json
    python docs/bench/prelabel_review.py --score 0.5 --out docs/bench/prelabel_review_auair_score0.5.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SRC = Path(os.environ.get("AUAIR", Path.home() / ".cache/aerodaas/aerial/auair"))
NAMES = ["car", "large_vehicle", "person"]  # AU-AIR's YOLO class ids, as staged by prepare_aerial_data.py


def flight(p: Path) -> str:
    """The flight of an AU-AIR frame ``frame_<flight start>_x_<n>.jpg``."""
    return p.name.split("_")[1]


def truth(p: Path, w: int, h: int) -> list[tuple[str, tuple[float, float, float, float]]]:
    """AU-AIR's boxes of frame ``p``: (class, pixel ``x0, y0, x1, y1``)."""
    out = []
    for ln in (SRC / "labels" / f"{p.stem}.txt").read_text().splitlines():
        k, cx, cy, bw, bh = ln.split()
        cx, cy, bw, bh = float(cx) * w, float(cy) * h, float(bw) * w, float(bh) * h
        out.append((NAMES[int(k)], (cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2)))
    return out


def from_task(task: dict) -> list[tuple[str, tuple[float, float, float, float]]]:
    """A Label Studio task's prediction boxes back in pixels: (class, ``x0, y0, x1, y1``)."""
    out = []
    for r in task["predictions"][0]["result"]:
        v, w, h = r["value"], r["original_width"], r["original_height"]
        x0, y0 = v["x"] * w / 100.0, v["y"] * h / 100.0
        out.append((v["rectanglelabels"][0], (x0, y0, x0 + v["width"] * w / 100.0, y0 + v["height"] * h / 100.0)))
    return out


def match(pred: list, gt: list, low: float) -> list[float]:
    """IoUs of the one-to-one pairs of ``pred`` and ``gt`` boxes (one class) at IoU >= ``low``, best first."""
    from aerodaas.perception.boxes import iou_matrix

    if not pred or not gt:
        return []
    iou = iou_matrix(np.array(pred, float), np.array(gt, float))
    pairs = []
    while iou.size and iou.max() >= low:
        i, j = np.unravel_index(int(np.argmax(iou)), iou.shape)
        pairs.append(float(iou[i, j]))
        iou[i, :], iou[:, j] = 0.0, 0.0
    return pairs


def review(frames: list[tuple[list, list]], cls: str, kept_iou: float, low: float) -> dict:
    """Counts and shares of one class over ``frames`` ((pre-labels, AU-AIR boxes) per frame)."""
    n = {"prelabels": 0, "truth": 0, "kept": 0, "moved": 0, "removed": 0, "added": 0}
    for pred, gt in frames:
        p = [b for c, b in pred if c == cls]
        g = [b for c, b in gt if c == cls]
        pairs = match(p, g, low)
        n["prelabels"] += len(p)
        n["truth"] += len(g)
        n["kept"] += sum(v >= kept_iou for v in pairs)
        n["moved"] += sum(v < kept_iou for v in pairs)
        n["removed"] += len(p) - len(pairs)
        n["added"] += len(g) - len(pairs)
    k = len(frames)
    share = (lambda x: round(x / n["prelabels"], 3)) if n["prelabels"] else (lambda x: None)
    return {**n, "share_kept": share(n["kept"]), "share_moved": share(n["moved"]),
            "share_removed": share(n["removed"]), "removed_per_frame": round(n["removed"] / k, 2),
            "added_per_frame": round(n["added"] / k, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs/bench/prelabel_review_auair.json")
    ap.add_argument("--score", type=float, default=0.3, help="pre-label score threshold (label frames --score)")
    ap.add_argument("--kept-iou", type=float, default=0.9)
    ap.add_argument("--moved-iou", type=float, default=0.5)
    a = ap.parse_args()
    if not (SRC / "images").is_dir():
        raise SystemExit(f"AU-AIR not staged at {SRC} (examples/training/prepare_aerial_data.py auair)")
    import cv2
    from aerodaas.labelling.prelabels import label_studio_tasks
    from aerodaas.labelling.scoring import build_detectors, prelabels
    from aerodaas.labelling.select import Candidate
    from aerodaas.labelling.sources import FrameRef

    paths = sorted((SRC / "images").glob("*.jpg"))
    dets = build_detectors("aerial_nano", score_threshold=a.score, threads=1)
    t0 = time.time()
    picks = []
    for i, p in enumerate(paths):
        img = cv2.imread(str(p))
        c = Candidate(FrameRef(flight(p), "camera", i, None, str(p)), img.shape[1], img.shape[0], 0,
                      np.zeros(128, np.float32))
        c.boxes = prelabels(*dets.detect(img), dets.score_threshold)
        picks.append(c)
    wall = time.time() - t0
    tasks = label_studio_tasks(picks, "images", dets.model_version)
    frames = [(from_task(t), truth(Path(c.ref.source), c.width, c.height)) for c, t in zip(picks, tasks)]
    rep = {"benchmark": "prelabel_review", "dataset": "auair sample (80 frames, 8 flights), CC BY-NC-SA 2.0",
           "reviewer": "AU-AIR's own annotation", "frames": len(frames), "model_version": dets.model_version,
           "score_threshold": dets.score_threshold, "margin": dets.margin, "strong": dets.strong_kind,
           "kept_iou": a.kept_iou, "select_and_prelabel_wall_s": round(wall, 1), "threads": 1,
           "machine": platform.machine(), "load_1min_at_end": round(os.getloadavg()[0], 1)}
    for low in (a.moved_iou, 0.3):
        key = "classes" if low == a.moved_iou else "match_iou_0.3"
        rep[key] = {"match_iou": low, **{cls: review(frames, cls, a.kept_iou, low) for cls in NAMES}}
    a.out.write_text(json.dumps(rep, indent=1) + "\n")
    for key in ("classes", "match_iou_0.3"):
        for cls in NAMES:
            r = rep[key][cls]
            print(f"{key} {cls}: pre-labels {r['prelabels']} truth {r['truth']} kept {r['share_kept']} moved "
                  f"{r['share_moved']} removed {r['share_removed']} ({r['removed_per_frame']}/frame) added "
                  f"{r['added_per_frame']}/frame")
    print(f"-> {a.out}")


if __name__ == "__main__":
    main()
