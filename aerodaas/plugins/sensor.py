"""The sensor extension point: a new sensor type is one class, a subclass of :class:`SensorPlugin`.

The class declares

* ``name`` — the sensor ``type`` written in ``environment.json`` (``robots[].sensors[].type``);
* ``Config`` — a pydantic model of the sensor's ``properties`` (subclass :class:`SensorPluginConfig`, which has
  ``rate_hz``); the properties are validated against it when the environment is loaded, before Ray starts,
  errors naming ``robots.<i>.sensors.<j>.properties.<field>``;
* ``Message`` — a pydantic model of one reading: :meth:`SensorPlugin.sample` returns one (or None). The recording
  names it by :meth:`SensorPlugin.schema_name` with the JSON Schema pydantic derives from it
  (``model_json_schema(mode="serialization")``, JSON Schema draft 2020-12), unless ``record_schema`` names a schema
  the recorder already knows (:mod:`aerodaas.recording.schemas`);
* how its data is produced — by the class it subclasses: :class:`SensorPlugin` itself, sampled readings:
  :meth:`SensorPlugin.sample` is called by the drone's actor at ``rate_hz`` (vehicle
  time) with the vehicle state (an :class:`aerodaas.model.types.Odometry`: ENU metres from home, m/s, degrees,
  geodetic position) and the vehicle time in seconds.

Each reading is recorded on ``/<robot>/<sensor id>`` and published on the sensor's stream (``get_data_stream()``):
an analytics that subscribes receives ``data`` = the reading as a JSON-ready dict, ``meta`` = None. The plan
(``aerodaas plan``), the recorder and the summary take all of this from the declaration; nothing in the framework
names a plug-in sensor type.

The other ways a sensor's data is produced are contracts of their own, subclasses of :class:`ActorProducedSensor`
(the drone's actor makes the data, not :meth:`SensorPlugin.sample`): :class:`FrameSensor` (frames of a frame
source, :mod:`aerodaas.plugins.frames`, chosen by the sensor's properties), :class:`VehicleStateSensor` (the
vehicle's odometry) and :class:`MissionStatusSensor` (the drone's mission status). Each contract names the
component of the drone's actor that delivers its data by its :attr:`SensorPlugin.delivery` (a :class:`Delivery`);
the runtime wires a sensor by asking that delivery (is it frames? is its component built without a subscriber?),
never by testing the sensor's class or its type name.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from enum import Enum
from typing import Any, Callable, ClassVar

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["Delivery", "SensorPlugin", "SensorPluginConfig", "SensorPropertiesBase", "ActorProducedSensor", "FrameSensor",
           "VehicleStateSensor", "MissionStatusSensor"]


class Delivery(Enum):
    """The component of the drone's actor that delivers a sensor type's data (:attr:`SensorPlugin.delivery`), and
    what the runtime needs to know of it. The value names it in ``aerodaas plan`` (text and ``--json``)."""

    #: readings of :meth:`SensorPlugin.sample`, called at ``rate_hz`` (vehicle time) by the sensor's own component
    SAMPLED = "sampled"
    #: frames of the frame source the sensor's properties select (:meth:`FrameSensor.frame_source`), from a camera
    CAMERA = "camera"
    #: the vehicle's odometry, published by the drone
    VEHICLE_STATE = "vehicle_state"
    #: the drone's mission status (stat stream), published by the drone
    MISSION_STATUS = "mission_status"

    @property
    def frames(self) -> bool:
        """Whether the data are frames of a frame source (the sensor class has :meth:`FrameSensor.frame_source`)."""
        return self is Delivery.CAMERA

    @property
    def sampled(self) -> bool:
        """Whether the data are readings of :meth:`SensorPlugin.sample` (not produced by the drone's actor itself)."""
        return self is Delivery.SAMPLED

    def has_component(self, subscribed: bool, recorded: bool) -> bool:
        """Whether a run builds this sensor's component in the drone's actor, given whether anything subscribes to
        the sensor's stream and whether the run records: sampled readings always (they are recorded on the
        sensor's own topic), frames when subscribed or recorded, the vehicle state and the mission status only when
        subscribed (the drone records those itself)."""
        if self is Delivery.SAMPLED:
            return True
        return subscribed or (recorded and self is Delivery.CAMERA)


class SensorPropertiesBase(BaseModel):
    """Base of every sensor type's ``properties`` model: unknown properties are refused, numbers are finite."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class SensorPluginConfig(SensorPropertiesBase):
    """Base of a sampled sensor's ``properties``: ``rate_hz`` (readings per second of vehicle time, (0, 1000];
    a number, not a string or a boolean); unknown properties are refused."""

    rate_hz: float = Field(default=1.0, gt=0, le=1000.0, strict=True, description="readings per second (vehicle time)")


class SensorPlugin(ABC):
    """Base class of a sensor type plug-in (see the module docstring). One instance per configured sensor, built
    in the drone's actor: ``robot_id``, ``sensor_id`` and ``config`` (an instance of ``Config``). A subclass must
    define :meth:`sample` (an abstract method: building one without it raises TypeError)."""

    plugin_kind: ClassVar[str] = "sensor"
    #: the sensor ``type`` in environment.json
    name: ClassVar[str] = ""
    Config: ClassVar[type[SensorPropertiesBase]] = SensorPluginConfig
    #: the token an analytics' ``consumes`` names what the drone's actor delivers for this type by ("frame",
    #: "odometry", "stat"); None for a sampled sensor, whose readings are its ``Message``
    delivered_token: ClassVar[str | None] = None
    #: the component of the drone's actor that delivers the data (set by the contract a class subclasses)
    delivery: ClassVar[Delivery] = Delivery.SAMPLED
    #: the kind of the sensor's component in the plan (:class:`aerodaas.protocol.ids.ComponentId`)
    component_kind: ClassVar[str] = "sensor"
    #: whether an environment-level sensor (``env_sensors[]``) may be of this type (not a robot's)
    environment_sensor: ClassVar[bool] = False
    #: whether its readings are recorded on ``/<robot>/<sensor id>`` (the id must then be usable as a topic name)
    own_topic: ClassVar[bool] = True
    #: a sensor id to add this type under to every robot that has none of it (None: only when configured)
    default_id: ClassVar[str | None] = None
    #: one reading (what :meth:`sample` returns)
    Message: ClassVar[type[BaseModel] | None] = None
    #: a schema name the recorder already knows, to record readings with instead of ``Message``'s JSON Schema
    record_schema: ClassVar[str | None] = None
    consumes: ClassVar[tuple] = ("vehicle_state",)

    def __init__(self, robot_id: str, sensor_id: str, config: SensorPluginConfig) -> None:
        self.robot_id, self.sensor_id, self.config = robot_id, sensor_id, config

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if not isinstance(cls.delivery, Delivery):
            raise TypeError(f"sensor class {cls.__module__}.{cls.__qualname__}: delivery must be a member of "
                            f"aerodaas.plugins.sensor.Delivery, got {cls.delivery!r:.80}")
        if cls.Message is not None and "produces" not in cls.__dict__:
            cls.produces = (cls.Message,)

    produces: ClassVar[tuple] = ()

    # -- declaration helpers (used by the config, the plan and the recorder)
    @classmethod
    def validate_properties(cls, properties: dict[str, Any]) -> dict[str, Any]:
        """``properties`` checked against ``Config`` and completed with its defaults (a JSON-ready dict). Raises
        pydantic's ValidationError."""
        return cls.Config.model_validate(properties).model_dump(mode="json")

    @classmethod
    def check_for_robot(cls, properties: dict[str, Any], robot: Any, where: str) -> None:
        """Checks of validated ``properties`` that need the robot (an :class:`aerodaas.config.RobotConfig`: its
        backend, say), before Ray starts. ``where`` is the sensor's path (``sensors.<j>``). Raises ValueError naming
        ``where`` and the property. Nothing here."""

    @classmethod
    def check_for_environment(cls, properties: dict[str, Any], where: str) -> None:
        """Checks of an environment-level sensor's validated ``properties`` (``env_sensors.<j>``). Raises
        ValueError naming ``where`` and the property. Nothing here."""

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """Resolve the files ``properties`` name, in place, when the environment file is loaded (``resolve(path,
        field)`` returns the absolute path or raises ConfigError naming ``field``). Nothing here."""

    @classmethod
    def reads_wall_clock(cls, properties: dict[str, Any]) -> bool:
        """Whether this sensor's readings run on the wall clock (a live video stream): the run then needs speedup 1
        and no lock-step. False here."""
        return False

    @classmethod
    def schema_name(cls) -> str:
        """The schema name readings are recorded with: ``record_schema``, else ``<top package>.<Message name>``."""
        if cls.record_schema:
            return cls.record_schema
        top = cls.__module__.split(".")[0]
        msg = cls.Message.__name__ if cls.Message is not None else cls.__name__
        return f"{top}.{msg}"

    @classmethod
    def json_schema(cls) -> dict[str, Any] | None:
        """The JSON Schema of one reading (from ``Message``), None when ``record_schema`` names a known one."""
        if cls.record_schema or cls.Message is None:
            return None
        js = cls.Message.model_json_schema(mode="serialization")
        js["title"] = cls.schema_name()
        js.setdefault("type", "object")
        js["$schema"] = "https://json-schema.org/draft/2020-12/schema"
        return js

    @property
    def rate_hz(self) -> float:
        return float(self.config.rate_hz)

    # -- run time, in the drone's actor
    def setup(self) -> None:
        """Called once in the actor before the first reading (open a device, seed a generator)."""

    @abstractmethod
    def sample(self, state: Any, t: float) -> BaseModel | dict | None:
        """One reading at vehicle time ``t`` (seconds) given the vehicle ``state`` (an Odometry: ENU metres from
        home, m/s, degrees, ``geodetic`` lat/lon/alt). Return a ``Message`` (or a dict of its fields), or None for
        no reading now. An exception is recorded as a ``sensor_error`` event and counted; the flight goes on."""


