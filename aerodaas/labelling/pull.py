"""``aerodaas label pull``: a Label Studio project's reviewed and machine boxes written as training sets that
``aerodaas train detector`` reads (:mod:`aerodaas.training.dataset`).

``OUT/reviewed/`` holds the frames a reviewer submitted (every object of every class boxed: exhaustive frames);
``OUT/machine/`` the frames that kept only the detector's pre-labels, with an empty ``labelled_classes.txt``: their
boxes are learnt as objects, but what they missed is never taught as background
(:func:`aerodaas.training.dataset.labelled_classes`). Each is a YOLO folder (``images/``, ``labels/``,
``classes.txt``); image names lose Label Studio's upload prefix, so ``<flight>_<camera>-<frame>.jpg`` keeps the
split by video. Frames a reviewer skipped and frames without any box source are left out.

Everything is written to a temporary folder beside ``OUT`` and renamed at the end: on any error nothing is left.
"""
from __future__ import annotations

import os
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from aerodaas.labelling.label_studio import LabelStudio, LabelStudioError
from aerodaas.training.dataset import load_set
from aerodaas.training.labels.check import EDGE_TOLERANCE_PX, LabelError
from aerodaas.training.labels.images import IMAGE_EXTS
from aerodaas.training.label_studio_export import TaskBoxes, local_files_path, tasks_to_boxes

__all__ = ["PullResult", "project_classes", "export_tasks", "pull"]


@dataclass
class PullResult:
    """What a pull wrote: the ``out`` folder, the frames in ``reviewed/`` and ``machine/``, the frames left out
    (``skipped``: no submitted annotation nor predictions, or skipped by the reviewer) and the class ``names``."""

    out: Path
    reviewed: int
    machine: int
    skipped: int
    names: list[str]


def project_classes(project: dict) -> list[str]:
    """The class names of a project's labelling configuration: the ``Label`` values of its ``RectangleLabels``
    control, in order. Raises :class:`LabelStudioError` when it has none."""
    config = project.get("label_config") or ""
    try:
        root = ET.fromstring(config)
    except ET.ParseError as e:
        raise LabelStudioError(f"project {project.get('id')}: label_config is not XML ({e})") from None
    names = [lab.get("value") for rl in root.iter("RectangleLabels") for lab in rl.iter("Label")]
    names = [n for n in names if n]
    if not names:
        raise LabelStudioError(f"project {project.get('id')} ({project.get('title')!r}): its labelling configuration "
                               f"has no RectangleLabels with a Label: no box classes to pull")
    return names


def export_tasks(ls: LabelStudio, project_id: int) -> list[dict]:
    """The project's tasks in Label Studio's JSON export (all tasks, annotations in full), with their predictions
    in full (the export lists only their ids; they come from ``/api/predictions``)."""
    tasks = ls.request("GET", f"/api/projects/{project_id}/export",
                       query={"exportType": "JSON", "download_all_tasks": "true"})
    if not isinstance(tasks, list):
        raise LabelStudioError(f"project {project_id}: the JSON export is not a list of tasks")
    preds = ls.request("GET", "/api/predictions", query={"project": project_id})
    by_task: dict = {}
    for p in preds if isinstance(preds, list) else []:
        by_task.setdefault(p.get("task"), []).append(p)
    for t in tasks:
        if isinstance(t, dict):
            t["predictions"] = sorted(by_task.get(t.get("id"), []), key=lambda p: p.get("id", 0))
    return tasks


def _image_bytes(ls: LabelStudio, t: TaskBoxes, root: Path | None) -> bytes:
    """The task's image: from the local-files document root ``root`` when it is there, else from Label Studio."""
    rel = local_files_path(t.ref)
    if root is not None and rel is not None:
        f = (root / unquote(rel)).resolve()
        if root.resolve() in f.parents and f.is_file():
            return f.read_bytes()
    if not t.ref.startswith(("/", "http://", "https://")):
        raise LabelStudioError(f"task {t.task_id}: image reference {t.ref!r} is not a Label Studio URL")
    return ls.download(t.ref)


