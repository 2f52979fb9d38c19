"""Camera and video-stream discovery (MAVLink camera protocol v2), the ground-station side: which cameras the
vehicle's system has and where their video streams are, so that a camera with ``source: "mavlink"`` reads the
stream the vehicle announces.

A camera is a component that sends HEARTBEAT with MAV_TYPE_CAMERA (recommended ids MAV_COMP_ID_CAMERA..CAMERA6,
100-105), or the autopilot itself, which may "proxy" cameras attached to it (ArduPilot's AP_Camera, e.g. a Siyi or
a servo-triggered camera). Each candidate is asked with MAV_CMD_REQUEST_MESSAGE (512) for CAMERA_INFORMATION
(259) and VIDEO_STREAM_INFORMATION (269; param2 0 = every stream, else the stream id); a request is re-sent every
:data:`RESEND_S` seconds, alternating with the older MAV_CMD_REQUEST_CAMERA_INFORMATION (521) /
MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION (2504) for cameras that predate REQUEST_MESSAGE (the protocol's migration
notes ask ground stations to support both), until the request's timeout. Sources:
https://mavlink.io/en/services/camera.html ("Camera Addressing", "Camera Discovery", "Video Streaming").
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Protocol

from aerodaas.backends.mavlink._common import M, _enum_name
from aerodaas.video.discovery import (DiscoveredStream, StreamDiscoveryError, StreamRequest, VideoStreamType, codec_of,
                                      stream_source)

__all__ = ["CameraFinder", "RESEND_S"]

#: seconds between two requests to one camera component (wall clock)
RESEND_S = 1.0
#: the messages the finder reads (of any component of the vehicle's system)
WATCHED = frozenset({"HEARTBEAT", "CAMERA_INFORMATION", "VIDEO_STREAM_INFORMATION", "COMMAND_ACK"})
_REQUESTS = {M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_CAMERA_INFORMATION,
             M.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION}

class CameraLink(Protocol):
    """What the finder needs of the vehicle's link (link.py :class:`MavlinkLink`): ``send(fn)`` calls ``fn`` with
    the pymavlink ``MAVLink`` object on the I/O side, ``target`` is the vehicle's (system id, component id), and
    ``serve_components(finder)`` hands the finder every message of the vehicle's system."""

    target: tuple[int, int]

    def send(self, fn: Callable[[Any], Any]) -> None: ...

    def serve_components(self, receiver: Any) -> None: ...


def _text(value: Any) -> str:
    """A MAVLink char[] field as text (pymavlink gives str, or bytes for uint8_t[] fields)."""
    if isinstance(value, str):
        return value.rstrip("\0")
    return bytes(value).rstrip(b"\0").decode(errors="replace")


@dataclass
class _Camera:
    """What one component announced: its CAMERA_INFORMATION (``name``), its streams by id, how many streams it
    said it has, the refusals of our requests (MAV_RESULT names) and when it was last asked."""

    component: int
    heartbeat: bool = False
    name: str | None = None
    streams: dict[int, DiscoveredStream] = field(default_factory=dict)
    stream_count: int = 0
    refused: list[str] = field(default_factory=list)
    asked: int = 0
    next_ask: float = 0.0


