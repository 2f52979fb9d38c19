"""What a frame looks like, in a few numbers: a difference hash for near-duplicates and a small appearance
embedding for visual diversity (OpenCV and NumPy only).

* :func:`dhash`: the 64-bit difference hash (Krawetz, "Kind of Like That", The Hacker Factor Blog, 2013): the frame
  in grey shrunk to 9x8 pixels (``cv2.INTER_AREA``), one bit per horizontally adjacent pair, set where the left
  pixel is brighter. Two frames whose hashes differ in few bits (:func:`hamming`) look alike.
* :func:`embedding`: a 4x4x4-bin BGR colour histogram (64 values, L1-normalised, square-rooted: the Hellinger
  map, so Euclidean distance compares distributions) beside an 8x8 grey thumbnail (64 values, zero mean, unit
  norm), each half scaled to unit length: a ``(128,)`` float32 vector whose Euclidean distance stays in [0, 2*sqrt(2)].
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["dhash", "hamming", "embedding", "EMBED_DIM"]

#: length of :func:`embedding`
EMBED_DIM = 128


def _grey(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def dhash(image: np.ndarray) -> int:
    """The 64-bit difference hash of an ``(H, W, 3) uint8 BGR`` (or ``(H, W)`` grey) image (module docstring)."""
    small = cv2.resize(_grey(image), (9, 8), interpolation=cv2.INTER_AREA).astype(np.int16)
    bits = (small[:, :-1] > small[:, 1:]).ravel()
    return int(np.packbits(bits).view(">u8")[0])


def hamming(a: int, b: int) -> int:
    """Bits in which two :func:`dhash` values differ (0 to 64)."""
    return (int(a) ^ int(b)).bit_count()


def embedding(image: np.ndarray) -> np.ndarray:
    """The ``(128,)`` float32 appearance vector of an ``(H, W, 3) uint8 BGR`` image (module docstring)."""
    small = cv2.resize(image, (64, 48), interpolation=cv2.INTER_AREA)
    hist = cv2.calcHist([small], [0, 1, 2], None, [4, 4, 4], [0, 256, 0, 256, 0, 256]).ravel().astype(np.float64)
    hist = np.sqrt(hist / max(hist.sum(), 1.0))
    thumb = cv2.resize(_grey(small), (8, 8), interpolation=cv2.INTER_AREA).astype(np.float64).ravel()
    thumb -= thumb.mean()
    parts = [v / n if (n := np.linalg.norm(v)) > 0 else v for v in (hist, thumb)]
    return np.concatenate(parts).astype(np.float32)
