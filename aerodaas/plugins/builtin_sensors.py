"""The built-in sensor types — ``camera``, ``odometry`` and ``stat_stream`` — declared through the same contract as
a sensor plug-in (:class:`aerodaas.plugins.sensor.SensorPlugin`): a name, a pydantic ``Config`` of the sensor's
``properties`` (strict: a string or a boolean is not a number; every size, rate and duration bounded), and where its
readings come from (:class:`~aerodaas.plugins.sensor.SensorDelivery`). The framework reads these declarations; it
never compares a sensor's type with these names.

Their readings are made by the drone's actor itself (the camera component, the vehicle's odometry, the mission's
stat-stream), not by :meth:`SensorPlugin.sample`: these classes are declarations, never instantiated.

Units: camera sizes in pixels, fps in frames/s, angles in degrees (``pitch_deg`` 90 = nadir), rates in Hz,
timeouts in seconds; the bounds are :mod:`aerodaas.model.bounds`' (docs/safety.md "Configuration bounds").
"""
from __future__ import annotations

from typing import Any, Callable, ClassVar

from pydantic import Field, model_validator

from aerodaas.model.bounds import MAX_CAMERA_FPS, MAX_CAMERA_PX, MAX_RATE_HZ
from aerodaas.plugins.sensor import SensorDelivery, SensorPlugin, SensorPropertiesBase

__all__ = ["CameraProperties", "OdometryProperties", "StatStreamProperties", "CameraSensor", "OdometrySensor",
           "StatStreamSensor", "CAMERA_SOURCES", "STREAM_PROPERTIES", "MAVLINK_SOURCE", "DISCOVERY_PROPERTIES"]

#: where a camera's frames come from: the simulated world, the robot's backend (its own video stream, e.g. the
#: Tello's), or a recorded MCAP camera channel; any other source is a video stream or file (aerodaas.video.source)
CAMERA_SOURCES = ("sim", "backend", "mcap")
#: camera properties that only a video stream source uses
STREAM_PROPERTIES = ("transport", "codec", "first_frame_timeout_s", "stall_timeout_s")
#: the source whose stream the vehicle announces over MAVLink (aerodaas.video.discovery), and its own properties
MAVLINK_SOURCE = "mavlink"
DISCOVERY_PROPERTIES = ("camera_component", "stream_id", "discovery_timeout_s")
_Text = Field(default=None, min_length=1, strict=True)


class CameraProperties(SensorPropertiesBase):
    """A camera's ``properties`` (see :class:`aerodaas.config.SensorConfig` for ``source``): ``width``/``height``
    pixels [1, 8192], ``hfov_deg`` (0, 180), ``fps`` (0, 240], ``pitch_deg`` (0, 90] (90 = nadir),
    ``jpeg_quality`` [1, 100]; a video stream's ``transport``/``codec`` and timeouts in seconds,
    ``first_frame_timeout_s`` (0, 600], ``stall_timeout_s`` (0, 60]; with ``source: "mavlink"`` (the stream the
    vehicle announces, docs/video.md) ``camera_component`` [1, 255] (MAVLink component id; default the first camera
    found), ``stream_id`` [1, 255] (default the lowest-numbered) and ``discovery_timeout_s`` (0, 120] (default 10)."""

    width: int = Field(default=640, ge=1, le=MAX_CAMERA_PX, strict=True, description="pixels")
    height: int = Field(default=480, ge=1, le=MAX_CAMERA_PX, strict=True, description="pixels")
    hfov_deg: float = Field(default=78.0, gt=0.0, lt=180.0, strict=True, description="horizontal field of view, deg")
    fps: float = Field(default=15.0, gt=0.0, le=MAX_CAMERA_FPS, strict=True, description="frames per second")
    pitch_deg: float = Field(default=90.0, gt=0.0, le=90.0, strict=True, description="degrees below the horizon")
    jpeg_quality: int = Field(default=80, ge=1, le=100, strict=True)
    source: str = Field(default="sim", min_length=1, strict=True)
    mcap: str | None = _Text
    topic: str | None = _Text
    transport: str | None = _Text
    codec: str | None = _Text
    first_frame_timeout_s: float | None = Field(default=None, gt=0.0, le=600.0, strict=True, description="seconds")
    stall_timeout_s: float | None = Field(default=None, gt=0.0, le=60.0, strict=True, description="seconds")
    camera_component: int | None = Field(default=None, ge=1, le=255, strict=True, description="MAVLink component id")
    stream_id: int | None = Field(default=None, ge=1, le=255, strict=True)
    discovery_timeout_s: float | None = Field(default=None, gt=0.0, le=120.0, strict=True, description="seconds")

    @model_validator(mode="after")
    def _check_source(self) -> "CameraProperties":
        src = self.source
        stream_props = [k for k in STREAM_PROPERTIES if getattr(self, k) is not None]
        discovery_props = [k for k in DISCOVERY_PROPERTIES if getattr(self, k) is not None]
        if discovery_props and src != MAVLINK_SOURCE:
            raise ValueError(f"properties.{discovery_props[0]} is only used with properties.source 'mavlink' (the "
                             f"stream the vehicle announces), but source is {src!r}")
        if src == MAVLINK_SOURCE:  # the URL comes from the vehicle once connected; checked by the video source then
            if self.codec is not None and self.codec not in ("h264", "h265"):
                raise ValueError(f"properties.codec must be one of ['h264', 'h265'], got {self.codec!r}")
            if self.transport is not None and self.transport not in ("tcp", "udp"):
                raise ValueError(f"properties.transport must be 'tcp' or 'udp', got {self.transport!r}")
        elif src not in CAMERA_SOURCES:  # a video stream or file: checked (scheme, host, port, codec) by its parser
            from aerodaas.video.source import parse_stream_source

            parse_stream_source(src, self.transport, self.codec)
        elif stream_props:
            raise ValueError(f"properties.{stream_props[0]} is only used with a video stream source (rtsp://, "
                             f"rtp://, udp://, an .sdp or video file, /dev/videoN), but source is {src!r}")
        if src == "mcap":
            if not self.mcap:
                raise ValueError(f"properties.mcap must name the MCAP recording to replay when properties.source "
                                 f"is 'mcap', got {self.mcap!r}")
            if self.topic is not None and not self.topic.startswith("/"):
                raise ValueError(f"properties.topic must be an MCAP topic starting with '/', got {self.topic!r}")
        else:
            for k in ("mcap", "topic"):
                if getattr(self, k) is not None:
                    raise ValueError(f"properties.{k} is only used with properties.source 'mcap', "
                                     f"but source is {src!r}")
        return self


