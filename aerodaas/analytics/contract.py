"""The output contract of an analytics: what it declares it takes and gives, checked and recorded from the
declaration (docs/extending.md "An analytics' output contract").

An analytics may declare

* ``Output`` — a pydantic model of its (main) output message, as a sensor plug-in declares ``Message``:
  :meth:`~aerodaas.analytics.base.Analytics.process` returns one (or a dict of its fields, or None). Each is
  recorded on ``/<robot>/<analytics>`` with the schema :func:`schema_name` names and the JSON Schema pydantic derives
  from the model (:func:`json_schema`), and published downstream as a JSON-ready dict. Without ``Output`` the
  output stays free-form (``aerodaas.AnalyticsOutput``, as before).
* ``named_outputs`` — ``{output name: pydantic model}``: further outputs, each its own stream
  (:meth:`~aerodaas.analytics.base.Analytics.output_stream`) and its own channel ``/<robot>/<analytics>/<output>``;
  the analytics sends to one with :meth:`~aerodaas.analytics.base.Analytics.emit`.
* ``consumes`` — the stream types it accepts (:func:`stream_types`); checked against every stream that feeds it
  when the application is loaded (:func:`check_consumes`), before Ray starts.

And while it processes an item it may record an event with
:meth:`~aerodaas.analytics.base.Analytics.emit_event`: what it emits is gathered per item in an :class:`Emissions`
(:func:`collecting`) and recorded by the runtime with that item's robot and time.
"""
from __future__ import annotations

import json
import re
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Iterator

from pydantic import BaseModel

from aerodaas.model.data import AeroStreamData
from aerodaas.plugins import registry

__all__ = ["AnalyticsEvent", "NamedOutput", "Emissions", "collecting", "current_emissions", "NamedOutputStream",
           "ContractError", "RESERVED_OUTPUT_NAMES", "RESERVED_EVENT_FIELDS", "schema_name", "json_schema",
           "output_schemas", "stream_types", "check_declaration", "check_consumes", "event_record"]

#: sub-topics an analytics already records under (``/<robot>/<analytics>/<sub>``): not usable as output names
RESERVED_OUTPUT_NAMES = ("detections", "navigation", "tasks", "tracks")
#: keys every recorded event has (``aerodaas.MissionEvent``): an event's own fields may not use them
RESERVED_EVENT_FIELDS = ("robot", "t", "event", "analytics")
#: an output or event name: ASCII letters, digits and ``_``, a letter first (part of a topic and of a JSON key)
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,63}$")
#: the built-in messages' stream types, and the classes that name the same type in a ``consumes`` declaration
_BUILTIN_TYPES = {"Odometry": "odometry", "Detection": "detections", "AeroNavigation": "navigation"}


class ContractError(ValueError):
    """An analytics' declaration (``Output``, ``named_outputs``, ``consumes``) does not hold: raised while the
    application is loaded, before Ray starts (``aerodaas run`` exits 2), naming the analytics and the field."""


@dataclass(frozen=True)
class AnalyticsEvent:
    """An event an analytics emitted: ``kind`` (the recorded ``event``) and its JSON-ready ``fields``."""

    kind: str
    fields: dict[str, Any]


@dataclass(frozen=True)
class NamedOutput:
    """A message for the analytics' named output ``output`` (an instance of its declared model)."""

    output: str
    message: BaseModel


@dataclass
class Emissions:
    """What an analytics emitted while processing: ``events`` and ``outputs`` (named), each with the index of the
    item of the batch it belongs to (``item``: set by the default ``process_batch`` before each item; 0 for a
    single item)."""

    events: list[tuple[int, AnalyticsEvent]] = field(default_factory=list)
    outputs: list[tuple[int, NamedOutput]] = field(default_factory=list)
    item: int = 0

    def take(self) -> "Emissions":
        """Everything gathered so far, and forget it (a fresh :class:`Emissions` holds it)."""
        out = Emissions(self.events, self.outputs)
        self.events, self.outputs = [], []
        return out


class EmissionCollector:
    """Where one analytics object's ``emit`` / ``emit_event`` go while the runtime processes an item: per thread,
    the :class:`Emissions` of the innermost :func:`collecting` block (a ``threading.local`` of its own, so an
    object that several threads run at once keeps their items apart). Each analytics object owns one
    (:func:`collector_of`), no process-wide table."""

    def __init__(self) -> None:
        self._local = threading.local()

    def __reduce__(self) -> tuple:
        """A copy (``copy.deepcopy``, pickling the analytics to its actor) is a fresh collector: blocks in progress
        belong to the threads of this process (a ``threading.local`` cannot be pickled)."""
        return (EmissionCollector, ())

    @contextmanager
    def collecting(self) -> Iterator[Emissions]:
        """Gather what is emitted in this thread while the block runs; nested blocks each gather their own."""
        prev = getattr(self._local, "emissions", None)
        self._local.emissions = em = Emissions()
        try:
            yield em
        finally:
            self._local.emissions = prev

    def current(self) -> Emissions | None:
        """The :class:`Emissions` of the innermost block of this thread, None outside one."""
        return getattr(self._local, "emissions", None)


