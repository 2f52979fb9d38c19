"""Labelled frames written as the labelling tools export them, for the loader's tests: the frames (small real JPEGs
drawn with OpenCV), their true boxes in pixels, and one writer per export layout, each following the tool's own
writer (Label Studio: label_studio_sdk ``Converter.convert_to_yolo`` / ``convert_to_coco`` and its upload naming;
CVAT: the "YOLO 1.1" and "COCO 1.0" formats of its documentation)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

NAMES = ["car", "person"]
W, H = 320, 240
#: (flight_camera, frame numbers): three flights, frames named as a DJI drone's extracted frames are
FLIGHTS = (("DJI_0025_cam1", (12, 13, 14)), ("DJI_0031_cam1", (1, 2)), ("DJI_0040_cam2", (7, 8, 9)))


@dataclass(frozen=True)
class Frame:
    """One frame: its ``name`` (``DJI_0025_cam1-000012.jpg``), the 8-hex prefix Label Studio gave its upload, its
    ``flight`` and its true ``boxes`` (x0, y0, x1, y1 pixels) and ``classes`` (indices into :data:`NAMES`)."""

    name: str
    upload_prefix: str
    flight: str
    boxes: tuple
    classes: tuple

    @property
    def stem(self) -> str:
        return Path(self.name).stem

    @property
    def uploaded(self) -> str:
        """The name Label Studio stores the uploaded file under (``<uuid4()[:8]>-<name>``)."""
        return f"{self.upload_prefix}-{self.name}"


def frames() -> list[Frame]:
    """The frames of :data:`FLIGHTS`, each with a car and, every other frame, a person."""
    out, k = [], 0
    for flight, numbers in FLIGHTS:
        for n in numbers:
            boxes = [(20.0 + 10 * k, 30.0 + 4 * k, 60.0 + 10 * k, 50.0 + 4 * k)]
            classes = [0]
            if k % 2:
                boxes.append((200.0 + 3 * k, 100.0, 208.0 + 3 * k, 116.0))
                classes.append(1)
            out.append(Frame(f"{flight}-{n:06d}.jpg", f"{(0x3f2a9c1e + 0x1010101 * k) & 0xFFFFFFFF:08x}", flight,
                             tuple(boxes), tuple(classes)))
            k += 1
    return out


def write_jpeg(path: Path, frame: Frame) -> None:
    """A real W x H JPEG with the frame's boxes drawn (dark rectangles on grey ground)."""
    im = np.full((H, W, 3), 120, np.uint8)
    for (x0, y0, x1, y1), c in zip(frame.boxes, frame.classes):
        cv2.rectangle(im, (int(x0), int(y0)), (int(x1) - 1, int(y1) - 1), (40, 40, 200) if c == 0 else (240,) * 3, -1)
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), im), path


def ls_percent(box: tuple) -> dict:
    """A pixel box as a Label Studio rectangle's value: x, y, width, height in percent of the image."""
    x0, y0, x1, y1 = box
    return {"x": x0 / W * 100, "y": y0 / H * 100, "width": (x1 - x0) / W * 100, "height": (y1 - y0) / H * 100,
            "rotation": 0}


def ls_tasks(fs: list[Frame]) -> list[dict]:
    """Label Studio's JSON export of the frames uploaded to project 1 (``/data/upload/1/<prefix>-<name>``)."""
    tasks = []
    for i, f in enumerate(fs, 1):
        result = [{"id": f"r{i}_{j}", "type": "rectanglelabels", "from_name": "label", "to_name": "image",
                   "original_width": W, "original_height": H, "image_rotation": 0,
                   "value": {**ls_percent(b), "rectanglelabels": [NAMES[c]]}}
                  for j, (b, c) in enumerate(zip(f.boxes, f.classes))]
        tasks.append({"id": i, "data": {"image": f"/data/upload/1/{f.uploaded}"},
                      "annotations": [{"id": i, "completed_by": 1, "result": result}]})
    return tasks


LS_CONFIG = ('<View><Image name="image" value="$image"/><RectangleLabels name="label" toName="image">'
             + "".join(f'<Label value="{n}"/>' for n in NAMES) + "</RectangleLabels></View>")


def _ls_yolo_line(box: tuple, c: int) -> str:
    """One line as label_studio_sdk ``convert_annotation_to_yolo`` computes it from the percent values."""
    v = ls_percent(box)
    return f"{c} {(v['x'] + v['width'] / 2) / 100} {(v['y'] + v['height'] / 2) / 100} {v['width'] / 100} " \
           f"{v['height'] / 100}"


def _ls_notes() -> dict:
    return {"categories": [{"id": i, "name": n} for i, n in enumerate(NAMES)],
            "info": {"year": 2026, "version": "1.0", "contributor": "Label Studio"}}


