"""Labelled sets for training: what CVAT and Label Studio export (YOLO txt folders, COCO JSON), recognised by
their layout (:mod:`aerodaas.training.labels.layout` lists each), checked in full before any training starts, and
split by video (one video by time).

Every problem is collected (boxes outside the image, non-positive sizes, unknown classes, label files without an
image, images that cannot be read, an empty set) and reported at once as
:class:`~aerodaas.training.labels.check.LabelError`, naming the file, line and value; reading checks image headers
only, so a set of thousands of images is checked in seconds.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from aerodaas.training.labels.check import Checker, LabelError
from aerodaas.training.labels.coco import load_coco
from aerodaas.training.labels.images import LabelledImage, frame_number
from aerodaas.training.labels.layout import detect_layout
from aerodaas.training.labels.yolo import NAME_FILES, load_yolo
from aerodaas.training.label_studio_export import load_tasks

__all__ = ["load_set", "labelled_classes", "split_by_sequence"]


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


def split_by_sequence(items: Sequence[LabelledImage], fraction: float, seed: int) -> tuple[list, list]:
    """Split ``items`` into (train, val) by whole sequences (``LabelledImage.sequence``), about ``fraction`` of the
    images in val, reproducibly for ``seed``. A set of one sequence (the frames of one recording) is split by time
    instead: its last ``fraction`` of the images by frame number (the trailing number of the name,
    :func:`~aerodaas.training.labels.images.frame_number`), at least one and not all, form val, so no validation
    frame lies between two training frames. Raises ValueError for an empty set or a set of one image."""
    seqs = sorted({it.sequence for it in items})
    if not seqs:
        raise ValueError(f"val_fraction={fraction}: the set has no image")
    if len(seqs) == 1:
        if len(items) < 2:
            raise ValueError(f"val_fraction={fraction}: the set has {len(items)} image(s); a validation split needs at "
                             f"least two (or pass --val DIR)")
        by_time = sorted(items, key=lambda it: (frame_number(it.path), it.path.name))
        k = min(max(1, round(fraction * len(items))), len(items) - 1)
        return by_time[:-k], by_time[-k:]
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


def load_set(path: str | Path, names: Sequence[str] | None = None) -> tuple[list[LabelledImage], list[str]]:
    """Read and check the labelled set at ``path``: a folder or a COCO ``.json`` in one of the layouts of
    :mod:`aerodaas.training.labels.layout`. ``names``: the class names in label order (default: the folder's names
    file, or the COCO categories). Returns the images and the class names. Raises :class:`LabelError` listing
    every problem (including an empty set, no class names, or a file that is no export this reads)."""
    root = Path(path)
    if not root.exists():
        raise LabelError(str(root), [f"data={str(root)!r}: no such file or folder"])
    chk = Checker()
    layout = detect_layout(root, chk)
    if layout.kind == "tasks":
        items, names = load_tasks(layout.source, layout.doc, names, chk)
    elif layout.kind == "coco":
        items, names = load_coco(layout.source, layout.doc, names, chk)
    else:
        names = list(names) if names else layout.names
        if not names:
            raise LabelError(str(root), [f"no class names: add one of {NAME_FILES} (one name per line) or pass "
                                         f"--names"])
        items = load_yolo(layout.images, layout.labels, names, chk)
    if not items and not chk.problems:
        chk.problems.append(f"no labelled image found ({layout.tool} at {layout.source}: images in {root}/images "
                            f"or {root}, labels in {root}/labels, or a COCO .json)")
    if chk.problems:
        raise LabelError(str(root), chk.problems)
    return items, list(names)
