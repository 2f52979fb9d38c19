"""Label Studio's JSON export read as boxes: the one conversion that ``aerodaas label pull`` and
:func:`aerodaas.training.dataset.load_set` (a ``*.json`` export given as ``--data``) share.

A Label Studio JSON export is a list of tasks ``{"id", "data": {"image": URL, ...}, "annotations": [...],
"predictions": [...]}``; an annotation or prediction holds ``result`` items, and an image box is one of type
``rectanglelabels`` whose ``value`` has ``x``, ``y``, ``width``, ``height`` in percent of the image
(``original_width`` x ``original_height`` pixels), ``rotation`` in degrees clockwise about the box's top-left
corner, and ``rectanglelabels`` (its class name). Source: Label Studio's export format
(``label_studio_sdk/converter``, ``Converter.convert_to_yolo``: the same percent-to-pixel rule).

A task counts as

* **reviewed** when it has an annotation that was not cancelled (a reviewer submitted it: every object of every
  class is boxed, so the frame is exhaustive); the most recently updated one is used;
* **machine** when it has no annotation but predictions (machine boxes nobody checked); the last prediction is used;
* neither when every annotation was cancelled (the reviewer skipped the frame) or it has no box source at all.

Results of other types (choices, polygons, ...) are left out. No PyTorch here; only :func:`load_tasks` reads
image files.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Sequence
from urllib.parse import parse_qs, unquote, urlsplit

import numpy as np

from aerodaas.training.labels.check import EDGE_TOLERANCE_PX, Checker, LabelError
from aerodaas.training.labels.images import LabelledImage, make_item, original_stem, read_hw
from aerodaas.training.labels.yolo import NAME_FILES, read_names

__all__ = ["TaskBoxes", "tasks_to_boxes", "load_tasks", "image_name", "local_files_path", "strip_upload_prefix"]

@dataclass
class TaskBoxes:
    """One task's boxes: ``task_id``; ``name``, the image file name (upload prefix stripped); ``ref``, the task's
    image reference (a ``/data/...`` URL); ``hw`` ``(height, width)`` pixels from the results (None without boxes);
    ``boxes`` ``(N, 4)`` float32 x0 y0 x1 y1 pixels; ``classes`` ``(N,)`` int64 indices into the class names;
    ``reviewed``: from a submitted annotation (True) or from predictions (False)."""

    task_id: object
    name: str
    ref: str
    hw: tuple[int, int] | None
    boxes: np.ndarray
    classes: np.ndarray
    reviewed: bool


def strip_upload_prefix(name: str) -> str:
    """File ``name`` without Label Studio's upload and cache prefixes (``1a2b3c4d-DJI_0005-0018.jpg`` ->
    ``DJI_0005-0018.jpg``; :func:`~aerodaas.training.labels.images.original_stem`)."""
    p = PurePosixPath(name)
    return original_stem(p.stem) + p.suffix


def local_files_path(ref: str) -> str | None:
    """The path relative to Label Studio's local-files document root of a ``/data/local-files/?d=PATH`` reference,
    else None."""
    parts = urlsplit(ref)
    if not parts.path.rstrip("/").endswith("/data/local-files"):
        return None
    d = parse_qs(parts.query).get("d")
    return d[0] if d else None


def image_ref(task: dict) -> str:
    """The task's image reference: ``data["image"]``, else its first string value ("" if none)."""
    data = task.get("data") if isinstance(task.get("data"), dict) else {}
    ref = data.get("image")
    if isinstance(ref, str):
        return ref
    return next((v for v in data.values() if isinstance(v, str)), "")


def image_name(task: dict) -> str:
    """The image's file name: ``data["aerodaas_name"]`` (what ``aerodaas label frames`` writes), else the last
    part of its reference (the ``d=`` path of a local file), upload prefix stripped."""
    data = task.get("data") if isinstance(task.get("data"), dict) else {}
    name = data.get("aerodaas_name")
    if not isinstance(name, str) or not name:
        ref = image_ref(task)
        name = PurePosixPath(unquote(local_files_path(ref) or urlsplit(ref).path)).name
    return strip_upload_prefix(name)


def _latest(items: list[dict]) -> dict:
    """The most recently updated of ``items`` (ISO 8601 stamps sort as text; id, then list order, break ties)."""
    return max(enumerate(items), key=lambda kv: (str(kv[1].get("updated_at") or kv[1].get("created_at") or ""),
                                                  kv[1].get("id") if isinstance(kv[1].get("id"), int) else -1,
                                                  kv[0]))[1]


def _box_px(v: dict, w: float, h: float) -> tuple[float, float, float, float]:
    """x0 y0 x1 y1 pixels of a ``rectanglelabels`` value (percent of the ``w`` x ``h`` image); a rotated box gives
    the axis-aligned box around it (rotation clockwise about the top-left corner, y pointing down)."""
    x, y = float(v["x"]) / 100 * w, float(v["y"]) / 100 * h
    bw, bh = float(v["width"]) / 100 * w, float(v["height"]) / 100 * h
    rot = math.radians(float(v.get("rotation") or 0.0))
    if rot == 0.0:
        return x, y, x + bw, y + bh
    c, s = math.cos(rot), math.sin(rot)
    xs = [x + px * c - py * s for px, py in ((0, 0), (bw, 0), (bw, bh), (0, bh))]
    ys = [y + px * s + py * c for px, py in ((0, 0), (bw, 0), (bw, bh), (0, bh))]
    return min(xs), min(ys), max(xs), max(ys)


