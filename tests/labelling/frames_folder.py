"""A small frames folder as ``aerodaas label frames`` writes it (``images/``, ``classes.txt``, ``tasks.json`` of Label
Studio tasks with pre-labels), made of the repository's real aerial sample frames (``tests/data/aerial_sample``)
with their first boxes as the detector's predictions."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "aerial_sample"
NAMES = ["car", "large_vehicle", "person"]
#: the sample frames used (640x512 each), in task order, and the frame names they get: two flights, one camera
SOURCES = ("0_100_30_0_03281.jpg", "0_100_30_0_03302.jpg", "1_130_30_0_03841.jpg", "1_80_30_0_01129.jpg")
FRAME_NAMES = ("f1_cam0-000010.jpg", "f1_cam0-000020.jpg", "f2_cam0-000010.jpg", "f2_cam0-000020.jpg")
#: boxes per frame taken as pre-labels
BOXES_PER_FRAME = 3


def rect(x0: float, y0: float, x1: float, y1: float, w: int, h: int, label: str, score: float | None = None) -> dict:
    """A Label Studio ``rectanglelabels`` result of the pixel box x0 y0 x1 y1 on a ``w`` x ``h`` image."""
    r = {"type": "rectanglelabels", "from_name": "label", "to_name": "image", "original_width": w,
         "original_height": h, "value": {"x": 100 * x0 / w, "y": 100 * y0 / h, "width": 100 * (x1 - x0) / w,
                                         "height": 100 * (y1 - y0) / h, "rotation": 0, "rectanglelabels": [label]}}
    if score is not None:
        r["score"] = score
    return r


def sample_boxes(source: str, n: int = BOXES_PER_FRAME) -> list[tuple[int, float, float, float, float]]:
    """The first ``n`` boxes of a sample frame's YOLO labels: (class, x0, y0, x1, y1) pixels of the 640x512 frame."""
    out = []
    for ln in (SAMPLE / "labels" / f"{Path(source).stem}.txt").read_text().splitlines()[:n]:
        c, cx, cy, bw, bh = ln.split()
        cx, cy, bw, bh = float(cx) * 640, float(cy) * 512, float(bw) * 640, float(bh) * 512
        out.append((int(c), cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2))
    return out


def write_frames_folder(folder: Path) -> list[dict]:
    """Write the frames folder at ``folder`` (its images referenced as local files below ``folder``'s parent);
    returns its tasks."""
    (folder / "images").mkdir(parents=True)
    (folder / "classes.txt").write_text("\n".join(NAMES) + "\n")
    tasks = []
    for src, name in zip(SOURCES, FRAME_NAMES):
        im = cv2.imread(str(SAMPLE / "images" / src))
        assert im.shape[:2] == (512, 640), src
        shutil.copyfile(SAMPLE / "images" / src, folder / "images" / name)
        result = [rect(x0, y0, x1, y1, 640, 512, NAMES[c], 0.8) for c, x0, y0, x1, y1 in sample_boxes(src)]
        tasks.append({"data": {"image": f"/data/local-files/?d={folder.name}/images/{name}", "aerodaas_name": name},
                      "predictions": [{"model_version": "aerial_nano", "score": 0.8, "result": result}]})
    (folder / "tasks.json").write_text(json.dumps(tasks, indent=1))
    return tasks
