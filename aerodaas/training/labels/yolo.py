"""YOLO txt labels: one ``<stem>.txt`` per image, lines ``class cx cy w h`` normalised to [0, 1] of the image's
width and height (the Darknet format CVAT's "YOLO 1.1" and Label Studio's "YOLO" exports write), paired with the
images by stem, with or without Label Studio's upload prefix
(:func:`~aerodaas.training.labels.images.original_stem`)."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Sequence

from aerodaas.training.labels.check import Checker
from aerodaas.training.labels.images import LabelledImage, make_item, original_stem, read_hw

__all__ = ["NAME_FILES", "read_names", "pair_labels", "load_yolo"]

#: the files that hold a YOLO set's class names, one per line: Label Studio's, CVAT's, a plain list
NAME_FILES = ("classes.txt", "obj.names", "names.txt")


def read_names(folder: Path) -> tuple[list[str], Path] | None:
    """The class names in the first of :data:`NAME_FILES` in ``folder`` (one per line, blank lines skipped) and
    that file, else None."""
    for cand in NAME_FILES:
        f = folder / cand
        if f.is_file():
            return [ln.strip() for ln in f.read_text().splitlines() if ln.strip()], f
    return None


def _key(rel: str) -> str:
    head, _, stem = rel.rpartition("/")
    return f"{head}/{original_stem(stem)}" if head else original_stem(stem)


def pair_labels(images: dict[str, Path], labels: dict[str, Path], chk: Checker) -> dict[Path, Path | None]:
    """Each image's label file (None: no label file, no object). ``images`` / ``labels``: relative stem
    (``sub/DJI_0025-0001``) -> file. A label pairs with the image of the same stem, else with the one whose stem
    is the same once Label Studio's upload prefix is taken off either side (its YOLO export names the labels
    ``3f2a9c1e-DJI_0025-0001.txt`` while the user's images keep their own names). A label file without an image,
    or one that fits several images (or an image several labels), is a problem noted in ``chk``."""
    out: dict[Path, Path | None] = {p: None for p in images.values()}
    left_labels = {}
    for rel, lab in labels.items():
        if rel in images:
            out[images[rel]] = lab
        else:
            left_labels[rel] = lab
    by_key: dict[str, list[Path]] = defaultdict(list)
    for rel, img in images.items():
        if out[img] is None:
            by_key[_key(rel)].append(img)
    lab_by_key: dict[str, list[Path]] = defaultdict(list)
    for rel, lab in left_labels.items():
        lab_by_key[_key(rel)].append(lab)
    for key, labs in lab_by_key.items():
        imgs = by_key.get(key, [])
        if not imgs:
            chk.problems += [f"{lab}: label file without an image ({lab.stem}.* or {original_stem(lab.stem)}.* "
                             f"not among the images)" for lab in labs]
        elif len(imgs) > 1 or len(labs) > 1:
            chk.problems.append(f"{', '.join(map(str, labs))}: label file(s) that fit several images or one image "
                                f"several times ({', '.join(map(str, imgs))}); keep one of each")
        else:
            out[imgs[0]] = labs[0]
    return out


def _parse(lab: Path, names: Sequence[str], hw: tuple[int, int], chk: Checker) -> tuple[list, list]:
    boxes, classes = [], []
    for n, ln in enumerate(lab.read_text().splitlines(), 1):
        fields = ln.split()
        if not fields:
            continue
        where = f"{lab}:{n}"
        try:
            if len(fields) != 5:
                raise ValueError(len(fields))
            c, cx, cy, bw, bh = int(fields[0]), *(float(v) for v in fields[1:])
        except ValueError:
            chk.problems.append(f"{where}: expected 'class cx cy w h', got {ln.strip()!r} (a polygon or an oriented "
                                f"box has more values: export rectangles)")
            continue
        if not 0 <= c < len(names):
            chk.problems.append(f"{where}: class {c} is unknown (the set has {len(names)} classes: {list(names)})")
            continue
        h, w = hw
        b = ((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h)
        if chk.box(where, *b, hw):
            boxes.append(b)
            classes.append(c)
    return boxes, classes


def load_yolo(images: dict[str, Path], labels: dict[str, Path], names: Sequence[str],
              chk: Checker) -> list[LabelledImage]:
    """The labelled images of a YOLO set (``images`` / ``labels``: relative stem -> file, paired by
    :func:`pair_labels`), boxes in pixels; every problem (a malformed line, an unknown class index, a box outside
    its image, an unreadable image) is noted in ``chk`` naming the file and line."""
    out = []
    for img, lab in pair_labels(images, labels, chk).items():
        hw = read_hw(img, chk)
        if hw is None:
            continue
        boxes, classes = _parse(lab, names, hw, chk) if lab is not None else ([], [])
        out.append(make_item(img, hw, boxes, classes))
    return out