def _result_boxes(result: list, index: dict[str, int], where: str, tolerance: float,
                  problems: list[str]) -> tuple[tuple[int, int] | None, list, list]:
    """The boxes of one annotation's or prediction's ``result``: ((H, W) or None, boxes, classes); problems noted."""
    hw, boxes, classes = None, [], []
    for k, r in enumerate(result if isinstance(result, list) else []):
        if not isinstance(r, dict) or r.get("type") != "rectanglelabels":
            continue
        at = f"{where}.result[{k}]"
        v = r.get("value") or {}
        labels = v.get("rectanglelabels") or []
        if len(labels) != 1 or labels[0] not in index:
            problems.append(f"{at}: rectanglelabels={labels!r} is not one of the classes {list(index)}")
            continue
        try:
            w, h = int(r["original_width"]), int(r["original_height"])
            x0, y0, x1, y1 = _box_px(v, w, h)
        except (KeyError, TypeError, ValueError) as e:
            problems.append(f"{at}: not a box with original_width/original_height and x/y/width/height "
                            f"({type(e).__name__}: {e})")
            continue
        if hw is not None and hw != (h, w):
            problems.append(f"{at}: original size {w}x{h} differs from the task's other boxes ({hw[1]}x{hw[0]})")
            continue
        hw = (h, w)
        if not (x1 > x0 and y1 > y0):
            problems.append(f"{at}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) has a non-positive size")
        elif x0 < -tolerance or y0 < -tolerance or x1 > w + tolerance or y1 > h + tolerance:
            problems.append(f"{at}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) px lies outside the {w}x{h} "
                            f"image")
        else:
            boxes.append((max(x0, 0.0), max(y0, 0.0), min(x1, float(w)), min(y1, float(h))))
            classes.append(index[labels[0]])
    return hw, boxes, classes


def tasks_to_boxes(tasks: object, names: Sequence[str], where: str, *, predictions: bool = True,
                   tolerance: float = 2.0) -> tuple[list[TaskBoxes], list[str]]:
    """The boxes of a Label Studio JSON export ``tasks`` (module docstring: which tasks are reviewed, machine, or
    left out), for the class names ``names``. ``where`` names the export in problems; ``predictions``: False leaves
    machine tasks out (as a training set of exhaustive frames needs); ``tolerance``: pixels a box may reach outside
    its image. Returns (the kept tasks, every problem found: a label not in ``names``, a box outside its image, a
    task that is not a dict, predictions exported as ids only)."""
    problems: list[str] = []
    if not isinstance(tasks, list):
        return [], [f"{where}: not a Label Studio JSON export (a list of tasks), got {type(tasks).__name__}"]
    index = {n: i for i, n in enumerate(names)}
    out = []
    for k, task in enumerate(tasks):
        if not isinstance(task, dict) or not isinstance(task.get("data"), dict):
            problems.append(f"{where}: tasks[{k}] is not a task (a dict with 'data')")
            continue
        tid = task.get("id", k)
        done = [a for a in task.get("annotations") or [] if isinstance(a, dict) and not a.get("was_cancelled")]
        preds = task.get("predictions") or []
        if done:
            src, reviewed, at = _latest(done), True, f"{where}: task {tid} annotation"
        elif predictions and preds and not task.get("annotations"):
            if not all(isinstance(p, dict) for p in preds):
                problems.append(f"{where}: task {tid}: predictions are ids only ({preds[:3]!r}); export them in "
                                f"full (aerodaas label pull does)")
                continue
            src, reviewed, at = _latest(preds), False, f"{where}: task {tid} prediction"
        else:
            continue
        at = f"{at} {src.get('id', '?')}"
        hw, boxes, classes = _result_boxes(src.get("result"), index, at, tolerance, problems)
        out.append(TaskBoxes(tid, image_name(task), image_ref(task), hw, np.array(boxes, np.float32).reshape(-1, 4),
                             np.array(classes, np.int64), reviewed))
    return out, problems


def load_tasks(js: Path, doc: object, names: Sequence[str] | None, chk: Checker) -> tuple[list[LabelledImage], list[str]]:
    """A Label Studio JSON export ``js`` (its parsed list of tasks ``doc``) as a training set: its reviewed tasks
    (a submitted annotation: exhaustive frames) with their images in ``images/`` beside it, in its own folder, or
    at the task's local-files path below it; machine-only tasks are left out (``aerodaas label pull`` writes them
    as a set of their own). Class names: ``names``, else the names file beside it (the export has none). Problems
    go to ``chk``; raises :class:`LabelError` when there are no class names."""
    found = read_names(js.parent)
    names = list(names) if names else (found[0] if found else None)
    if not names:
        raise LabelError(str(js), [f"{js}: a Label Studio export has no class list: put {NAME_FILES[0]} (one name "
                                   f"per line, in label order) beside it or pass --names"])
    kept, problems = tasks_to_boxes(doc, names, str(js), predictions=False, tolerance=EDGE_TOLERANCE_PX)
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
        hw = read_hw(img, chk)
        if hw is None:
            continue
        if t.hw is not None and t.hw != hw:
            chk.problems.append(f"{js}: task {t.task_id}: {img} is {hw[1]}x{hw[0]} px but was labelled as "
                                f"{t.hw[1]}x{t.hw[0]}")
            continue
        out.append(make_item(img, hw, list(t.boxes), list(t.classes)))
    return out, list(names)