class ActorProducedSensor(SensorPlugin):
    """Base of the sensor types whose data the drone's actor produces itself (frames, odometry, mission status),
    not :meth:`sample`: declarations, never instantiated by the framework. A subclass is one of the contracts
    below (or names a :class:`Delivery` other than ``SAMPLED``); one without raises TypeError when defined."""

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if cls.delivery.sampled:
            raise TypeError(f"sensor class {cls.__module__}.{cls.__qualname__}: the drone's actor produces its data, "
                            f"so its delivery must name the component that does (a Delivery other than SAMPLED): "
                            f"subclass FrameSensor, VehicleStateSensor or MissionStatusSensor")

    def sample(self, state: Any, t: float) -> BaseModel | dict | None:
        """Not used: raises TypeError (the drone's actor produces this sensor's data)."""
        raise TypeError(f"sensor type {self.name!r} is produced by the drone's actor, not sampled")


class FrameSensor(ActorProducedSensor):
    """A camera-like sensor: frames ((H, W, 3) uint8 BGR, capture times in seconds on the run's vehicle clock)
    from the frame source its properties select (:meth:`frame_source`), published and recorded by the drone
    actor's camera component on ``/<robot>/camera/<id>`` (``foxglove.CompressedImage``)."""

    delivery = Delivery.CAMERA
    delivered_token = "frame"
    component_kind = "camera"
    own_topic = False  # /<robot>/camera/<id>
    record_schema = "foxglove.CompressedImage"

    @classmethod
    def frame_source(cls, properties: dict[str, Any]) -> type:
        """The :class:`aerodaas.plugins.frames.FrameSource` subclass that produces this sensor's frames, from its
        validated ``properties`` (``source``, default ``sim``; see :func:`aerodaas.plugins.frames.frame_source_class`)."""
        from aerodaas.plugins.frames import frame_source_class  # lazy: heavy numpy

        return frame_source_class(properties.get("source", "sim"))

    @classmethod
    def reads_wall_clock(cls, properties: dict[str, Any]) -> bool:
        """Whether its frame source's frames arrive on the wall clock (a live video stream)."""
        return bool(cls.frame_source(properties).wall_clock)


class VehicleStateSensor(ActorProducedSensor):
    """The vehicle's odometry (an :class:`aerodaas.model.types.Odometry`: ENU metres from home, m/s, degrees,
    geodetic position), published by the drone at the sensor's ``rate_hz`` of vehicle time."""

    delivery = Delivery.VEHICLE_STATE
    delivered_token = "odometry"
    component_kind = "odometry"
    own_topic = False  # /<robot>/odometry


class MissionStatusSensor(ActorProducedSensor):
    """The drone's stat-stream (mission state, battery, current waypoint)."""

    delivery = Delivery.MISSION_STATUS
    delivered_token = "stat"
    component_kind = "stat_stream"
    own_topic = False  # /mission/state