def _yolo_lines(t: TaskBoxes) -> str:
    if not len(t.boxes):
        return ""
    h, w = t.hw
    rows = []
    for (x0, y0, x1, y1), c in zip(t.boxes.tolist(), t.classes.tolist()):
        rows.append(f"{c} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} {(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}")
    return "\n".join(rows) + "\n"


def _write_sets(ls: LabelStudio, kept: list[TaskBoxes], names: list[str], tmp: Path, root: Path | None) -> None:
    """Every kept task's image and label file into ``tmp/reviewed`` or ``tmp/machine``; each set checked by
    :func:`load_set` as training will read it. Raises :class:`LabelStudioError` on a bad image or label."""
    seen: dict[str, object] = {}
    for t in kept:
        if Path(t.name).suffix.lower() not in IMAGE_EXTS or "/" in t.name or t.name.startswith("."):
            raise LabelStudioError(f"task {t.task_id}: image name {t.name!r} is not an image file name")
        if t.name in seen:
            raise LabelStudioError(f"task {t.task_id}: image name {t.name!r} is also task {seen[t.name]}'s")
        seen[t.name] = t.task_id
        d = tmp / ("reviewed" if t.reviewed else "machine")
        if not d.exists():
            (d / "images").mkdir(parents=True)
            (d / "labels").mkdir()
            (d / "classes.txt").write_text("\n".join(names) + "\n")
            if not t.reviewed:
                (d / "labelled_classes.txt").write_text("")  # no class is exhaustive: misses are not background
        (d / "images" / t.name).write_bytes(_image_bytes(ls, t, root))
        (d / "labels" / f"{Path(t.name).stem}.txt").write_text(_yolo_lines(t))
    for d in sorted(p for p in tmp.iterdir() if p.is_dir()):
        try:
            items, _ = load_set(d, names)
        except LabelError as e:
            raise LabelStudioError(f"the pulled {d.name} set fails its check: {e.problems[0]}") from None
        sizes = {it.path.name: it.hw for it in items}
        for t in kept:
            if t.hw is not None and t.name in sizes and sizes[t.name] != t.hw:
                raise LabelStudioError(f"task {t.task_id}: image {t.name} is {sizes[t.name][1]}x{sizes[t.name][0]} "
                                       f"px but was labelled as {t.hw[1]}x{t.hw[0]}")


def pull(ls: LabelStudio, project_ref: str, out: str | Path, *, reviewed_only: bool = False,
         root: str | Path | None = None) -> PullResult:
    """Write the project ``project_ref`` (id or title) of ``ls`` as training sets in ``out`` (module docstring).
    ``reviewed_only``: leave the machine frames out; ``root``: Label Studio's local-files document root, read
    directly when given (else images come from Label Studio). Raises :class:`LabelStudioError` (unknown project,
    ``out`` exists, a label not among the project's classes, a box outside its image, an image that cannot be had);
    on error ``out`` is not created."""
    out = Path(out)
    if out.exists():
        raise LabelStudioError(f"--out {str(out)!r}: already exists; pull writes a new folder (remove it or choose "
                               f"another)")
    project = ls.project(str(project_ref))
    names = project_classes(project)
    tasks = export_tasks(ls, int(project["id"]))
    kept, problems = tasks_to_boxes(tasks, names, f"project {project['id']}", predictions=not reviewed_only,
                                    tolerance=EDGE_TOLERANCE_PX)
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise LabelStudioError("; ".join(problems[:3]) + more)
    if not kept:
        raise LabelStudioError(f"project {project['id']} ({project['title']!r}): no submitted annotation"
                               f"{'' if reviewed_only else ' and no prediction'}: nothing to pull")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        _write_sets(ls, kept, names, tmp, Path(root) if root else None)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    n_rev = sum(t.reviewed for t in kept)
    return PullResult(out, n_rev, len(kept) - n_rev, len(tasks) - len(kept), names)
