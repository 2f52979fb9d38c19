"""``aerodaas label push``: a folder of frames and pre-labels (what ``aerodaas label frames`` writes) made a Label
Studio project, for a reviewer to correct.

The folder ``DIR`` holds ``images/<flight>_<camera>-<frame>.jpg``, ``classes.txt`` (one class per line) and
``tasks.json``, a list of Label Studio tasks ``{"data": {"image": ..., "aerodaas_name": NAME}, "predictions": [...]}``
(predictions as in :mod:`aerodaas.training.label_studio_export`). Push creates the project (one ``RectangleLabels``
control ``label`` on the image ``image``, one ``Label`` per class), a local-files import storage on ``DIR/images``
(so Label Studio serves the frames from where they are, nothing is uploaded) and imports the tasks, each image
referenced as ``/data/local-files/?d=<path below the document root>``. It refuses a project title that already
exists (a second push would add every frame twice); if a step fails, the project it created is deleted again.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence
from urllib.parse import quote
from xml.sax.saxutils import quoteattr

from aerodaas.labelling.label_studio import LabelStudio, LabelStudioError
from aerodaas.training.label_studio_export import image_name, tasks_to_boxes

__all__ = ["PushResult", "label_config", "read_frames_folder", "push"]

#: the largest ``tasks.json`` read (bytes)
MAX_TASKS_BYTES = 256 << 20


@dataclass
class PushResult:
    """What a push made: the project's ``project_id`` and web ``url``, ``tasks`` and ``predictions`` imported."""

    project_id: int
    url: str
    tasks: int
    predictions: int


def label_config(classes: Sequence[str]) -> str:
    """Label Studio's labelling configuration for boxes of ``classes`` on one image (tag names ``image`` and
    ``label``, the names the tasks' predictions use)."""
    labels = "".join(f"<Label value={quoteattr(c)}/>" for c in classes)
    return (f'<View><Image name="image" value="$image"/><RectangleLabels name="label" toName="image">{labels}'
            f"</RectangleLabels></View>")


def read_frames_folder(folder: Path, classes: Sequence[str] | None = None) -> tuple[list[str], list[dict]]:
    """The class names (``classes``, else ``folder/classes.txt``) and the tasks of ``folder/tasks.json``, checked:
    every task's image is in ``folder/images`` and every predicted box has a known class and lies in its image.
    Raises :class:`LabelStudioError` naming the file and the first problems."""
    if not (folder / "tasks.json").is_file():
        raise LabelStudioError(f"DIR={str(folder)!r}: no tasks.json (write the folder with aerodaas label frames)")
    if classes is None:
        f = folder / "classes.txt"
        if not f.is_file():
            raise LabelStudioError(f"DIR={str(folder)!r}: no classes.txt and no --classes")
        classes = [ln.strip() for ln in f.read_text().splitlines() if ln.strip()]
    if not classes or len(set(classes)) != len(classes):
        raise LabelStudioError(f"classes={list(classes)!r}: need at least one class, each once")
    tf = folder / "tasks.json"
    if tf.stat().st_size > MAX_TASKS_BYTES:
        raise LabelStudioError(f"{tf}: larger than {MAX_TASKS_BYTES} bytes")
    try:
        tasks = json.loads(tf.read_text())
    except ValueError as e:
        raise LabelStudioError(f"{tf}: not JSON ({e})") from None
    _, problems = tasks_to_boxes(tasks, classes, str(tf))
    if not problems:
        missing = [image_name(t) for t in tasks if not (folder / "images" / image_name(t)).is_file()]
        problems = [f"{tf}: image {n!r} is not in {folder / 'images'}" for n in missing]
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise LabelStudioError("; ".join(problems[:3]) + more)
    if not tasks:
        raise LabelStudioError(f"{tf}: no task")
    return list(classes), tasks


def document_root(folder: Path, root: str | Path | None) -> Path:
    """The local-files document root Label Studio serves from: ``root``, else the environment's
    ``LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT`` (Label Studio's own setting), else ``folder``'s parent. Raises
    :class:`LabelStudioError` unless ``folder/images`` lies below it."""
    r = Path(root or os.environ.get("LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT") or folder.resolve().parent).resolve()
    images = (folder / "images").resolve()
    if r not in images.parents:
        raise LabelStudioError(f"--document-root {str(r)!r}: {images} is not below it (start Label Studio with "
                               f"LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT set to a folder above DIR)")
    return r


def _local_tasks(folder: Path, root: Path, tasks: list[dict]) -> list[dict]:
    """``tasks`` with each image referenced by its path below ``root`` (and its file name kept in
    ``aerodaas_name``)."""
    out = []
    for t in tasks:
        name = image_name(t)
        rel = (folder / "images" / name).resolve().relative_to(root).as_posix()
        data = {**t["data"], "image": f"/data/local-files/?d={quote(rel)}", "aerodaas_name": name}
        out.append({**t, "data": data})
    return out


def push(ls: LabelStudio, folder: str | Path, title: str, *, classes: Sequence[str] | None = None,
         root: str | Path | None = None) -> PushResult:
    """Make the frames folder ``folder`` the new Label Studio project ``title`` on ``ls`` (module docstring).
    ``root``: Label Studio's local-files document root (:func:`document_root`). Raises :class:`LabelStudioError`
    (bad folder, a project of that title exists, Label Studio refused a step: the project made is deleted)."""
    folder = Path(folder)
    classes, tasks = read_frames_folder(folder, classes)
    tasks = _local_tasks(folder, document_root(folder, root), tasks)
    if len(title.strip()) < 3:
        raise LabelStudioError(f"--project {title!r}: Label Studio needs a title of at least 3 characters")
    ls.whoami()
    existing = ls.projects_titled(title)
    if existing:
        raise LabelStudioError(f"--project {title!r}: already a project at {ls.url} (id {existing[0]['id']}); push "
                               f"makes a new project and refuses to import the frames twice: choose another title "
                               f"or delete that project")
    project = ls.request("POST", "/api/projects", {"title": title, "label_config": label_config(classes)})
    pid = int(project["id"])
    try:
        ls.request("POST", "/api/storages/localfiles",
                   {"project": pid, "path": str((folder / "images").resolve()), "title": "aerodaas frames",
                    "use_blob_urls": True, "regex_filter": r".*\.(jpe?g|png)$"})
        done = ls.request("POST", f"/api/projects/{pid}/import", tasks)
        n = int(done.get("task_count", -1)) if isinstance(done, dict) else -1
        if n != len(tasks):
            raise LabelStudioError(f"project {pid}: Label Studio imported {n} of {len(tasks)} tasks ({done})")
    except BaseException:
        try:
            ls.request("DELETE", f"/api/projects/{pid}")
        except LabelStudioError:
            pass
        raise
    return PushResult(pid, ls.project_url(pid), n, int(done.get("prediction_count", 0)))