class CameraFinder:
    """The cameras of one vehicle's system. :meth:`on_message` takes every message of the system (the backend's I/O
    thread); :meth:`discover` (the caller's thread) asks and waits; requests go out on ``link``."""

    def __init__(self, link: CameraLink) -> None:
        self._link = link
        link.serve_components(self)
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._cams: dict[int, _Camera] = {}

    def _request(self, component: int, command: int, params: tuple) -> None:
        """COMMAND_LONG ``command`` with ``params`` (zero-padded to 7) to ``component`` of the vehicle's system, not
        waited for: the answer is a message (:meth:`on_message`)."""
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        sysid = self._link.target[0]
        self._link.send(lambda mav: mav.command_long_send(sysid, component, command, 0, *p))

    def on_message(self, msg: Any) -> None:
        """Take a message of the vehicle's system (any component): camera HEARTBEATs, CAMERA_INFORMATION,
        VIDEO_STREAM_INFORMATION and the COMMAND_ACKs of our requests; anything else is ignored at once."""
        kind = msg.get_type()
        if kind not in WATCHED:
            return
        comp = int(msg.get_srcComponent())
        if kind == "HEARTBEAT" and msg.type != M.MAV_TYPE_CAMERA:
            return
        if kind == "COMMAND_ACK" and (msg.command not in _REQUESTS or msg.result == M.MAV_RESULT_ACCEPTED):
            return
        with self._changed:
            cam = self._cams.setdefault(comp, _Camera(comp))
            if kind == "HEARTBEAT":
                cam.heartbeat = True
            elif kind == "CAMERA_INFORMATION":
                cam.name = f"{_text(msg.vendor_name)} {_text(msg.model_name)}".strip()
            elif kind == "COMMAND_ACK":
                cam.refused.append(f"{_enum_name('MAV_CMD', msg.command)}: {_enum_name('MAV_RESULT', msg.result)}")
            else:
                s = self._stream(msg, cam)
                cam.stream_count = max(cam.stream_count, int(msg.count))
                cam.streams[s.stream_id] = s
            self._changed.notify_all()

    @staticmethod
    def _stream(msg: Any, cam: _Camera) -> DiscoveredStream:
        try:
            kind = VideoStreamType(int(msg.type))
        except ValueError:
            kind = VideoStreamType.RTSP  # an unknown type: its URI is read as sent (and checked as any source)
        uri = _text(msg.uri)
        return DiscoveredStream(system=int(msg.get_srcSystem()), component=cam.component, camera=cam.name or "",
                                stream_id=int(msg.stream_id), stream_name=_text(msg.name), stream_type=kind, uri=uri,
                                resolution=(int(msg.resolution_h), int(msg.resolution_v)),
                                framerate_hz=float(msg.framerate), hfov_deg=int(msg.hfov),
                                codec=codec_of(getattr(msg, "encoding", 0)), source=stream_source(kind, uri))

    def discover(self, request: StreamRequest, autopilot: int) -> DiscoveredStream:
        """The stream ``request`` asks for, found within ``request.timeout_s`` wall seconds. Candidates: the
        asked component, or every component that sent a camera HEARTBEAT (ascending id) and the ``autopilot``
        component last. Without a stream id the lowest-numbered stream with a URI is taken once the camera's
        announced count of streams is in (or after :data:`RESEND_S`). Raises :class:`StreamDiscoveryError` naming
        the robot, the sensor, what was asked and what the vehicle announced; the backend's LinkLost when the
        link is down."""
        deadline = time.monotonic() + request.timeout_s
        with self._changed:
            for cam in self._cams.values():  # a new search asks again at once
                cam.next_ask, cam.asked = 0.0, 0
        while True:
            now = time.monotonic()
            with self._lock:
                found = self._choice(request, autopilot, now)
                due = [] if found is not None else self._due(request, autopilot, now)
            if found is not None:
                return found
            if now >= deadline:
                raise StreamDiscoveryError(self._failure(request, autopilot))
            for comp, attempt in due:
                self._ask(comp, attempt, request.stream_id)
            with self._changed:
                self._changed.wait(timeout=min(0.1, max(0.0, deadline - time.monotonic())))

    def _candidates(self, request: StreamRequest, autopilot: int) -> list[int]:
        if request.camera_component is not None:
            return [request.camera_component]
        return sorted(c.component for c in self._cams.values() if c.heartbeat and c.component != autopilot) \
            + [autopilot]

    def _due(self, request: StreamRequest, autopilot: int, now: float) -> list[tuple[int, int]]:
        """(component, attempt number) of every candidate to ask now (lock held)."""
        out = []
        for comp in self._candidates(request, autopilot):
            cam = self._cams.setdefault(comp, _Camera(comp))
            if now >= cam.next_ask:
                out.append((comp, cam.asked))
                cam.asked += 1
                cam.next_ask = now + RESEND_S
        return out

    def _ask(self, comp: int, attempt: int, stream_id: int | None) -> None:
        """Ask ``comp`` for its CAMERA_INFORMATION and its streams: REQUEST_MESSAGE on even attempts, the older
        dedicated requests on odd ones."""
        sid = float(stream_id or 0)
        if attempt % 2 == 0:
            self._request(comp, M.MAV_CMD_REQUEST_MESSAGE, (float(M.MAVLINK_MSG_ID_CAMERA_INFORMATION),))
            self._request(comp, M.MAV_CMD_REQUEST_MESSAGE, (float(M.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION), sid))
        else:
            self._request(comp, M.MAV_CMD_REQUEST_CAMERA_INFORMATION, (1.0,))
            self._request(comp, M.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION, (sid,))

    def _choice(self, request: StreamRequest, autopilot: int, now: float) -> DiscoveredStream | None:
        """The stream to read, once decided (lock held): the first candidate in order that announced a matching
        stream, when every candidate before it has been asked twice without announcing one."""
        for comp in self._candidates(request, autopilot):
            cam = self._cams.get(comp)
            if cam is None:
                return None
            usable = {sid: s for sid, s in cam.streams.items() if s.uri and s.source}
            if request.stream_id is not None and request.stream_id in usable:
                return self._named(usable[request.stream_id], cam)
            if request.stream_id is None and usable:
                complete = len(cam.streams) >= cam.stream_count or now >= cam.next_ask
                return self._named(usable[min(usable)], cam) if complete else None
            if cam.asked < 2 and not cam.refused:
                return None  # an earlier candidate may still answer
        return None

    @staticmethod
    def _named(s: DiscoveredStream, cam: _Camera) -> DiscoveredStream:
        """``s`` with its camera's name (CAMERA_INFORMATION may come after VIDEO_STREAM_INFORMATION)."""
        return replace(s, camera=cam.name or s.camera)

    def _failure(self, request: StreamRequest, autopilot: int) -> str:
        """Why nothing was found: what was asked and what every component announced."""
        with self._lock:
            heard = sorted(c.component for c in self._cams.values() if c.heartbeat)
            said = []
            for comp in self._candidates(request, autopilot):
                cam = self._cams.get(comp) or _Camera(comp)
                who = "the autopilot" if comp == autopilot else "camera"
                streams = ", ".join(f"{s.stream_id} {s.stream_name!r} uri {s.uri!r}" for s in cam.streams.values())
                said.append(f"{who} component {comp}: "
                            + ("no CAMERA_INFORMATION" if cam.name is None else f"camera {cam.name!r}")
                            + (f", streams: {streams}" if streams else ", no VIDEO_STREAM_INFORMATION")
                            + (f", refused {sorted(set(cam.refused))}" if cam.refused else ""))
        found = f"camera HEARTBEATs from components {heard}" if heard else "no camera HEARTBEAT (MAV_TYPE_CAMERA)"
        return (f"{request.where()}: properties.source 'mavlink' found no video stream within "
                f"{request.timeout_s:g} s (discovery_timeout_s); asked for {request.describe()}; heard {found}; "
                f"{'; '.join(said)}. The vehicle or its companion computer must announce the stream (camera "
                f"protocol v2: docs/video.md)")
