"""Which export a data path is, from the files the labelling tools write (:func:`detect_layout`):

* Label Studio "YOLO" / "YOLO_WITH_IMAGES" (label_studio_sdk ``Converter.convert_to_yolo``): ``classes.txt``,
  ``notes.json`` (``{"categories": [{"id", "name"}], "info"}``), ``labels/<name>.txt`` and ``images/`` (empty
  without images: put your frames there);
* CVAT "YOLO 1.1": ``obj.data``, ``obj.names``, ``train.txt`` (lines ``data/obj_train_data/<name>.jpg``) and
  ``obj_<subset>_data/<name>.txt`` with the images beside the labels (or in ``images/``);
* any other YOLO folder: ``images/`` and ``labels/`` (or both in the folder itself) with ``classes.txt``,
  ``obj.names`` or ``names.txt``;
* COCO: one ``*.json`` with ``images``, ``annotations`` and ``categories`` in the folder or in ``annotations/``
  (CVAT "COCO 1.0": ``annotations/instances_default.json``; Label Studio "COCO": ``result.json``), or its path;
* a JSON list: Label Studio's JSON export of tasks (kind ``"tasks"``), as a file or in a folder of no label files with its
  frames in ``images/``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from aerodaas.training.labels.check import Checker, LabelError
from aerodaas.training.labels.coco import is_coco
from aerodaas.training.labels.images import IMAGE_EXTS
from aerodaas.training.labels.yolo import NAME_FILES, read_names

__all__ = ["Layout", "detect_layout"]

#: text files of a YOLO folder that are not labels
_NOT_LABELS = (*NAME_FILES, "labelled_classes.txt", "train.txt", "valid.txt", "test.txt")


@dataclass
class Layout:
    """A recognised export: ``kind`` ``"yolo"``, ``"coco"`` or ``"tasks"``; ``source`` the folder or JSON file;
    ``tool`` what wrote it, in words; for YOLO ``names`` (from ``names_file``) and ``images`` / ``labels``
    (relative stem -> file); for COCO and tasks ``doc``, the parsed JSON."""

    kind: str
    source: Path
    tool: str
    names: list[str] | None = None
    names_file: Path | None = None
    images: dict[str, Path] = field(default_factory=dict)
    labels: dict[str, Path] = field(default_factory=dict)
    doc: object = None


def _read_json(f: Path) -> object:
    """The parsed JSON of ``f``, or a :class:`LabelError` naming it (returned: a stray broken file beside a YOLO
    set is no problem of the set)."""
    try:
        return json.loads(f.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        return LabelError(str(f), [f"{f}: cannot be read as JSON ({type(e).__name__}: {e})"])


def _kind_of_json(doc: object) -> str:
    if isinstance(doc, LabelError):
        return "broken"
    if is_coco(doc):
        return "coco"
    if isinstance(doc, list):
        return "tasks"
    if isinstance(doc, dict) and "categories" in doc and "images" not in doc:
        return "notes"  # Label Studio's notes.json beside a YOLO export
    return "other"


def _not_coco(f: Path, kind: str) -> LabelError:
    why = {"notes": "Label Studio's notes.json of a YOLO export (class names only): pass the export's folder, "
                    "with its labels/ and images",
           "other": "an object without 'images', 'annotations' and 'categories' lists"}[kind]
    return LabelError(str(f), [f"{f}: not a COCO detection file: {why}"])


def _files(d: Path, exts: tuple[str, ...], recursive: bool, chk: Checker, skip: tuple[str, ...] = ()) -> dict:
    """Relative stem (posix) -> file, for the files of ``d`` whose suffix is in ``exts``; two files of one stem
    (``a.jpg`` and ``a.png``) are a problem."""
    out: dict[str, Path] = {}
    for f in sorted(d.rglob("*") if recursive else d.iterdir()):
        if f.suffix.lower() not in exts or f.name in skip or not f.is_file():
            continue
        rel = f.relative_to(d).with_suffix("").as_posix()
        if rel in out:
            chk.problems.append(f"{f}: two files for one image ({out[rel].name} too); keep one")
        out[rel] = f
    return out


def _yolo(root: Path, chk: Checker) -> Layout:
    found = read_names(root)
    names, names_file = found if found else (None, None)
    cvat = sorted(d for d in root.glob("obj_*_data") if d.is_dir())
    if cvat:
        lay = Layout("yolo", root, 'CVAT "YOLO 1.1"', names, names_file)
        for d in cvat:
            lay.labels.update(_files(d, (".txt",), True, chk))
            lay.images.update(_files(d, IMAGE_EXTS, True, chk))
        if (root / "images").is_dir():
            lay.images.update(_files(root / "images", IMAGE_EXTS, True, chk))
        return lay
    tool = 'Label Studio "YOLO"' if (root / "notes.json").is_file() else "YOLO folder"
    lay = Layout("yolo", root, tool, names, names_file)
    img_dir = root / "images" if (root / "images").is_dir() else root
    lab_dir = root / "labels" if (root / "labels").is_dir() else root
    lay.images = _files(img_dir, IMAGE_EXTS, img_dir != root, chk)
    lay.labels = _files(lab_dir, (".txt",), lab_dir != root, chk, skip=_NOT_LABELS)
    return lay


def detect_layout(path: Path, chk: Checker) -> Layout:
    """The export at ``path`` (a folder, or a ``.json`` file); problems found on the way (two image files of one
    stem) are noted in ``chk``. Raises :class:`LabelError` naming the file for a JSON file that cannot be read, a
    JSON file that is neither COCO nor a list of tasks (a ``notes.json`` alone, say), a folder with several COCO
    files, and a folder with neither labels, images nor a COCO file beside such a JSON file."""
    if path.is_file():
        if path.suffix.lower() != ".json":
            raise LabelError(str(path), [f"data={str(path)!r}: expected a folder or a COCO .json file"])
        doc = _read_json(path)
        if isinstance(doc, LabelError):
            raise doc
        kind = _kind_of_json(doc)
        if kind not in ("coco", "tasks"):
            raise _not_coco(path, kind)
        return Layout(kind, path, "COCO" if kind == "coco" else "Label Studio JSON", doc=doc)
    jsons = {f: _read_json(f) for f in sorted(path.glob("*.json")) + sorted(path.glob("annotations/*.json"))}
    kinds = {f: _kind_of_json(doc) for f, doc in jsons.items()}
    cocos = [f for f, k in kinds.items() if k == "coco"]
    if len(cocos) > 1:
        raise LabelError(str(path), [f"{path}: several COCO files {[str(f.relative_to(path)) for f in cocos]}: pass "
                                     f"one as --data (repeat --data for several)"])
    if cocos:
        tool = 'CVAT "COCO 1.0"' if cocos[0].parent.name == "annotations" else "COCO"
        return Layout("coco", cocos[0], tool, doc=jsons[cocos[0]])
    lay = _yolo(path, chk)
    tasks = [f for f, k in kinds.items() if k == "tasks"]
    if tasks and not lay.labels:  # Label Studio's JSON export with the frames beside it (images/)
        return Layout("tasks", tasks[0], "Label Studio JSON", doc=jsons[tasks[0]])
    if lay.labels or lay.images:
        return lay
    if "notes" in kinds.values():
        f = next(f for f, k in kinds.items() if k == "notes")
        raise LabelError(str(path), [f"{f}: Label Studio's notes.json of a YOLO export, but no label file "
                                     f"(labels/*.txt) and no image (images/) beside it: unpack the whole export"])
    if kinds:
        f, k = next(iter(kinds.items()))
        raise jsons[f] if k == "broken" else _not_coco(f, k)
    return lay