def check_replay_recording(path: str, topic: str, where: str) -> None:
    """Before Ray starts: the camera replay's file ``path`` is an MCAP file (read with the ``mcap`` library: its
    summary section, or front to back when the file is unfinished) and ``topic`` a ``foxglove.CompressedImage``
    channel with messages in it, what :class:`aerodaas.backends.replay.McapCameraReplay` reads (it refused such a
    file only in the camera's actor, after Ray had started). ``where`` is the sensor's path
    (``robots.0.sensors.0``). Raises ValueError naming the property."""
    from mcap.reader import NonSeekingReader, make_reader

    schemas: dict[str, str] = {}  # topic -> schema name, of the channels with messages
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
            if summary is not None and summary.statistics is not None:
                counts = summary.statistics.channel_message_counts
                for cid, ch in summary.channels.items():
                    if counts.get(cid):
                        sc = summary.schemas.get(ch.schema_id)
                        schemas[ch.topic] = sc.name if sc is not None else ""
            else:  # an unfinished recording: its messages front to back, up to the first of the topic
                f.seek(0)
                for sc, ch, _ in NonSeekingReader(f).iter_messages():
                    schemas.setdefault(ch.topic, sc.name if sc is not None else "")
                    if ch.topic == topic:
                        break
    except Exception as e:  # noqa: BLE001 - whatever the reader cannot read is no recording to replay
        raise ValueError(f"{where}.properties.mcap: {path!r} is not a readable MCAP recording "
                         f"({type(e).__name__}: {str(e)[:200]})") from None
    if topic not in schemas:
        raise ValueError(f"{where}.properties.topic: {topic!r} is not a channel with messages in the recording "
                         f"{path!r}; its channels: {sorted(schemas)}")
    if schemas[topic] != "foxglove.CompressedImage":
        raise ValueError(f"{where}.properties.topic: {topic!r} in {path!r} carries {schemas[topic]!r}, not "
                         f"foxglove.CompressedImage (a camera's images)")


class OdometryProperties(SensorPropertiesBase):
    """The odometry sensor's ``properties``: ``rate_hz``, samples per second of vehicle time, (0, 1000]."""

    rate_hz: float = Field(default=10.0, gt=0.0, le=MAX_RATE_HZ, strict=True, description="Hz (vehicle time)")


class StatStreamProperties(SensorPropertiesBase):
    """The stat-stream has no properties."""


