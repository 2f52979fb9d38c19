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
* how it produces readings — :meth:`SensorPlugin.sample` is called by the drone's actor at ``rate_hz`` (vehicle
  time) with the vehicle state (an :class:`aerodaas.model.types.Odometry`: ENU metres from home, m/s, degrees,
  geodetic position) and the vehicle time in seconds.

Each reading is recorded on ``/<robot>/<sensor id>`` and published on the sensor's stream (``get_data_stream()``):
an analytics that subscribes receives ``data`` = the reading as a JSON-ready dict, ``meta`` = None. The plan
(``aerodaas plan``), the recorder and the summary take all of this from the declaration; nothing in the framework
names a plug-in sensor type.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["SensorPlugin", "SensorPluginConfig"]


class SensorPluginConfig(BaseModel):
    """Base of a sensor plug-in's ``properties``: ``rate_hz`` (readings per second of vehicle time, (0, 1000]);
    unknown properties are refused."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    rate_hz: float = Field(default=1.0, gt=0, le=1000.0, description="readings per second (vehicle time)")


class SensorPlugin(ABC):
    """Base class of a sensor type plug-in (see the module docstring). One instance per configured sensor, built
    in the drone's actor: ``robot_id``, ``sensor_id`` and ``config`` (an instance of ``Config``). A subclass must
    define :meth:`sample` (an abstract method: building one without it raises TypeError)."""

    plugin_kind: ClassVar[str] = "sensor"
    #: the sensor ``type`` in environment.json
    name: ClassVar[str] = ""
    Config: ClassVar[type[SensorPluginConfig]] = SensorPluginConfig
    #: one reading (what :meth:`sample` returns)
    Message: ClassVar[type[BaseModel] | None] = None
    #: a schema name the recorder already knows, to record readings with instead of ``Message``'s JSON Schema
    record_schema: ClassVar[str | None] = None
    consumes: ClassVar[tuple] = ("vehicle_state",)

    def __init__(self, robot_id: str, sensor_id: str, config: SensorPluginConfig) -> None:
        self.robot_id, self.sensor_id, self.config = robot_id, sensor_id, config

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
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