def collector_of(analytics: Any) -> EmissionCollector:
    """The :class:`EmissionCollector` of the analytics object ``analytics``, made on first use and kept in the
    object's own ``__dict__``, as :class:`~aerodaas.analytics.base.Analytics` keeps its other per-object state."""
    return analytics.__dict__.setdefault("_emission_collector", EmissionCollector())


@contextmanager
def collecting(analytics: Any) -> Iterator[Emissions]:
    """Gather what ``analytics`` emits in this thread while the block runs (the runtime wraps each ``process`` /
    ``process_batch`` call in it); nested blocks each gather their own."""
    with collector_of(analytics).collecting() as em:
        yield em


def current_emissions(analytics: Any) -> Emissions | None:
    """The :class:`Emissions` of the innermost :func:`collecting` block of ``analytics`` in this thread, None
    outside one."""
    return collector_of(analytics).current()


class NamedOutputStream(AeroStreamData):
    """The stream of named output ``output`` of analytics ``source`` (what ``source.output_stream(output)``
    returns): another analytics subscribes to it with ``analyse(...)``; its items are dicts of the output's model."""

    def __init__(self, source: Any, output: str, buffer: int = 1) -> None:
        super().__init__(source, buffer)
        self.output = output

    def __repr__(self) -> str:
        return f"NamedOutputStream(source={getattr(self.source, 'name', self.source)!r}, output={self.output!r})"


def schema_name(model: type[BaseModel]) -> str:
    """The schema name a message model is recorded with: ``<top package>.<class name>`` (as a sensor plug-in's)."""
    return f"{model.__module__.split('.')[0]}.{model.__name__}"


