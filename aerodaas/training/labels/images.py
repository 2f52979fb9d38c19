"""A labelled image (:class:`LabelledImage`), its size read from the file's header, and the video or flight it
belongs to (:func:`sequence_of`), with the prefixes Label Studio puts before uploaded file names taken off."""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aerodaas.training.labels.check import Checker

__all__ = ["IMAGE_EXTS", "LabelledImage", "sequence_of", "frame_number", "original_stem", "read_hw", "make_item"]

IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
#: Label Studio's prefixes before a file name: ``<md5(url)[:8]>__`` where its converter caches a downloaded file
#: (label_studio_tools ``_build_cache_path``), then ``<uuid4()[:8]>-`` given to every uploaded file
#: (label_studio ``data_import.models.upload_name_generator``); each 8 lower-case hex digits
_TOOL_PREFIX = re.compile(r"^(?:[0-9a-f]{8}__)?(?:[0-9a-f]{8}-)?")
#: a trailing frame number and the separators before it (``-000012`` of ``DJI_0025_cam1-000012``)
_FRAME_SUFFIX = re.compile(r"[-_ .]*(\d+)$")


def original_stem(stem: str) -> str:
    """``stem`` without Label Studio's upload and download-cache prefixes (:data:`_TOOL_PREFIX`):
    ``3f2a9c1e-DJI_0025_cam1-000012`` and ``5d41402a__3f2a9c1e-DJI_0025_cam1-000012`` -> ``DJI_0025_cam1-000012``;
    any other stem as it is."""
    return _TOOL_PREFIX.sub("", stem, count=1) or stem


def sequence_of(path: Path) -> str:
    """The video or flight an image belongs to, from its name: the stem without Label Studio's upload prefix
    (:func:`original_stem`) and without a trailing frame number (``DJI_0005-0018.jpg`` -> ``DJI_0005``;
    ``frame_000123.png`` -> ``frame``; ``3f2a9c1e-DJI_0025_cam1-000012.jpg`` -> ``DJI_0025_cam1``). Splits are made
    by sequence, never by frame: neighbouring frames of one video are near copies and would leak into the
    validation set."""
    stem = original_stem(path.stem)
    return _FRAME_SUFFIX.sub("", stem) or stem


def frame_number(path: Path) -> int:
    """The frame number an image's name ends in, after Label Studio's prefixes (:func:`original_stem`):
    ``3f2a9c1e-DJI_0025_cam1-000012.jpg`` -> 12; -1 for a name without one."""
    m = _FRAME_SUFFIX.search(original_stem(path.stem))
    return int(m.group(1)) if m else -1


@dataclass
class LabelledImage:
    """One training image: ``path``, its ``(height, width)`` in pixels, ``boxes`` ``(N, 4)`` float32 x0 y0 x1 y1
    pixels (clipped to the image) and ``classes`` ``(N,)`` int64 indices into the set's class names; ``sequence``
    (default :func:`sequence_of` its path); ``labelled`` ``(nc,)`` bool: the classes its set labels exhaustively
    (None: all)."""

    path: Path
    hw: tuple[int, int]
    boxes: np.ndarray
    classes: np.ndarray
    sequence: str = ""
    labelled: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not self.sequence:
            self.sequence = sequence_of(self.path)


def make_item(img: Path, hw: tuple[int, int], boxes: list, classes: list) -> LabelledImage:
    """The :class:`LabelledImage` of ``img`` with ``boxes`` (x0 y0 x1 y1 pixels) clipped to its ``hw``."""
    b = np.array(boxes, np.float32).reshape(-1, 4)
    b[:, 0::2] = b[:, 0::2].clip(0, hw[1])
    b[:, 1::2] = b[:, 1::2].clip(0, hw[0])
    return LabelledImage(img, hw, b, np.array(classes, np.int64))


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


def read_hw(path: Path, chk: Checker) -> tuple[int, int] | None:
    """(height, width) of an image from its header (JPEG, PNG), else by decoding it; None (and a problem noted
    in ``chk``) when it cannot be read."""
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
