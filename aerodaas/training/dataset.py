"""Labelled images for training: YOLO txt folders and COCO JSON files (what CVAT and Label Studio export), checked
in full before any training starts.

A data folder is either

* YOLO: ``images/`` and ``labels/`` (one ``<stem>.txt`` per image, lines ``class cx cy w h`` normalised to [0, 1];
  an image without a label file has no object) with the class names in ``classes.txt``, ``obj.names`` or
  ``names.txt`` (one per line; CVAT's "YOLO 1.1" export and Label Studio's "YOLO" export), or
* COCO: one ``*.json`` with ``images`` / ``annotations`` (``bbox`` ``[x, y, w, h]`` pixels) / ``categories`` beside
  the images (or in ``annotations/`` with the images in ``images/``), or
* Label Studio JSON: one ``*.json`` export (a list of tasks) with the images in ``images/`` beside it and the class
  names in a names file: its reviewed tasks (:mod:`aerodaas.training.label_studio_export`).

Every problem is collected (boxes outside the image, non-positive sizes, unknown classes, label files without an
image, images that cannot be read, an empty set) and reported at once as :class:`LabelError`, naming the file, line
and value; reading checks image headers only, so a set of thousands of images is checked in seconds.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from aerodaas.training.label_studio_export import local_files_path, tasks_to_boxes

__all__ = ["LabelledImage", "LabelError", "load_set", "labelled_classes", "sequence_of", "split_by_sequence", "IMAGE_EXTS"]

IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
_NAME_FILES = ("classes.txt", "obj.names", "names.txt")
#: a box may reach this far (pixels) outside its image before it is an error (labelling tools round outwards)
EDGE_TOLERANCE_PX = 2.0
_MAX_REPORTED = 20


class LabelError(ValueError):
    """The labelled set cannot be trained on; ``problems`` lists every problem found (file:line: what)."""

    def __init__(self, where: str, problems: list[str]) -> None:
        self.problems = problems
        shown = "\n  ".join(problems[:_MAX_REPORTED])
        more = f"\n  ... and {len(problems) - _MAX_REPORTED} more" if len(problems) > _MAX_REPORTED else ""
        super().__init__(f"{where}: {len(problems)} problem(s) in the labels:\n  {shown}{more}")


@dataclass
class LabelledImage:
    """One training image: ``path``, its ``(height, width)`` in pixels, ``boxes`` ``(N, 4)`` float32 x0 y0 x1 y1
    pixels (clipped to the image) and ``classes`` ``(N,)`` int64 indices into the set's class names."""

    path: Path
    hw: tuple[int, int]
    boxes: np.ndarray
    classes: np.ndarray
    sequence: str = ""
    labelled: np.ndarray | None = None  # (nc,) bool: classes its set labels exhaustively; None = all

    def __post_init__(self) -> None:
        if not self.sequence:
            self.sequence = sequence_of(self.path)


@dataclass
class _Checker:
    problems: list[str] = field(default_factory=list)

    def box(self, where: str, x0: float, y0: float, x1: float, y1: float, hw: tuple[int, int]) -> bool:
        h, w = hw
        if not (x1 > x0 and y1 > y0):
            self.problems.append(f"{where}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) has a non-positive size")
            return False
        t = EDGE_TOLERANCE_PX
        if x0 < -t or y0 < -t or x1 > w + t or y1 > h + t:
            self.problems.append(f"{where}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) px lies outside the "
                                 f"{w}x{h} image")
            return False
        return True


def labelled_classes(path: str | Path, names: Sequence[str]) -> np.ndarray | None:
    """Which classes a set labels exhaustively: the names in ``labelled_classes.txt`` beside its names file (one
    per line), as a ``(nc,)`` bool mask; None (all) without that file. A set of vehicle labels only (cars are boxed,
    people in the same frames are not) says ``car`` and ``large_vehicle`` there, and training then does not teach
    the model that an unboxed person is background. Raises :class:`LabelError` for a name not in ``names``."""
    f = Path(path) / "labelled_classes.txt"
    if not f.is_file():
        return None
    listed = [ln.strip() for ln in f.read_text().splitlines() if ln.strip()]
    bad = [n for n in listed if n not in names]
    if bad:
        raise LabelError(str(f), [f"{f}: class(es) {bad} are not among the set's classes {list(names)}"])
    return np.array([n in listed for n in names])


def sequence_of(path: Path) -> str:
    """The video or flight an image belongs to, from its name: the stem without a trailing frame number
    (``DJI_0005-0018.jpg`` -> ``DJI_0005``; ``frame_000123.png`` -> ``frame``). Splits are made by sequence, never by
    frame: neighbouring frames of one video are near copies and would leak into the validation set."""
    stem = re.sub(r"[-_ .]*\d+$", "", path.stem)
    return stem or path.stem


