"""Video streams as camera sources: RTSP, RTP on UDP (QGroundControl's 5600), MPEG-TS on UDP, V4L2 and video files,
decoded with PyAV into a newest-wins slot, each frame stamped at capture (see docs/video.md).

The names below are resolved on first use (PEP 562), so that a simulated camera's actor, which imports only the
pose sampling (:mod:`aerodaas.video.pose`), does not import the stream reader."""
from __future__ import annotations

import importlib
from typing import Any

#: each public name -> the module that defines it
_HOMES = {"CaptureClock": "aerodaas.video.clock", "StreamReader": "aerodaas.video.reader",
          "StreamSpec": "aerodaas.video.source", "VideoEvent": "aerodaas.video.reader",
          "VideoFrame": "aerodaas.video.reader", "VideoSourceError": "aerodaas.video.reader",
          "is_stream_source": "aerodaas.video.source", "parse_stream_source": "aerodaas.video.source"}

__all__ = ["CaptureClock", "StreamReader", "StreamSpec", "VideoEvent", "VideoFrame", "VideoSourceError",
           "is_stream_source", "parse_stream_source"]


def __getattr__(name: str) -> Any:
    """The public ``name`` from its module (imported now); AttributeError for any other name."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'aerodaas.video' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value
