"""Frames between actors: JPEG encoding for the edges that cross tiers, and the per-process count of every copy of a
frame's pixels (the totals per frame are in :mod:`aerodaas.actors.data.plane`'s docstring)."""
from __future__ import annotations

import threading

import cv2
import numpy as np

__all__ = ["FrameCopies", "encode_frame", "decode_frame"]


class FrameCopies:
    """Counts, in one actor process, every place where a frame's pixels are materialised or copied (see
    :mod:`aerodaas.actors.data.plane`'s docstring for the per-frame totals). Counters, in frames:

    * ``materialised``: frames produced by a camera (the one allocation of the pixels);
    * ``tier_jpeg_encoded`` / ``tier_jpeg_decoded``: frames JPEG-encoded here to cross to an actor of another tier /
      decoded here on arrival from one;
    * ``object_store_put`` / ``object_store_get``: frames sent to / received from an actor of the same tier as an
      ObjectRef;
    * ``channel_copy``: frames copied into a same-node channel's shared-memory slot (:mod:`aerodaas.actors.data.channel`; the
      receiver reads the slot in place);
    * ``channel_in_place``: frames a camera made straight in such a slot (:meth:`aerodaas.actors.data.channel_outlet.ChannelOutlet.lend`)
      and sent from there, with no copy;
    * ``recorder_jpeg_encoded``: frames JPEG-encoded by the recorder (written as ``foxglove.CompressedImage``).

    Handing a frame to a component of the same actor copies nothing and is not counted. Thread-safe; a count costs
    one uncontended lock (well under a microsecond)."""

    FIELDS = ("materialised", "tier_jpeg_encoded", "tier_jpeg_decoded", "object_store_put", "object_store_get",
              "channel_copy", "channel_in_place", "recorder_jpeg_encoded")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._n = dict.fromkeys(self.FIELDS, 0)

    def count(self, what: str, n: int = 1) -> None:
        """Add ``n`` frames to counter ``what`` (one of :attr:`FIELDS`; KeyError otherwise)."""
        with self._lock:
            self._n[what] += n

    def snapshot(self) -> dict[str, int]:
        """The counters now, ``{name: frames}``."""
        with self._lock:
            return dict(self._n)


def encode_frame(frame: np.ndarray, quality: int = 85) -> bytes:
    """(H, W, 3) uint8 BGR -> JPEG bytes (for frames crossing tiers). Raises ValueError if encoding fails."""
    ok, buf = cv2.imencode(".jpg", frame, [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:
        raise ValueError(f"cannot JPEG-encode a frame of shape {getattr(frame, 'shape', None)}")
    return buf.tobytes()


def decode_frame(data: bytes) -> np.ndarray:
    """JPEG bytes -> read-only (H, W, 3) uint8 BGR. Raises ValueError for undecodable bytes."""
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot decode a {len(data)}-byte JPEG frame")
    img.flags.writeable = False
    return img
