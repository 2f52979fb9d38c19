"""The built-in frame sources of a camera (:mod:`aerodaas.plugins.frames`), one class each, registered under the
word ``properties.source`` names them by (``aerodaas.plugins.registry``, kind ``frame_source``):

* ``sim`` — :class:`RenderedFrames`, rendered from the simulated world at the camera's pose;
* ``backend`` — :class:`BackendFrames`, the vehicle's own video (a backend with ``provides_camera``, the Tello);
* ``mcap`` — :class:`McapFrames`, the frames of a recorded MCAP camera channel, at their recorded times;
* ``stream`` — :class:`StreamFrames`, a video stream or file (RTSP, RTP/UDP, MPEG-TS/UDP or TCP, SDP, V4L2, a
  video file: :func:`aerodaas.video.source.parse_stream_source`); every ``source`` that names no registered frame
  source is one;
* ``mavlink`` — :class:`MavlinkFrames`, the stream the vehicle announces over MAVLink (camera protocol v2,
  ``docs/video.md``).

Units: times in seconds (the run's vehicle clock; a stream frame's host times are ``time.monotonic()`` seconds),
images ``(H, W, 3)`` ``uint8`` BGR.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from aerodaas.model.types import FramePose
from aerodaas.plugins import registry
from aerodaas.plugins.builtin_sensors import DISCOVERY_PROPERTIES, STREAM_PROPERTIES, check_replay_recording
from aerodaas.plugins.frames import (STREAM_SOURCE, CapturedFrame, FrameSource, FrameSourceContext, LiveFrameSource,
                                    frame_source_names)
# aerodaas.video is imported by the stream sources' methods: a simulated camera's actor reads no stream

__all__ = ["RenderedFrames", "BackendFrames", "McapFrames", "StreamFrames", "MavlinkFrames"]


def _backend_declares(backend: str, flag: str) -> bool:
    """Whether the registered backend ``backend`` declares the class attribute ``flag`` true."""
    try:
        return bool(getattr(registry.get("backend", backend), flag, False))
    except registry.UnknownPlugin:
        return False


def _camera_backends() -> list[str]:
    """The registered backends that declare a camera stream (for the error message)."""
    return registry.names_with_flag("backend", "provides_camera")


class RenderedFrames(FrameSource):
    """``sim``: the simulated world (:meth:`aerodaas.sim.world.World.render`) seen from the camera's pose at run
    time ``t``; its ground truth in view travels with the frame."""

    name = "sim"
    needs_world = True
    environment_ok = True
    renders_into = True

    def frame_at(self, t: float, pose: FramePose, out: np.ndarray | None = None) -> CapturedFrame | None:
        frame, truth = self.ctx.world.render(pose, self.ctx.intrinsics, t, out=out)
        return CapturedFrame(frame, t, tuple(truth))


class _NewOnly:
    """Skips a frame whose time (s) is the previous one's: a source polled faster than it produces."""

    def __init__(self) -> None:
        self.last_t: float | None = None

    def fresh(self, got: tuple | None) -> CapturedFrame | None:
        if got is None or got[1] == self.last_t:
            return None
        self.last_t = got[1]
        return CapturedFrame(got[0], float(got[1]))


class BackendFrames(FrameSource):
    """``backend``: the robot's backend's own newest frame (``VehicleBackend.camera``) at its time on the
    vehicle clock; None when it is the one delivered before."""

    name = "backend"

    def __init__(self, ctx: FrameSourceContext) -> None:
        super().__init__(ctx)
        self._new = _NewOnly()

    @classmethod
    def check_for_robot(cls, properties: Mapping[str, Any], robot: Any, where: str) -> None:
        """The robot's backend must declare its own camera stream (``provides_camera``)."""
        if not _backend_declares(robot.backend, "provides_camera"):
            raise ValueError(f"{where}.properties.source: 'backend' needs a backend with its own camera stream "
                             f"(provides_camera: {_camera_backends()}), but backend is {robot.backend!r}")

    def frame_at(self, t: float, pose: FramePose) -> CapturedFrame | None:
        camera = self.ctx.backend.camera
        return self._new.fresh(camera.frame() if camera is not None else None)


class McapFrames(FrameSource):
    """``mcap``: the frame recorded at run time ``t`` on a ``foxglove.CompressedImage`` channel (``properties.topic``,
    default ``/<robot>/camera/<sensor>``) of the MCAP recording ``properties.mcap``, at its recorded time
    (:class:`aerodaas.backends.replay.McapCameraReplay`), to re-run analytics on a recorded flight."""

    name = "mcap"
    camera_properties = ("mcap", "topic")
    environment_ok = True

    def __init__(self, ctx: FrameSourceContext) -> None:
        super().__init__(ctx)
        from aerodaas.backends.replay import McapCameraReplay  # lazy: heavy pymap3d, shapely

        p = ctx.properties
        self.replay = McapCameraReplay(p["mcap"], p.get("topic") or f"/{ctx.robot_id}/camera/{ctx.sensor_id}")
        self._new = _NewOnly()

    @classmethod
    def check_properties(cls, properties: Mapping[str, Any], where: str) -> None:
        """``mcap`` names the recording; ``topic``, when given, is an MCAP topic (``/...``)."""
        if not properties.get("mcap"):
            raise ValueError(f"{where}.mcap must name the MCAP recording to replay when {where}.source "
                             f"is 'mcap', got {properties.get('mcap')!r}")
        topic = properties.get("topic")
        if topic is not None and not topic.startswith("/"):
            raise ValueError(f"{where}.topic must be an MCAP topic starting with '/', got {topic!r}")

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """The recording resolved to an absolute path, the topic defaulted and checked to be a camera channel with
        messages (:func:`aerodaas.plugins.builtin_sensors.check_replay_recording`)."""
        properties["mcap"] = str(resolve(properties["mcap"], f"{where}.properties.mcap"))
        properties.setdefault("topic", f"/{robot_id}/camera/{sensor_id}")
        check_replay_recording(properties["mcap"], properties["topic"], where)

    def frame_at(self, t: float, pose: FramePose) -> CapturedFrame | None:
        return self._new.fresh(self.replay.frame_at(t))