def split_by_sequence(items: Sequence[LabelledImage], fraction: float, seed: int) -> tuple[list, list]:
    """Split ``items`` into (train, val) by whole sequences (:func:`sequence_of`), about ``fraction`` of the images
    in val, reproducibly for ``seed``. Raises ValueError when there are fewer than two sequences."""
    seqs = sorted({it.sequence for it in items})
    if len(seqs) < 2:
        raise ValueError(f"val_fraction={fraction}: the set has {len(seqs)} sequence(s) ({seqs[:3]}); a split by "
                         f"video needs at least two (name files <video>_<frame>.jpg, or pass --val DIR)")
    order = np.random.default_rng(seed).permutation(len(seqs))
    val, n = set(), 0
    for i in order:
        if n >= fraction * len(items) and val:
            break
        val.add(seqs[i])
        n += sum(1 for it in items if it.sequence == seqs[i])
    if len(val) == len(seqs):
        val.discard(seqs[order[-1]])
    return [it for it in items if it.sequence not in val], [it for it in items if it.sequence in val]


def _header_hw(path: Path) -> tuple[int, int] | None:
    """(height, width) read from a PNG's IHDR or a JPEG's SOFn segment (ISO/IEC 10918-1 B.2.2), else None."""
    with open(path, "rb") as f:
        head = f.read(26)
        if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
            return int.from_bytes(head[20:24], "big"), int.from_bytes(head[16:20], "big")
        if head[:2] != b"\xff\xd8":
            return None
        f.seek(2)
        for _ in range(256):  # segments before the frame header: a bounded walk
            marker = f.read(2)
            if len(marker) < 2 or marker[0] != 0xFF:
                return None
            seg = int.from_bytes(f.read(2), "big")
            if marker[1] in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
                sof = f.read(5)
                return int.from_bytes(sof[1:3], "big"), int.from_bytes(sof[3:5], "big")
            f.seek(seg - 2, 1)
    return None


def _read_hw(path: Path, chk: _Checker) -> tuple[int, int] | None:
    """(height, width) of an image from its header (JPEG, PNG), else by decoding it; None (and a problem noted)
    when it cannot be read."""
    try:
        hw = _header_hw(path)
    except OSError as e:
        chk.problems.append(f"{path}: image cannot be read ({e})")
        return None
    if hw and hw[0] > 0 and hw[1] > 0:
        return hw
    im = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if im is None:
        chk.problems.append(f"{path}: image cannot be read")
        return None
    return im.shape[0], im.shape[1]


def _names_in(folder: Path, names: Sequence[str] | None) -> list[str] | None:
    if names:
        return list(names)
    for cand in _NAME_FILES:
        f = folder / cand
        if f.is_file():
            return [ln.strip() for ln in f.read_text().splitlines() if ln.strip()]
    return None


