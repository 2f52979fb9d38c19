"""The built-in sensor types — ``camera``, ``odometry`` and ``stat_stream`` — declared through the same contract as
a sensor plug-in (:class:`aerodaas.plugins.sensor.SensorPlugin`): a name, a pydantic ``Config`` of the sensor's
``properties`` (strict: a string or a boolean is not a number; every size, rate and duration bounded), and where its
the contract that says how their data is produced (:class:`~aerodaas.plugins.sensor.FrameSensor`,
:class:`~aerodaas.plugins.sensor.VehicleStateSensor`, :class:`~aerodaas.plugins.sensor.MissionStatusSensor`). The framework reads these declarations; it
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
from aerodaas.plugins import registry
from aerodaas.plugins.frames import frame_source_class
from aerodaas.plugins.sensor import (FrameSensor, MissionStatusSensor, SensorPropertiesBase,
                                    VehicleStateSensor)

__all__ = ["CameraProperties", "OdometryProperties", "StatStreamProperties", "CameraSensor", "OdometrySensor",
           "StatStreamSensor", "STREAM_PROPERTIES", "MAVLINK_SOURCE", "DISCOVERY_PROPERTIES"]

#: camera properties that only a video stream source uses
STREAM_PROPERTIES = ("transport", "codec", "first_frame_timeout_s", "stall_timeout_s")
#: the source whose stream the vehicle announces over MAVLink (aerodaas.video.discovery), and its own properties
MAVLINK_SOURCE = "mavlink"
DISCOVERY_PROPERTIES = ("camera_component", "stream_id", "discovery_timeout_s")
#: the built-in properties a frame source may use beyond the common ones, and whom they are for (error messages)
_USED_WITH = {**{k: "properties.source 'mavlink' (the stream the vehicle announces)" for k in DISCOVERY_PROPERTIES},
              **{k: "a video stream source (rtsp://, rtp://, udp://, an .sdp or video file, /dev/videoN)"
                 for k in STREAM_PROPERTIES},
              "mcap": "properties.source 'mcap'", "topic": "properties.source 'mcap'"}
_Text = Field(default=None, min_length=1, strict=True)


class CameraProperties(SensorPropertiesBase):
    """A camera's ``properties`` (see :class:`aerodaas.config.SensorConfig` for ``source``): ``width``/``height``
    pixels [1, 8192], ``hfov_deg`` (0, 180), ``fps`` (0, 240], ``pitch_deg`` (0, 90] (90 = nadir),
    ``jpeg_quality`` [1, 100], ``record_fps`` [0, ``fps``] (the frames per second of vehicle time the recording and
    the live view take, default ``fps``; 0: none; a camera nothing else takes renders only those); a video stream's ``transport``/``codec`` and timeouts in seconds,
    ``first_frame_timeout_s`` (0, 600], ``stall_timeout_s`` (0, 60]; with ``source: "mavlink"`` (the stream the
    vehicle announces, docs/video.md) ``camera_component`` [1, 255] (MAVLink component id; default the first camera
    found), ``stream_id`` [1, 255] (default the lowest-numbered) and ``discovery_timeout_s`` (0, 120] (default 10)."""

    width: int = Field(default=640, ge=1, le=MAX_CAMERA_PX, strict=True, description="pixels")
    height: int = Field(default=480, ge=1, le=MAX_CAMERA_PX, strict=True, description="pixels")
    hfov_deg: float = Field(default=78.0, gt=0.0, lt=180.0, strict=True, description="horizontal field of view, deg")
    fps: float = Field(default=15.0, gt=0.0, le=MAX_CAMERA_FPS, strict=True, description="frames per second")
    pitch_deg: float = Field(default=90.0, gt=0.0, le=90.0, strict=True, description="degrees below the horizon")
    jpeg_quality: int = Field(default=80, ge=1, le=100, strict=True)
    record_fps: float | None = Field(default=None, ge=0.0, le=MAX_CAMERA_FPS, strict=True,
                                     description="frames per second the recording and the live view take, at most fps "
                                     "(0: none); unset: fps")
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
        """``record_fps`` against ``fps``, then the properties against the frame source ``source`` selects (:func:`aerodaas.plugins.frames.
        frame_source_class`): a built-in property set that the source does not use is refused, naming it; then the
        source's own checks (for a source with properties of its own, :meth:`CameraSensor.validate_properties`
        runs them with those)."""
        if self.record_fps is not None and self.record_fps > self.fps:
            raise ValueError(f"properties.record_fps must be at most properties.fps ({self.fps:g}), "
                             f"got {self.record_fps!r}")
        src = self.source
        cls = frame_source_class(src)
        for k in _USED_WITH:
            if getattr(self, k) is not None and k not in cls.camera_properties:
                raise ValueError(f"properties.{k} is only used with {_USED_WITH[k]}, but source is {src!r}")
        if cls.Config is None:
            cls.check_properties(self.model_dump(exclude_none=True), "properties")
        return self


def check_replay_recording(path: str, topic: str, where: str) -> None:
    """Before Ray starts: the camera replay's file ``path`` is an MCAP file (read with the ``mcap`` library: its
    summary section, or front to back when the file is unfinished) and ``topic`` a ``foxglove.CompressedImage``
    channel with messages in it, what :class:`aerodaas.backends.replay.McapCameraReplay` reads (it refused such a
    file only in the camera's actor, after Ray had started). ``where`` is the sensor's path
    (``robots.0.sensors.0``). Raises ValueError naming the property."""
    from mcap.reader import NonSeekingReader, make_reader  # lazy: heavy mcap

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


class CameraSensor(FrameSensor):
    """``camera``: frames from the drone actor's camera component (``actors/sensors/camera.py``), produced by the frame
    source ``properties.source`` selects (:mod:`aerodaas.plugins.frames`; the built-ins in
    ``actors/sensors/frame_sources.py``: rendered, the vehicle's own video, a replayed MCAP channel, a video stream, the
    stream the vehicle announces). Also allowed as an environment sensor (``env_sensors[]``) with a source that
    needs no vehicle (``environment_ok``: ``sim``, ``mcap``)."""

    name = "camera"
    Config = CameraProperties
    environment_sensor = True
    consumes: ClassVar[tuple] = ("vehicle_state", "world")

    @classmethod
    def validate_properties(cls, properties: dict[str, Any]) -> dict[str, Any]:
        """As :meth:`SensorPlugin.validate_properties`, without the unset optional properties. The properties its
        frame source declares in its own ``Config`` are validated by that model (completed with its defaults), the
        others by :class:`CameraProperties` (an unknown one refused), then the source's ``check_properties`` runs
        on them all. Raises pydantic's ValidationError, or ValueError from the source's checks."""
        source = properties.get("source", "sim")
        src_cls = cls.frame_source({"source": source}) if isinstance(source, str) else None
        own = set(src_cls.Config.model_fields) if src_cls is not None and src_cls.Config is not None else set()
        out = cls.Config.model_validate({k: v for k, v in properties.items() if k not in own}).model_dump(
            mode="json", exclude_none=True)
        if own:
            out.update(src_cls.Config.model_validate({k: v for k, v in properties.items() if k in own})
                       .model_dump(mode="json"))
            src_cls.check_properties(out, "properties")
        return out

    @classmethod
    def check_for_robot(cls, properties: dict[str, Any], robot: Any, where: str) -> None:
        """The frame source's own checks with the robot (:meth:`aerodaas.plugins.frames.FrameSource.check_for_robot`)."""
        cls.frame_source(properties).check_for_robot(properties, robot, where)

    @classmethod
    def check_for_environment(cls, properties: dict[str, Any], where: str) -> None:
        """An environment camera's source needs no vehicle (``environment_ok``); a replay needs its ``topic``."""
        src = properties.get("source")
        if not cls.frame_source(properties).environment_ok:
            raise ValueError(f"{where}.properties.source: {src!r} is for a robot's camera; an environment camera's "
                             f"source needs no vehicle: {_environment_sources()}")
        if src == "mcap" and "topic" not in properties:
            raise ValueError(f"{where}.properties.topic: an environment camera replayed from an MCAP "
                             f"recording needs the topic to read")

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """The files the frame source reads, resolved to absolute paths (its ``resolve_files``)."""
        cls.frame_source(properties).resolve_files(properties, resolve, where, robot_id, sensor_id)


class OdometrySensor(VehicleStateSensor):
    """``odometry``: the vehicle's position samples (an :class:`aerodaas.model.types.Odometry`: ENU metres from home,
    m/s, degrees, geodetic position), published at ``rate_hz`` of vehicle time."""

    name = "odometry"
    Config = OdometryProperties
    record_schema = "aerodaas.Odometry"


class StatStreamSensor(MissionStatusSensor):
    """``stat_stream``: the drone's mission status (state, battery, current waypoint). Every robot has one: added as
    ``stat`` when the configuration lists none."""

    name = "stat_stream"
    Config = StatStreamProperties
    record_schema = "aerodaas.MissionState"
    default_id = "stat"


def _environment_sources() -> list[str]:
    """The registered frame sources an environment camera may use (for the error message)."""
    return registry.names_with_flag("frame_source", "environment_ok")
