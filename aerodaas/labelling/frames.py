"""``aerodaas label frames`` as a function: :func:`label_frames` reads the inputs, selects the frames
(:func:`aerodaas.labelling.select.select_frames`) and writes the output folder ``out``:

* ``images/<flight>_<camera>-<frame:06d>.jpg`` (:mod:`aerodaas.labelling.names`), ``classes.txt`` (one class a line);
* ``tasks.json`` (Label Studio tasks with predictions), ``annotations.xml`` (CVAT for images 1.1), ``coco.json``
  (COCO detection JSON): :mod:`aerodaas.labelling.prelabels`;
* ``selection.json``: the run's parameters and seed, per flight the frames read, candidates and quota, and per
  picked frame its flight, camera, source file, frame number, time, pose, size, why it was picked and its scores;
* ``poses/<name>.json``: the pose of each picked recording frame that has one (the vehicle's recorded pose nearest
  in time, :class:`aerodaas.labelling.sources.McapSource`).

Everything is written into a hidden folder beside ``out`` and renamed to ``out`` at the end; on any error the
partial folder is removed, so ``out`` is either complete or absent.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Sequence

import cv2

from aerodaas.labelling.prelabels import coco_json, cvat_xml, image_file, label_studio_tasks
from aerodaas.labelling.scoring import build_detectors
from aerodaas.labelling.select import Progress, SelectOptions, Selection, select_frames
from aerodaas.labelling.sources import LabelInputError, open_source

__all__ = ["label_frames", "images_url_path", "JPEG_QUALITY"]

#: JPEG quality of the written frames
JPEG_QUALITY = 95


def images_url_path(out: Path, document_root: Path | None) -> str:
    """``out/images`` relative to ``document_root`` (default: ``out``'s parent), ``/``-separated: the path Label
    Studio's local-files URLs carry when ``LOCAL_FILES_DOCUMENT_ROOT`` is ``document_root``. Raises
    :class:`LabelInputError` when ``out`` is not inside ``document_root``."""
    root = (document_root if document_root is not None else out.parent).resolve()
    images = (out / "images").resolve()
    try:
        return images.relative_to(root).as_posix()
    except ValueError:
        raise LabelInputError(f"--document-root {str(root)!r}: does not contain --out {str(out)!r}") from None


def _check_out(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise LabelInputError(f"--out {str(out)!r}: exists and is not an empty folder (choose a new one)")
    if not out.parent.is_dir():
        raise LabelInputError(f"--out {str(out)!r}: its parent folder does not exist")


def _frame_record(c) -> dict:
    r = c.ref
    return {"file": f"images/{image_file(c)}", "flight": r.flight, "camera": r.camera, "source": r.source,
            "frame": r.index, "t_s": r.t_s, "pose": r.pose, "width": c.width, "height": c.height,
            "reason": c.reason, "scores": c.scores, "boxes": len(c.boxes or [])}


def _write(tmp: Path, sel: Selection, sources: list, url_path: str, extra: dict, progress: Progress | None) -> None:
    """Every output file of ``sel`` into ``tmp``: the images (a third decode pass over the picks' sources)."""
    (tmp / "images").mkdir(parents=True)
    picks = {c.ref.key: c for c in sel.picked}
    flights = {c.ref.flight for c in sel.picked}
    done = 0
    for s in sources:
        if s.flight not in flights:
            continue
        for ref, img in s.frames(lambda r: r.key in picks):
            c = picks[ref.key]
            if not cv2.imwrite(str(tmp / "images" / image_file(c)), img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]):
                raise OSError(f"cannot write {tmp / 'images' / image_file(c)}")
            if ref.pose is not None:
                (tmp / "poses").mkdir(exist_ok=True)
                (tmp / "poses" / f"{ref.name}.json").write_text(json.dumps(
                    {"flight": ref.flight, "camera": ref.camera, "frame": ref.index, "t_s": ref.t_s,
                     "source": ref.source, "pose": ref.pose}, indent=1))
            done += 1
            if progress is not None:
                progress("write", done, len(picks))
    classes = list(sel.detectors.classes)
    (tmp / "classes.txt").write_text("".join(f"{n}\n" for n in classes))
    (tmp / "tasks.json").write_text(json.dumps(label_studio_tasks(sel.picked, url_path, sel.detectors.model_version),
                                               indent=1))
    cvat_xml(sel.picked, classes, extra["out_name"]).write(tmp / "annotations.xml", encoding="utf-8",
                                                           xml_declaration=True)
    (tmp / "coco.json").write_text(json.dumps(coco_json(sel.picked, classes), indent=1))
    flights_doc = {f: {"frames_read": sel.read.get(f, 0), "candidates": n, "quota": sel.quotas.get(f, 0)}
                   for f, n in sel.candidates.items()}
    doc = {"parameters": {**sel.parameters(), **extra}, "flights": flights_doc,
           "frames": [_frame_record(c) for c in sel.picked]}
    (tmp / "selection.json").write_text(json.dumps(doc, indent=1))


def label_frames(inputs: Sequence[str | os.PathLike], out: str | os.PathLike, options: SelectOptions, *,
                 model: str = "aerial_nano", classes: Sequence[str] | None = None, score_threshold: float = 0.3,
                 margin: float = 0.15, strong: str = "enlarged", document_root: str | os.PathLike | None = None,
                 threads: int = 1, progress: Progress | None = None) -> Selection:
    """Select ``options.budget`` frames of ``inputs`` (MCAP recordings ``*.mcap`` and video files) and write them
    with their pre-labels to ``out`` (module docstring). ``model``/``classes``/``score_threshold``/``margin``/
    ``strong``: :func:`aerodaas.labelling.scoring.build_detectors`; ``document_root``: Label Studio's
    ``LOCAL_FILES_DOCUMENT_ROOT`` the task URLs are relative to (default ``out``'s parent).

    Raises :class:`~aerodaas.labelling.sources.LabelInputError` naming the bad input (a missing or undecodable
    file, a recording without camera channels, a budget above the candidates, an unknown held-out flight or class,
    ``out`` not new) before anything is written; OSError when writing fails (``out`` is then left absent)."""
    out = Path(out)
    _check_out(out)
    url_path = images_url_path(out, None if document_root is None else Path(document_root))
    if not inputs:
        raise LabelInputError("no input: give MCAP recordings or video files")
    sources = [open_source(p) for p in inputs]
    dets = build_detectors(model, classes, score_threshold, margin, strong, threads)
    sel = select_frames(sources, options, dets, progress)
    extra = {"inputs": [str(p) for p in inputs], "out_name": out.name, "images_url_path": url_path,
             "document_root": str(Path(document_root).resolve() if document_root is not None
                                  else out.parent.resolve())}
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _write(tmp, sel, sources, url_path, extra, progress)
        if out.exists():
            out.rmdir()  # empty (checked above)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return sel
