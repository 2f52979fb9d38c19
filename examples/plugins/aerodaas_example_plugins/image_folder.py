"""A frame source plug-in (docs/extending-vehicles.md): a camera's frames from a folder of images
with their capture times, so that an unchanged analytics (the built-in ``ObjectDetector``) runs on photos taken
elsewhere — a survey's JPEGs, another camera's stills.

The folder holds the images and an index, a CSV file with the header ``image,capture_t_s`` and one row per image:
its file name (relative to the index's folder) and its capture time in seconds on the run's vehicle clock (0 = the
mission's start), strictly increasing. The camera takes ``"source": "image_folder"`` and the index as its
``index`` property (a path like every file of ``environment.json``: absolute, relative to the environment file, or
under ``$AERODAAS_DATA_DIR``)::

    {"id": "cam", "type": "camera",
     "properties": {"source": "image_folder", "index": "frames/index.csv", "width": 640, "height": 480, "fps": 5}}

At each of the camera's ticks (``fps``, vehicle time ``t``) the source hands over the oldest image not delivered
yet whose capture time is at or before ``t`` — none is skipped as long as ``fps`` is at least the images' rate —
as an ``(height, width, 3)`` ``uint8`` BGR array (OpenCV's ``imread``, resized with ``INTER_AREA`` when its size
differs from the camera's) with its capture time from the index; the recording's image then carries that time.
The index and every image are checked when the environment is loaded, before Ray starts: an error names
``...properties.index``, the line and the value.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Callable, ClassVar

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from aerodaas.model.types import FramePose
from aerodaas.plugins.frames import CapturedFrame, FrameSource, FrameSourceContext

HEADER = ["image", "capture_t_s"]


class ImageFolderConfig(BaseModel):
    """The source's own camera property: ``index``, the CSV file of images and capture times (see the module)."""

    model_config = ConfigDict(extra="forbid")

    index: str = Field(min_length=1, strict=True, description="CSV file: image,capture_t_s (s, vehicle clock)")


def read_index(path: str | Path, where: str = "properties.index") -> list[tuple[Path, float]]:
    """(absolute image path, capture time s) of every row of the index ``path``, in order. Raises ValueError
    naming ``where``, the line and the value: a missing header, an image that is not a file in the folder or that
    OpenCV cannot read, a time that is not a finite number >= 0 or not after the previous one, no row at all."""
    path = Path(path)
    folder = path.parent.resolve()
    rows: list[tuple[Path, float]] = []
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if [h.strip() for h in header or []] != HEADER:
            raise ValueError(f"{where}: {str(path)!r} line 1 must be the header {','.join(HEADER)}, got {header!r}")
        for line, row in enumerate(reader, start=2):
            if len(row) != 2:
                raise ValueError(f"{where}: {str(path)!r} line {line}: expected 2 fields (image, capture_t_s), "
                                 f"got {row!r}")
            image = (folder / row[0].strip()).resolve()
            if folder not in image.parents or not image.is_file():
                raise ValueError(f"{where}: {str(path)!r} line {line}: image {row[0]!r} is not a file in {str(folder)!r}")
            try:
                t = float(row[1])
            except ValueError:
                t = math.nan
            if not math.isfinite(t) or t < 0 or (rows and t <= rows[-1][1]):
                raise ValueError(f"{where}: {str(path)!r} line {line}: capture_t_s must be a finite number of "
                                 f"seconds >= 0 and after the previous row's, got {row[1]!r}")
            if cv2.imread(str(image), cv2.IMREAD_REDUCED_COLOR_8) is None:
                raise ValueError(f"{where}: {str(path)!r} line {line}: OpenCV cannot read image {str(image)!r}")
            rows.append((image, t))
    if not rows:
        raise ValueError(f"{where}: {str(path)!r} lists no image")
    return rows


class ImageFolderSource(FrameSource):
    """``image_folder``: the images of a folder at the capture times of its index (see the module docstring)."""

    name = "image_folder"
    Config: ClassVar[type[BaseModel]] = ImageFolderConfig
    environment_ok = True  # needs no vehicle: an environment camera may use it too

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """The index resolved to an absolute path, then read and checked with every image (:func:`read_index`)."""
        properties["index"] = str(resolve(properties["index"], f"{where}.properties.index"))
        read_index(properties["index"], f"{where}.properties.index")

    def __init__(self, ctx: FrameSourceContext) -> None:
        super().__init__(ctx)
        self.rows = read_index(ctx.properties["index"])
        self.next = 0  # the first row not delivered yet

    def frame_at(self, t: float, pose: FramePose) -> CapturedFrame | None:
        """The oldest image not delivered yet whose capture time is at or before ``t`` (s), or None."""
        if self.next >= len(self.rows) or self.rows[self.next][1] > t:
            return None
        path, capture_t = self.rows[self.next]
        self.next += 1
        return CapturedFrame(load_bgr(path, self.ctx.intrinsics.width, self.ctx.intrinsics.height), capture_t)


def load_bgr(path: Path, width: int, height: int) -> np.ndarray:
    """The image at ``path`` as a (height, width, 3) uint8 BGR array (resized with INTER_AREA when needed). Raises
    ValueError when OpenCV cannot read it (a file changed after the check)."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"OpenCV cannot read image {str(path)!r}")
    if img.shape[:2] != (height, width):
        img = cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)
    return img