def json_schema(model: type[BaseModel]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``model``'s messages: pydantic's ``model_json_schema(mode="serialization")``
    titled with :func:`schema_name`."""
    js = model.model_json_schema(mode="serialization")
    js["title"] = schema_name(model)
    js.setdefault("type", "object")
    js["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return js


def output_schemas(analytics: Any) -> dict[str, dict[str, Any]]:
    """Schema name -> JSON Schema of every message model ``analytics`` declares (``Output`` and ``named_outputs``):
    what the recorder must know before the first message."""
    models = [getattr(analytics, "Output", None), *dict(getattr(analytics, "named_outputs", None) or {}).values()]
    return {schema_name(m): json_schema(m) for m in models if isinstance(m, type) and issubclass(m, BaseModel)}


def _is_model(x: Any) -> bool:
    return isinstance(x, type) and issubclass(x, BaseModel)


def check_declaration(analytics: Any) -> None:
    """Check what ``analytics`` declares: ``Output`` None or a pydantic model class; ``named_outputs`` a dict of
    output names (:data:`_NAME` grammar, not one of :data:`RESERVED_OUTPUT_NAMES`) to pydantic model classes;
    ``consumes`` a tuple of stream types (str or class). Raises :class:`ContractError` naming the analytics and
    the field."""
    who = f"analytics {analytics.name!r} ({type(analytics).__name__})"
    out = getattr(analytics, "Output", None)
    if out is not None and not _is_model(out):
        raise ContractError(f"{who}: Output must be a pydantic BaseModel subclass (the message it returns), got "
                            f"{out!r}")
    named = getattr(analytics, "named_outputs", None) or {}
    if not isinstance(named, dict):
        raise ContractError(f"{who}: named_outputs must be a dict {{output name: pydantic model}}, got {named!r}")
    for k, m in named.items():
        if not isinstance(k, str) or not _NAME.match(k) or k in RESERVED_OUTPUT_NAMES:
            raise ContractError(f"{who}: named_outputs key {k!r}: an output name is ASCII letters, digits and _, "
                                f"a letter first, and not one of {list(RESERVED_OUTPUT_NAMES)}")
        if not _is_model(m):
            raise ContractError(f"{who}: named_outputs[{k!r}] must be a pydantic BaseModel subclass, got {m!r}")
    consumes = getattr(analytics, "consumes", ())
    if not isinstance(consumes, (tuple, list)) or not all(isinstance(c, (str, type)) for c in consumes):
        raise ContractError(f"{who}: consumes must be a tuple of stream types (str or message class), got "
                            f"{consumes!r}")


def _token(t: Any) -> str:
    """A stream type as one comparable name: a string as it is; a class by its built-in stream type
    (Odometry -> ``odometry``, Detection -> ``detections``, AeroNavigation -> ``navigation``) or its schema name."""
    if isinstance(t, str):
        return t
    if getattr(t, "__module__", "").startswith("aerodaas.") and t.__name__ in _BUILTIN_TYPES:
        return _BUILTIN_TYPES[t.__name__]
    return schema_name(t) if _is_model(t) else f"{t.__module__}.{t.__qualname__}"


def stream_types(stream: AeroStreamData) -> tuple[str, ...]:
    """The types a stream carries, each as :func:`_token` names it; empty when the stream says nothing (then no
    ``consumes`` check applies to it).

    * a sensor's stream: what the drone actor delivers by the sensor class's ``delivery`` (``frame`` for camera
      frames, ``odometry`` for the vehicle state, ``stat`` for the mission status), its type (e.g. ``thermometer``;
      the plug-in's ``name`` too when the type is a ``module:Class`` path) and its ``Message`` model's schema name;
    * an analytics' main output: its ``Output`` model, else its declared ``produces``;
    * a named output: its model."""
    src = stream.source
    if isinstance(stream, NamedOutputStream):
        return (_token(src.named_outputs[stream.output]),)
    sensor_type = getattr(src, "type", None)
    if isinstance(sensor_type, str) and not hasattr(src, "analyse"):  # a robot's sensor (aerodaas.app.api.Sensor)

        try:
            cls = registry.resolve("sensor", sensor_type).load()
        except Exception:  # noqa: BLE001 - an unknown type is refused by the configuration, naming it
            cls = None
        # what the drone actor delivers itself, by the class's declared token (never by its type name)
        delivered = getattr(cls, "delivered_token", None)
        msg = getattr(cls, "Message", None)
        name = getattr(cls, "name", None)  # the plug-in's own name, also when the type is a "module:Class" path
        names = (sensor_type,) + ((name,) if isinstance(name, str) and name and name != sensor_type else ())
        return ((delivered,) if delivered else ()) + names + ((_token(msg),) if _is_model(msg) else ())
    out = getattr(src, "Output", None)
    if _is_model(out):
        return (_token(out),)
    return tuple(_token(p) for p in (getattr(src, "produces", None) or ()))


def _describe(stream: AeroStreamData) -> str:
    src = stream.source
    if isinstance(stream, NamedOutputStream):
        return f"named output {stream.output!r} of analytics {src.name!r}"
    if hasattr(src, "analyse"):
        return f"the output of analytics {src.name!r}"
    return f"sensor {getattr(src, 'id', src)!r} ({getattr(src, 'type', '?')})"


def check_consumes(analytics: Any) -> None:
    """Check ``analytics.consumes`` against every stream that feeds it: each stream that declares its types
    (:func:`stream_types`) must carry one of the consumed types. An analytics that declares nothing, or a stream
    that says nothing, is not checked. Raises :class:`ContractError` naming the analytics, the declared types, the
    stream and its types."""
    declared = tuple(_token(c) for c in (getattr(analytics, "consumes", None) or ()))
    if not declared:
        return
    for stream in getattr(analytics, "inputs", None) or ():
        got = stream_types(stream)
        if got and not set(got) & set(declared):
            raise ContractError(f"analytics {analytics.name!r} ({type(analytics).__name__}) consumes "
                                f"{list(declared)}, but it is fed {_describe(stream)}, which carries {list(got)}")


def event_record(robot: str, t: float, analytics: str, event: AnalyticsEvent) -> dict[str, Any]:
    """The recorded form of an analytics' event (``aerodaas.MissionEvent`` on ``/<robot>/events``): ``robot``,
    ``t`` (s, the item's time), ``event`` (its kind), ``analytics`` (the analytics' name), then its fields."""
    return {"robot": robot, "t": t, "event": event.kind, "analytics": analytics, **event.fields}


def checked_event(kind: str, fields: dict[str, Any]) -> AnalyticsEvent:
    """An :class:`AnalyticsEvent`, checked: ``kind`` an event name (:data:`_NAME` grammar), no field named as a
    reserved key (:data:`RESERVED_EVENT_FIELDS`), every value JSON-serialisable. Raises ValueError naming it."""
    if not isinstance(kind, str) or not _NAME.match(kind):
        raise ValueError(f"emit_event: kind {kind!r}: an event name is ASCII letters, digits and _, a letter first")
    bad = [k for k in fields if k in RESERVED_EVENT_FIELDS]
    if bad:
        raise ValueError(f"emit_event({kind!r}): fields {bad} are set by the runtime ({list(RESERVED_EVENT_FIELDS)}); "
                         f"name them otherwise")
    try:
        fields = json.loads(json.dumps(fields, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise ValueError(f"emit_event({kind!r}): fields must be JSON-serialisable (finite numbers, str, lists, "
                         f"dicts): {e}") from None
    return AnalyticsEvent(kind, fields)
