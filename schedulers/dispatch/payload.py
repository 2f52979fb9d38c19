"""What an analytics task carries: :class:`FramePayload` (an application's frame, its metadata and the caller's
context) and :func:`frame_from_payload`, the frame of any payload an executor accepts (ndarray, FramePayload,
ObjectRef, JPEG bytes)."""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["FramePayload", "frame_from_payload"]


class FramePayload:
    """A task payload of an application's frame path: ``frame`` ((H, W, 3) uint8 BGR ndarray, the camera's own
    object: never copied on the edge), ``meta`` (:class:`~aerodaas.model.types.FrameMeta`, sent to the cloud with the
    JPEG) and ``context`` (edge-side only: what the caller needs to hand the result on; never sent)."""

    __slots__ = ("frame", "meta", "context")

    def __init__(self, frame: Any, meta: Any = None, context: Any = None) -> None:
        self.frame, self.meta, self.context = frame, meta, context


def frame_from_payload(payload: Any):
    """The frame of a task payload: an ``(H, W, 3)`` uint8 BGR array, from an ndarray, a :class:`FramePayload`, an
    ObjectRef to one, or JPEG bytes. Raises TypeError for anything else and ValueError for undecodable bytes."""
    if isinstance(payload, FramePayload):
        payload = payload.frame
    if payload is None:
        raise TypeError("the task has no frame (payload None); real executors need an image")
    if type(payload).__name__ == "ObjectRef":
        import ray  # lazy: heavy ray

        payload = ray.get(payload)
    if isinstance(payload, (bytes, bytearray, memoryview)):
        import cv2  # lazy: heavy cv2

        img = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError("payload bytes are not a decodable JPEG/PNG image")
        return img
    if isinstance(payload, np.ndarray) and payload.ndim == 3 and payload.shape[2] == 3:
        return payload
    raise TypeError(f"payload must be an (H, W, 3) uint8 BGR array, an ObjectRef to one, or JPEG bytes; "
                    f"got {type(payload).__name__}")