def write_ls_yolo(root: Path, fs: list[Frame], with_images: bool, cache_prefix: bool = False) -> Path:
    """Label Studio "YOLO" / "YOLO_WITH_IMAGES": ``classes.txt``, ``notes.json``, ``labels/<uploaded stem>.txt``,
    ``images/`` (the uploaded files, or empty: the user then copies the frames in under their own names).
    ``cache_prefix``: the files as its export snapshots name them, ``<md5(url)[:8]>__<uploaded>``."""
    (root / "labels").mkdir(parents=True)
    (root / "images").mkdir()
    (root / "classes.txt").write_text("".join(n + "\n" for n in NAMES))
    (root / "notes.json").write_text(json.dumps(_ls_notes(), indent=2))
    for i, f in enumerate(fs):
        stored = f"{i:08x}__{f.uploaded}" if cache_prefix else f.uploaded
        (root / "labels" / f"{Path(stored).stem}.txt").write_text(
            "".join(_ls_yolo_line(b, c) + "\n" for b, c in zip(f.boxes, f.classes)))
        write_jpeg(root / "images" / (stored if with_images else f.name), f)
    return root


def write_cvat_yolo(root: Path, fs: list[Frame]) -> Path:
    """CVAT "YOLO 1.1" with images: ``obj.data``, ``obj.names``, ``train.txt`` (``data/obj_train_data/<name>``),
    ``obj_train_data/<stem>.txt`` (``%d %.6f %.6f %.6f %.6f``) beside ``obj_train_data/<name>``."""
    (root / "obj_train_data").mkdir(parents=True)
    (root / "obj.names").write_text("".join(n + "\n" for n in NAMES))
    (root / "obj.data").write_text(f"classes = {len(NAMES)}\ntrain = data/train.txt\nnames = data/obj.names\n"
                                   "backup = backup/\n")
    (root / "train.txt").write_text("".join(f"data/obj_train_data/{f.name}\n" for f in fs))
    for f in fs:
        lines = [f"{c} {(x0 + x1) / 2 / W:.6f} {(y0 + y1) / 2 / H:.6f} {(x1 - x0) / W:.6f} {(y1 - y0) / H:.6f}"
                 for (x0, y0, x1, y1), c in zip(f.boxes, f.classes)]
        (root / "obj_train_data" / f"{f.stem}.txt").write_text("\n".join(lines) + "\n")
        write_jpeg(root / "obj_train_data" / f.name, f)
    return root


def coco_doc(fs: list[Frame], file_names: list[str], first_id: int) -> dict:
    """A COCO detection document of the frames (category and image ids from ``first_id``: CVAT 1, Label Studio
    0), each image's ``file_name`` from ``file_names``."""
    images, anns = [], []
    for i, (f, fname) in enumerate(zip(fs, file_names)):
        images.append({"id": first_id + i, "width": W, "height": H, "file_name": fname, "license": 0,
                       "flickr_url": "", "coco_url": "", "date_captured": 0})
        for (x0, y0, x1, y1), c in zip(f.boxes, f.classes):
            anns.append({"id": len(anns) + first_id, "image_id": first_id + i, "category_id": first_id + c,
                         "segmentation": [], "area": (x1 - x0) * (y1 - y0), "bbox": [x0, y0, x1 - x0, y1 - y0],
                         "iscrowd": 0, "attributes": {"occluded": False, "rotation": 0.0}})
    return {"licenses": [{"name": "", "id": 0, "url": ""}], "info": {"contributor": "", "version": ""},
            "categories": [{"id": first_id + i, "name": n, "supercategory": ""} for i, n in enumerate(NAMES)],
            "images": images, "annotations": anns}


def write_cvat_coco(root: Path, fs: list[Frame], image_dir: str) -> Path:
    """CVAT "COCO 1.0" with images: ``annotations/instances_default.json`` (``file_name`` the frame's name) and
    the frames in ``image_dir`` (``images`` or ``images/default``)."""
    (root / "annotations").mkdir(parents=True)
    (root / "annotations" / "instances_default.json").write_text(json.dumps(coco_doc(fs, [f.name for f in fs], 1)))
    for f in fs:
        write_jpeg(root / image_dir / f.name, f)
    return root


def assert_loaded(items, names, fs) -> None:
    """Every frame of ``fs`` loaded once (matched by its name, with or without Label Studio's prefixes), with its
    true boxes (pixels) and classes, and its flight as its sequence."""
    assert names == NAMES
    by_frame = {}
    for it in items:
        match = [f for f in fs if it.path.name.endswith(f.name)]
        assert len(match) == 1, it.path
        by_frame[match[0].name] = it
    assert sorted(by_frame) == sorted(f.name for f in fs)
    for f in fs:
        it = by_frame[f.name]
        assert it.hw == (H, W)
        np.testing.assert_allclose(it.boxes, np.array(f.boxes, np.float32), atol=1e-3, err_msg=f.name)
        assert it.classes.tolist() == list(f.classes), f.name
        assert it.sequence == f.flight, (it.path.name, it.sequence)