def _load_yolo(root: Path, names: list[str], chk: _Checker) -> list[LabelledImage]:
    img_dir = root / "images" if (root / "images").is_dir() else root
    lab_dir = root / "labels" if (root / "labels").is_dir() else img_dir
    images = {p.stem: p for p in sorted(img_dir.iterdir()) if p.suffix.lower() in IMAGE_EXTS}
    for lab in sorted(lab_dir.glob("*.txt")):
        if lab.stem not in images and lab.name not in _NAME_FILES:
            chk.problems.append(f"{lab}: label file without an image ({lab.stem}.* not in {img_dir})")
    out = []
    for stem, img in images.items():
        hw = _read_hw(img, chk)
        if hw is None:
            continue
        boxes, classes = [], []
        lab = lab_dir / f"{stem}.txt"
        lines = lab.read_text().splitlines() if lab.is_file() else []
        for n, ln in enumerate(lines, 1):
            if not ln.strip():
                continue
            where = f"{lab}:{n}"
            try:
                c, cx, cy, bw, bh = ln.split()[:5]
                c, cx, cy, bw, bh = int(c), float(cx), float(cy), float(bw), float(bh)
            except ValueError:
                chk.problems.append(f"{where}: expected 'class cx cy w h', got {ln.strip()!r}")
                continue
            if not 0 <= c < len(names):
                chk.problems.append(f"{where}: class {c} is unknown (the set has {len(names)} classes: {names})")
                continue
            h, w = hw
            b = ((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h)
            if chk.box(where, *b, hw):
                boxes.append(b)
                classes.append(c)
        out.append(_item(img, hw, boxes, classes))
    return out


def _item(img: Path, hw: tuple[int, int], boxes: list, classes: list) -> LabelledImage:
    b = np.array(boxes, np.float32).reshape(-1, 4)
    b[:, 0::2] = b[:, 0::2].clip(0, hw[1])
    b[:, 1::2] = b[:, 1::2].clip(0, hw[0])
    return LabelledImage(img, hw, b, np.array(classes, np.int64))


def _load_coco(js: Path, names: list[str] | None, chk: _Checker) -> tuple[list[LabelledImage], list[str]]:
    try:
        doc = json.loads(js.read_text())
        cats = {int(c["id"]): str(c["name"]) for c in doc["categories"]}
        imgs = {int(i["id"]): str(i.get("file_name", i.get("filename"))) for i in doc["images"]}
        anns = doc["annotations"]
    except (KeyError, TypeError, ValueError) as e:
        raise LabelError(str(js), [f"not a COCO detection file ({type(e).__name__}: {e})"]) from None
    names = list(names) if names else [cats[k] for k in sorted(cats)]
    index = {n: i for i, n in enumerate(names)}
    base = js.parent.parent / "images" if js.parent.name == "annotations" else js.parent
    per: dict[int, list] = {i: [] for i in imgs}
    for k, a in enumerate(anns):
        where = f"{js}: annotations[{k}]"
        iid, cid = a.get("image_id"), a.get("category_id")
        if iid not in per:
            chk.problems.append(f"{where}: image_id={iid!r} is not in images")
        elif cats.get(cid) not in index:
            chk.problems.append(f"{where}: category_id={cid!r} ({cats.get(cid)!r}) is not one of the classes {names}")
        else:
            per[iid].append((a.get("bbox"), index[cats[cid]], where))
    out = []
    for iid, fname in imgs.items():
        img = base / fname
        if not img.is_file():
            chk.problems.append(f"{js}: images[id={iid}].file_name={fname!r}: no such image in {base}")
            continue
        hw = _read_hw(img, chk)
        if hw is None:
            continue
        boxes, classes = [], []
        for bbox, c, where in per[iid]:
            try:
                x, y, w, h = (float(v) for v in bbox)
            except (TypeError, ValueError):
                chk.problems.append(f"{where}: bbox={bbox!r} is not [x, y, w, h]")
                continue
            if chk.box(where, x, y, x + w, y + h, hw):
                boxes.append((x, y, x + w, y + h))
                classes.append(c)
        out.append(_item(img, hw, boxes, classes))
    return out, names


def _is_label_studio(js: Path) -> bool:
    """Whether ``js`` is a Label Studio JSON export (a JSON list of tasks; a COCO file is an object)."""
    with open(js, "rb") as f:
        return f.read(4096).lstrip()[:1] == b"["


def _load_label_studio(js: Path, names: Sequence[str] | None, chk: _Checker) -> tuple[list[LabelledImage], list[str]]:
    """A Label Studio JSON export (:mod:`aerodaas.training.label_studio_export`): its reviewed tasks (a submitted
    annotation: exhaustive frames) with their images in ``images/`` beside it or in its own folder; machine-only
    tasks are left out (``aerodaas label pull`` writes them as a set of their own). Class names: ``names``, else
    the names file beside it (the export has none)."""
    names = _names_in(js.parent, names)
    if not names:
        raise LabelError(str(js), [f"{js}: a Label Studio export has no class list: put {_NAME_FILES[0]} (one name "
                                   f"per line, in label order) beside it or pass --names"])
    try:
        tasks = json.loads(js.read_text())
    except ValueError as e:
        raise LabelError(str(js), [f"not a Label Studio JSON export ({e})"]) from None
    kept, problems = tasks_to_boxes(tasks, names, str(js), predictions=False, tolerance=EDGE_TOLERANCE_PX)
    chk.problems += problems
    out = []
    for t in kept:
        rel = local_files_path(t.ref)
        cands = [js.parent / "images" / t.name, js.parent / t.name] + ([js.parent / rel] if rel else [])
        img = next((c for c in cands if c.is_file()), None)
        if img is None:
            chk.problems.append(f"{js}: task {t.task_id}: image {t.name!r} not found in {js.parent}/images or "
                                f"{js.parent}")
            continue
        hw = _read_hw(img, chk)
        if hw is None:
            continue
        if t.hw is not None and t.hw != hw:
            chk.problems.append(f"{js}: task {t.task_id}: {img} is {hw[1]}x{hw[0]} px but was labelled as "
                                f"{t.hw[1]}x{t.hw[0]}")
            continue
        out.append(_item(img, hw, list(t.boxes), list(t.classes)))
    return out, list(names)


def load_set(path: str | Path, names: Sequence[str] | None = None) -> tuple[list[LabelledImage], list[str]]:
    """Read and check the labelled set at ``path`` (module docstring for the layouts). ``names``: the class names
    in label order (default: the folder's names file, or the COCO categories). Returns the images and the class
    names. Raises :class:`LabelError` listing every problem (including an empty set or no class names)."""
    root = Path(path)
    if not root.exists():
        raise LabelError(str(root), [f"data={str(root)!r}: no such file or folder"])
    chk = _Checker()
    jsons = [root] if root.is_file() else sorted(root.glob("*.json")) + sorted(root.glob("annotations/*.json"))
    if jsons:
        if len(jsons) > 1:
            raise LabelError(str(root), [f"several COCO files {[j.name for j in jsons]}: pass one as --data"])
        loader = _load_label_studio if _is_label_studio(jsons[0]) else _load_coco
        items, names = loader(jsons[0], names, chk)
    else:
        found = _names_in(root, names)
        if not found:
            raise LabelError(str(root), [f"no class names: add one of {_NAME_FILES} (one name per line) or pass "
                                         f"--names"])
        names = found
        items = _load_yolo(root, names, chk)
    if not items and not chk.problems:
        chk.problems.append(f"no labelled image found (images in {root}/images or {root}, labels in "
                            f"{root}/labels, or a COCO .json)")
    if chk.problems:
        raise LabelError(str(root), chk.problems)
    return items, list(names)
