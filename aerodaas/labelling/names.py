"""File names of extracted frames: ``<flight>_<camera>-<frame:06d>.jpg``.

``flight`` is the recording's or video's file stem and ``camera`` the camera's name, each reduced to letters, digits
and ``-`` (any other run of characters becomes one ``-``; leading and trailing ``-`` are dropped), so the one ``_``
of a name separates the flight from the camera. The training loader groups frames into sequences by stripping a
trailing frame number (:func:`aerodaas.training.labels.images.sequence_of`, regex ``[-_ .]*\\d+$``): a name written here
maps back to ``<flight>_<camera>`` for every flight, ``DJI_0025`` (written ``DJI-0025``) included, because the
stripped run is exactly ``-<frame>`` (the camera part never ends in a separator).
"""
from __future__ import annotations

import re
from pathlib import Path

__all__ = ["clean_name", "flight_of", "frame_name", "FRAME_DIGITS"]

#: zero-padded digits of the frame number in a file name
FRAME_DIGITS = 6


def clean_name(text: str, fallback: str) -> str:
    """``text`` reduced to ``[A-Za-z0-9-]`` (other runs become one ``-``; no ``-`` at either end); ``fallback``
    when nothing is left."""
    out = re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-")
    return out or fallback


def flight_of(path: str | Path) -> str:
    """The flight name of a recording or video file: its cleaned stem (``DJI_0025.MP4`` -> ``DJI-0025``)."""
    return clean_name(Path(path).stem, "flight")


def frame_name(flight: str, camera: str, frame: int) -> str:
    """The file stem of frame ``frame`` (>= 0) of ``camera`` in ``flight``: ``<flight>_<camera>-<frame:06d>``
    (both names cleaned by :func:`clean_name`). Raises ValueError for a negative frame number."""
    if int(frame) < 0:
        raise ValueError(f"frame number must be >= 0, got {frame}")
    return f"{clean_name(flight, 'flight')}_{clean_name(camera, 'cam')}-{int(frame):0{FRAME_DIGITS}d}"
