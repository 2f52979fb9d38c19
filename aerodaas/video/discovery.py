"""``source: "mavlink"``: a camera whose video stream the vehicle announces over MAVLink (camera protocol v2), the
contract between the camera sensor and the backend that owns the vehicle's link.

The camera asks with a :class:`StreamRequest` (which camera, which stream, how long to look); the backend answers
with a :class:`DiscoveredStream` (what the camera component announced in ``CAMERA_INFORMATION`` and
``VIDEO_STREAM_INFORMATION``, and :attr:`DiscoveredStream.source`, the announced URI as a camera ``source``) or
raises :class:`StreamDiscoveryError`. The discovered source is then read exactly as a configured one
(:func:`aerodaas.video.source.parse_stream_source`): one data path.

Sources: https://mavlink.io/en/services/camera.html ("Camera Addressing", "Video Streaming"); common.xml
``VIDEO_STREAM_TYPE`` and ``VIDEO_STREAM_ENCODING``; QGroundControl's convention of a bare UDP port ("5600") for an
RTP/UDP stream. Nothing here touches the network.
"""
from __future__ import annotations

import enum
import re
from dataclasses import dataclass

from aerodaas.video.reader import VideoSourceError

__all__ = ["MAVLINK_SOURCE", "StreamRequest", "DiscoveredStream", "StreamDiscoveryError", "VideoStreamType",
           "stream_source", "DEFAULT_DISCOVERY_TIMEOUT_S", "MAX_DISCOVERY_TIMEOUT_S"]

#: the camera ``source`` that asks the vehicle for its stream
MAVLINK_SOURCE = "mavlink"
#: how long discovery looks by default, and at most (seconds, wall clock)
DEFAULT_DISCOVERY_TIMEOUT_S = 10.0
MAX_DISCOVERY_TIMEOUT_S = 120.0
#: VIDEO_STREAM_ENCODING (common.xml) -> the codec of a raw RTP stream (``properties.codec``)
_CODECS = {1: "h264", 2: "h265"}


class StreamDiscoveryError(VideoSourceError):
    """No camera, or no usable stream, within the discovery timeout: the message names the robot, the sensor, what
    was asked and what the vehicle did announce."""


class VideoStreamType(enum.IntEnum):
    """VIDEO_STREAM_TYPE (common.xml): how a camera serves a stream."""

    RTSP = 0
    RTPUDP = 1
    TCP_MPEG = 2
    MPEG_TS = 3


@dataclass(frozen=True)
class StreamRequest:
    """What a camera with ``source: "mavlink"`` asks for: ``camera_component`` the MAVLink component id of the
    camera (None: the camera components in ascending id, the autopilot, ArduPilot's integrated camera, last),
    ``stream_id`` (None: the lowest-numbered stream with a URI), ``timeout_s`` seconds of wall clock for the whole
    search (requests re-sent within it). ``robot_id``/``sensor_id`` name the asker in errors."""

    robot_id: str
    sensor_id: str
    camera_component: int | None = None
    stream_id: int | None = None
    timeout_s: float = DEFAULT_DISCOVERY_TIMEOUT_S

    def describe(self) -> str:
        """What was asked, for messages: e.g. "camera component 100, stream 2"."""
        cam = "any camera" if self.camera_component is None else f"camera component {self.camera_component}"
        return f"{cam}, {'the first stream' if self.stream_id is None else f'stream {self.stream_id}'}"

    def where(self) -> str:
        return f"robot {self.robot_id!r} camera {self.sensor_id!r}"


@dataclass(frozen=True)
class DiscoveredStream:
    """A stream a MAVLink camera announced: ``system``/``component`` ids of the camera, ``camera`` its vendor and
    model (CAMERA_INFORMATION), ``stream_id``, ``stream_name``, ``stream_type``, ``uri`` as sent,
    ``resolution`` (width, height) px, ``framerate_hz``, ``hfov_deg``, ``codec`` ("h264"/"h265" or None when the
    encoding is unknown), and :attr:`source`: the camera source AeroDaaS reads."""

    system: int
    component: int
    camera: str
    stream_id: int
    stream_name: str
    stream_type: VideoStreamType
    uri: str
    resolution: tuple[int, int]
    framerate_hz: float
    hfov_deg: int
    codec: str | None
    source: str

    def event_fields(self) -> dict:
        """The ``video_discovered`` event's fields (JSON)."""
        return {"url": self.source, "uri": self.uri, "system": self.system, "component": self.component,
                "camera": self.camera, "stream_id": self.stream_id, "stream_name": self.stream_name,
                "stream_type": self.stream_type.name, "resolution": list(self.resolution),
                "framerate_hz": self.framerate_hz}

    def describe(self) -> str:
        """One line for the summary: where the URL came from."""
        return (f"announced over MAVLink by camera component {self.component} ({self.camera or 'unnamed'}), "
                f"stream {self.stream_id} {self.stream_name!r} ({self.stream_type.name})")


def codec_of(encoding: int) -> str | None:
    """The codec of VIDEO_STREAM_ENCODING ``encoding`` (1 H264, 2 H265), None when unknown."""
    return _CODECS.get(int(encoding))


def stream_source(stream_type: VideoStreamType, uri: str) -> str:
    """The announced ``uri`` as a camera source. RTSP as sent; RTP/UDP as ``rtp://host:port`` (a bare port, as
    QGroundControl announces "5600", listens on every interface: ``rtp://0.0.0.0:5600``; ``udp://host:port`` is
    the same stream: RTP, not MPEG-TS); MPEG-TS on UDP as ``udp://host:port`` (a bare port likewise); MPEG-TS on
    TCP as ``tcp://host:port``. Anything else is returned as sent (the video source's parser then names it)."""
    uri = uri.strip()
    port = re.fullmatch(r":?(\d{1,5})", uri)
    if stream_type == VideoStreamType.RTPUDP:
        if port:
            return f"rtp://0.0.0.0:{port.group(1)}"
        if uri.lower().startswith(("udp://", "udp265://")):
            return "rtp://" + uri.split("://", 1)[1]
    if stream_type == VideoStreamType.MPEG_TS and port:
        return f"udp://0.0.0.0:{port.group(1)}"
    if stream_type == VideoStreamType.TCP_MPEG and "://" not in uri and uri:
        return f"tcp://{uri}"
    return uri
