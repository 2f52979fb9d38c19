"""Fixtures of the labelling tests: the shipped detector's two passes (built once per session) and a stand-in
whose detections follow the picture, for the selection rules without the cost of the model."""
from __future__ import annotations

import numpy as np
import pytest

from aerodaas.labelling.scoring import Detectors, build_detectors
from aerodaas.model.types import Detection


@pytest.fixture(scope="session")
def detectors():
    """:func:`aerodaas.labelling.scoring.build_detectors` with its defaults (the shipped ``aerial_nano``)."""
    return build_detectors()


class PictureDetector:
    """A stand-in detector: one ``car`` box in the top-left quarter of the frame scored by the frame's mean
    brightness (0 to 1), and with ``extra`` a second box in the bottom-right quarter scored by its green mean."""

    def __init__(self, extra: bool) -> None:
        self.extra = extra

    def detect(self, image: np.ndarray) -> list[Detection]:
        h, w = image.shape[:2]
        out = [Detection(class_id=0, class_name="car", score=float(image.mean()) / 255.0,
                         box=(0.0, 0.0, w / 4.0, h / 4.0))]
        if self.extra:
            out.append(Detection(class_id=0, class_name="car", score=float(image[..., 1].mean()) / 255.0,
                                 box=(w / 2.0, h / 2.0, 3 * w / 4.0, 3 * h / 4.0)))
        return out


@pytest.fixture(scope="session")
def picture_detectors() -> Detectors:
    """The two passes as :class:`PictureDetector` (the stronger one sees a second box)."""
    return Detectors(PictureDetector(False), PictureDetector(True), 0.3, 0.15, ["car"], ["car"], "picture@0", "stub")
