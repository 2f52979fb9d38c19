"""COCO detection JSON (``images`` / ``annotations`` with ``bbox`` ``[x, y, w, h]`` pixels / ``categories``;
cocodataset.org "Data format"), as CVAT's "COCO 1.0" and Label Studio's "COCO" exports write it, with each image's
``file_name`` found wherever those tools leave the image (:func:`find_image`)."""
from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Sequence

from aerodaas.training.labels.check import Checker, LabelError
from aerodaas.training.labels.images import IMAGE_EXTS, LabelledImage, make_item, original_stem, read_hw

__all__ = ["is_coco", "export_root", "ImageIndex", "find_image", "load_coco"]


def is_coco(doc: object) -> bool:
    """True for a parsed JSON document that is a COCO detection file: an object with ``images``, ``annotations``
    and ``categories`` lists (a Label Studio JSON export is a list of tasks; its YOLO export's ``notes.json`` has
    ``categories`` only)."""
    return isinstance(doc, dict) and all(isinstance(doc.get(k), list) for k in ("images", "annotations",
                                                                              "categories"))


def export_root(js: Path) -> Path:
    """The folder of the export a COCO file belongs to: its folder, or that folder's parent for CVAT's
    ``annotations/instances_<subset>.json``."""
    return js.parent.parent if js.parent.name == "annotations" else js.parent


class ImageIndex:
    """Every image file under an export's folder (:func:`export_root`) by base name and by base name without
    Label Studio's upload prefix; the folder is walked once, on the first :meth:`lookup` (only a ``file_name``
    that is not where the tools put it needs it)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._tables: tuple[dict[str, list[Path]], dict[str, list[Path]]] | None = None

    def lookup(self, name: str) -> list[list[Path]]:
        """The images named ``name``, then those named so once Label Studio's prefixes are taken off both."""
        if self._tables is None:
            by_name: dict[str, list[Path]] = defaultdict(list)
            by_original: dict[str, list[Path]] = defaultdict(list)
            for d, _, files in os.walk(self.root):
                for f in files:
                    p = Path(d) / f
                    if p.suffix.lower() in IMAGE_EXTS:
                        by_name[f].append(p)
                        by_original[original_stem(p.stem) + p.suffix].append(p)
            self._tables = by_name, by_original
        n = Path(name)
        return [self._tables[0].get(name, []), self._tables[1].get(original_stem(n.stem) + n.suffix, [])]


def find_image(js: Path, file_name: str, index: ImageIndex) -> tuple[Path | None, str]:
    """The image ``file_name`` of the COCO file ``js`` names, and "" (or None and why not). Tried in order:
    ``file_name`` under the json's folder, its parent, ``images/`` and ``images/default/`` of the export (CVAT
    writes ``images/`` or ``images/<subset>/``); then by base name anywhere in the export (Label Studio writes
    ``file_name`` relative to a temporary folder, ``../../…/upload/1/3f2a9c1e-a.jpg``, and copies the image into
    ``images/``); then by base name without Label Studio's upload prefix (the user's own copy, ``a.jpg``)."""
    root = export_root(js)
    for base in dict.fromkeys((js.parent, js.parent.parent, root / "images", root / "images" / "default")):
        cand = base / file_name
        if cand.is_file():
            return cand, ""
    for found in index.lookup(Path(file_name.replace("\\", "/")).name):
        if len(found) == 1:
            return found[0], ""
        if len(found) > 1:
            return None, f"several images fit it: {', '.join(str(p) for p in found[:5])}"
    return None, f"no such image under {root} (nor in images/ or images/default/)"


def _categories(js: Path, doc: dict, names: Sequence[str] | None) -> tuple[dict, list[str]]:
    try:
        cats = {int(c["id"]): str(c["name"]) for c in doc["categories"]}
    except (KeyError, TypeError, ValueError) as e:
        raise LabelError(str(js), [f"{js}: categories: not a COCO detection file ({type(e).__name__}: {e})"]) \
            from None
    return cats, list(names) if names else [cats[k] for k in sorted(cats)]


def _boxes(js: Path, doc: dict, cats: dict, names: list[str], chk: Checker) -> dict[int, list]:
    """Per image id, its annotations as (bbox, class index, where)."""
    index = {n: i for i, n in enumerate(names)}
    per: dict[int, list] = {}
    for k, i in enumerate(doc["images"]):
        iid = i.get("id") if isinstance(i, dict) else None
        if isinstance(iid, int) and iid not in per:
            per[iid] = []
        else:
            chk.problems.append(f"{js}: images[{k}]: id={iid!r} is not a unique integer")
    for k, a in enumerate(doc["annotations"]):
        where = f"{js}: annotations[{k}]"
        iid, cid = (a.get("image_id"), a.get("category_id")) if isinstance(a, dict) else (None, None)
        if iid not in per:
            chk.problems.append(f"{where}: image_id={iid!r} is not in images")
        elif cats.get(cid) not in index:
            chk.problems.append(f"{where}: category_id={cid!r} ({cats.get(cid)!r}) is not one of the classes {names}")
        else:
            per[iid].append((a.get("bbox"), index[cats[cid]], where))
    return per


def load_coco(js: Path, doc: dict, names: Sequence[str] | None, chk: Checker) -> tuple[list[LabelledImage],
                                                                                       list[str]]:
    """The labelled images of the COCO document ``doc`` read from ``js`` (:func:`is_coco`), boxes in pixels, and
    the class names (``names``, default the categories in id order). Problems (an annotation of an unknown image
    or category, a malformed ``bbox``, a box outside its image, an image not found or unreadable) are noted in
    ``chk`` naming the file and entry; raises :class:`LabelError` when the categories are malformed."""
    cats, names = _categories(js, doc, names)
    per = _boxes(js, doc, cats, names, chk)
    index, out = ImageIndex(export_root(js)), []
    for k, i in enumerate(doc["images"]):
        if not isinstance(i, dict) or i.get("id") not in per:
            continue  # reported by _boxes
        fname = i.get("file_name")
        if not isinstance(fname, str) or not fname:
            chk.problems.append(f"{js}: images[{k}]: file_name={fname!r} is not a file name")
            continue
        img, why = find_image(js, fname, index)
        if img is None:
            chk.problems.append(f"{js}: images[id={i['id']}].file_name={fname!r}: {why}")
            continue
        hw = read_hw(img, chk)
        if hw is None:
            continue
        boxes, classes = [], []
        for bbox, c, where in per[i["id"]]:
            try:
                x, y, w, h = (float(v) for v in bbox)
            except (TypeError, ValueError):
                chk.problems.append(f"{where}: bbox={bbox!r} is not [x, y, w, h]")
                continue
            if chk.box(where, x, y, x + w, y + h, hw):
                boxes.append((x, y, x + w, y + h))
                classes.append(c)
        out.append(make_item(img, hw, boxes, classes))
    return out, names