class StreamFrames(LiveFrameSource):
    """``stream`` (any ``source`` that names no registered frame source): the video stream or file the ``source``
    names, read by :class:`aerodaas.video.StreamReader` (``first_frame_timeout_s``, default 10 s, for the first
    frame; ``stall_timeout_s``, default 2 s, before ``video_lost``)."""

    name = STREAM_SOURCE
    camera_properties = STREAM_PROPERTIES

    @classmethod
    def check_properties(cls, properties: Mapping[str, Any], where: str) -> None:
        """Scheme, host, port and codec, by :func:`aerodaas.video.source.parse_stream_source`; a bare word that is
        no stream is named with the registered frame sources (a misspelt one)."""
        from aerodaas.video.source import parse_stream_source  # lazy: start-up cost

        src = properties["source"]
        try:
            parse_stream_source(src, properties.get("transport"), properties.get("codec"))
        except ValueError as e:
            if isinstance(src, str) and src.isidentifier():
                raise ValueError(f"{e}; the registered frame sources: {frame_source_names()}") from None
            raise

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """A video or SDP file is resolved like every other file of the environment."""
        from aerodaas.video.source import parse_stream_source  # lazy: start-up cost

        spec = parse_stream_source(properties["source"], properties.get("transport"), properties.get("codec"))
        if spec.kind in ("file", "sdp"):
            properties["source"] = str(resolve(spec.url, f"{where}.properties.source"))

    def start(self, on_frame: Callable[[], None]) -> None:
        super().start(on_frame)
        self.open(self.ctx.properties["source"], self.ctx.properties.get("codec"))

    def open(self, source: str, codec: str | None) -> None:
        """Read video ``source`` and wait for its first frame (VideoSourceError names the URL)."""
        from aerodaas.video.reader import StreamReader  # lazy: start-up cost
        from aerodaas.video.source import parse_stream_source  # lazy: start-up cost

        p, k = self.ctx.properties, self.ctx.intrinsics
        spec = parse_stream_source(source, p.get("transport") if source.startswith("rtsp") else None, codec)
        self.reader = StreamReader(spec, k.width, k.height, stall_timeout_s=float(p.get("stall_timeout_s") or 2.0),
                                   name=f"{self.ctx.robot_id}/{self.ctx.sensor_id}", on_frame=self._on_frame).start()
        self.reader.wait_first(float(p.get("first_frame_timeout_s") or 10.0))


class MavlinkFrames(StreamFrames):
    """``mavlink``: the stream the vehicle announces (camera protocol v2: ``camera_component``, ``stream_id``,
    ``discovery_timeout_s``), asked of the backend once connected and then read as a configured stream."""

    name = "mavlink"
    camera_properties = STREAM_PROPERTIES + DISCOVERY_PROPERTIES

    @classmethod
    def check_properties(cls, properties: Mapping[str, Any], where: str) -> None:
        """The URL comes from the vehicle once connected; only ``codec`` and ``transport`` are checked now."""
        codec, transport = properties.get("codec"), properties.get("transport")
        if codec is not None and codec not in ("h264", "h265"):
            raise ValueError(f"{where}.codec must be one of ['h264', 'h265'], got {codec!r}")
        if transport is not None and transport not in ("tcp", "udp"):
            raise ValueError(f"{where}.transport must be 'tcp' or 'udp', got {transport!r}")

    @classmethod
    def check_for_robot(cls, properties: Mapping[str, Any], robot: Any, where: str) -> None:
        """The backend must discover the vehicle's announced streams (``discovers_video_streams``)."""
        if not _backend_declares(robot.backend, "discovers_video_streams"):
            raise ValueError(f"{where}.properties.source: 'mavlink' asks the vehicle for its camera's stream "
                             f"over MAVLink, so the robot's backend must be 'mavlink', but backend is "
                             f"{robot.backend!r}")

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """No file: the URL comes from the vehicle."""

    def start(self, on_frame: Callable[[], None]) -> None:
        """Nothing opens before the vehicle connected (:meth:`on_vehicle_connected`)."""
        LiveFrameSource.start(self, on_frame)

    def on_vehicle_connected(self) -> None:
        """Ask the backend for the announced stream (kept in :attr:`discovered`) and read it. Raises
        StreamDiscoveryError (naming robot, sensor and what was asked) or VideoSourceError."""
        if self.reader is not None:
            return
        from aerodaas.video.discovery import (DEFAULT_DISCOVERY_TIMEOUT_S, StreamDiscoveryError,  # lazy: start-up cost
                                              StreamRequest)

        p = self.ctx.properties
        req = StreamRequest(self.ctx.robot_id, self.ctx.sensor_id, p.get("camera_component"), p.get("stream_id"),
                            float(p.get("discovery_timeout_s") or DEFAULT_DISCOVERY_TIMEOUT_S))
        found = self.ctx.backend.discover_video_stream(req)
        self.discovered = found
        codec = p.get("codec") or found.codec if found.source.startswith("rtp://") else None
        try:
            self.open(found.source, codec)
        except ValueError as e:  # a URI this camera source cannot read: the discovery's failure, named
            raise StreamDiscoveryError(f"{req.where()}: the vehicle announced {found.uri!r} "
                                       f"({found.describe()}), which is not a readable stream: {e}") from None