class CameraSensor(SensorPlugin):
    """``camera``: frames from the drone actor's camera component (``actors/camera.py``), rendered from the
    simulated world, the vehicle's own video (a backend with ``provides_camera``), a replayed MCAP channel or a
    video stream. Also allowed as an environment sensor (``env_sensors[]``, from ``sim`` or ``mcap``)."""

    name = "camera"
    Config = CameraProperties
    record_schema = "foxglove.CompressedImage"
    delivery = SensorDelivery.CAMERA
    component_kind = "camera"
    own_topic = False  # /<robot>/camera/<id>
    environment_sensor = True
    consumes: ClassVar[tuple] = ("vehicle_state", "world")

    @classmethod
    def validate_properties(cls, properties: dict[str, Any]) -> dict[str, Any]:
        """As :meth:`SensorPlugin.validate_properties`, without the unset optional properties (the camera reads
        ``"mcap" in properties`` as "replay a recording")."""
        return cls.Config.model_validate(properties).model_dump(mode="json", exclude_none=True)

    @classmethod
    def check_for_robot(cls, properties: dict[str, Any], robot: Any, where: str) -> None:
        """``source: backend`` needs a backend that declares its own camera stream (``provides_camera``);
        ``source: mavlink`` one that discovers the vehicle's announced streams (``discovers_video_streams``)."""
        if properties.get("source") == MAVLINK_SOURCE:
            if not _backend_declares(robot.backend, "discovers_video_streams"):
                raise ValueError(f"{where}.properties.source: 'mavlink' asks the vehicle for its camera's stream "
                                 f"over MAVLink, so the robot's backend must be 'mavlink', but backend is "
                                 f"{robot.backend!r}")
            return
        if properties.get("source") == "backend" and not _backend_declares(robot.backend, "provides_camera"):
            raise ValueError(f"{where}.properties.source: 'backend' needs a backend with its own camera stream "
                             f"(provides_camera: {_camera_backends()}), but backend is {robot.backend!r}")

    @classmethod
    def check_for_environment(cls, properties: dict[str, Any], where: str) -> None:
        """An environment camera is rendered (``sim``) or replayed (``mcap``, with its ``topic``)."""
        src = properties.get("source")
        if src not in ("sim", "mcap"):
            raise ValueError(f"{where}.properties.source: {src!r} is for a robot's camera; an "
                             f"environment camera is 'sim' or 'mcap'")
        if src == "mcap" and "topic" not in properties:
            raise ValueError(f"{where}.properties.topic: an environment camera replayed from an MCAP "
                             f"recording needs the topic to read")

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """An ``mcap`` replay's recording, a video file or an SDP file: resolved to absolute paths."""
        src = properties.get("source")
        if src == "mcap":
            properties["mcap"] = str(resolve(properties["mcap"], f"{where}.properties.mcap"))
            properties.setdefault("topic", f"/{robot_id}/camera/{sensor_id}")
            check_replay_recording(properties["mcap"], properties["topic"], where)
        elif src not in (None, MAVLINK_SOURCE, *CAMERA_SOURCES):
            from aerodaas.video.source import parse_stream_source

            spec = parse_stream_source(src, properties.get("transport"), properties.get("codec"))
            if spec.kind in ("file", "sdp"):  # a file the camera reads: resolved like every other file, now
                properties["source"] = str(resolve(spec.url, f"{where}.properties.source"))

    @classmethod
    def reads_wall_clock(cls, properties: dict[str, Any]) -> bool:
        """A video stream (not ``sim``, ``backend`` or ``mcap``) runs on the wall clock."""
        return properties.get("source", "sim") not in CAMERA_SOURCES


class OdometrySensor(SensorPlugin):
    """``odometry``: the vehicle's position samples (an :class:`aerodaas.model.types.Odometry`: ENU metres from home,
    m/s, degrees, geodetic position), published at ``rate_hz`` of vehicle time."""

    name = "odometry"
    Config = OdometryProperties
    record_schema = "aerodaas.Odometry"
    delivery = SensorDelivery.VEHICLE_STATE
    component_kind = "odometry"
    own_topic = False  # /<robot>/odometry


class StatStreamSensor(SensorPlugin):
    """``stat_stream``: the drone's mission status (state, battery, current waypoint). Every robot has one: added as
    ``stat`` when the configuration lists none."""

    name = "stat_stream"
    Config = StatStreamProperties
    record_schema = "aerodaas.MissionState"
    delivery = SensorDelivery.MISSION_STATUS
    component_kind = "stat_stream"
    own_topic = False  # /mission/state
    default_id = "stat"


def _backend_declares(backend: str, flag: str) -> bool:
    """Whether the registered backend ``backend`` declares the class attribute ``flag`` true."""
    from aerodaas.plugins import registry

    try:
        return bool(getattr(registry.get("backend", backend), flag, False))
    except registry.UnknownPlugin:
        return False


def _camera_backends() -> list[str]:
    """The registered backends that declare a camera stream (for the error message)."""
    from aerodaas.plugins import registry

    out = []
    for e in registry.entries("backend"):
        try:
            if getattr(e.load(), "provides_camera", False):
                out.append(e.name)
        except Exception:  # noqa: BLE001 - a backend that does not import offers no camera
            continue
    return out
