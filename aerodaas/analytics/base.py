"""Analytics (the paper's IAnalyse / INavigableAnalyse): the base classes :class:`Analytics` and
:class:`NavigableAnalytics`, and :func:`source_robot`.

An analytics is a plain Python object built in the application; ``deploy(compute)`` picks its tier and
``analyse(stream)`` wires it into the dataflow. At ``start_mission()`` the runtime ships it to a Ray
actor on that tier, calls :meth:`Analytics.setup` there once (load models), then :meth:`Analytics.process`
for every delivered item (or :meth:`Analytics.process_batch` for several at once). Subclass and override
``setup``/``process`` to write your own; its output contract (a typed ``Output``, ``named_outputs``, events,
``consumes``) is :mod:`aerodaas.analytics.contract`.

One analytics object may be fed by several drones (one shared detector or follow controller for a fleet). Whatever
it remembers between items must then be kept per drone: :func:`source_robot` names the drone an item comes from
and :meth:`Analytics.drone_state` holds one state object per drone. The built-in analytics keep all their memory
(tracks, PID integrators, confirmation streaks, running minima/maxima) that way.
"""
from __future__ import annotations

from typing import Any, Callable, ClassVar, Sequence, TypeVar

from pydantic import BaseModel

from aerodaas.analytics.contract import Emissions, NamedOutput, NamedOutputStream, checked_event, current_emissions
from aerodaas.model.data import AeroStreamData
from aerodaas.model.types import AeroNavigation, FrameMeta
from aerodaas.recording.health import DEFAULT_MAX_FAILURE_FRACTION

__all__ = ["Analytics", "IAnalyse", "INavigableAnalyse", "NavigableAnalytics", "source_robot"]

_S = TypeVar("_S")


def source_robot(data: Any, meta: Any) -> str:
    """The id of the drone (robot) an analytics input item comes from.

    * A camera frame, and everything an analytics derives from one (detections, navigation), travels with the
      frame's :class:`~aerodaas.model.types.FrameMeta`: its ``robot_id``.
    * Odometry (``meta`` None) is an :class:`~aerodaas.model.types.Odometry` dict or model: its ``robot_id``.
    * A stat-stream message (``meta`` None) is a dict with a ``robot`` field.

    Returns ``""`` when the item names no drone (an environment sensor's value): such items share one state."""
    rid = getattr(meta, "robot_id", None)
    if rid:
        return str(rid)
    if isinstance(data, dict):
        rid = data.get("robot_id") or data.get("robot")
    else:
        rid = getattr(data, "robot_id", None)
    return str(rid) if rid else ""


class Analytics:
    """Base class (IAnalyse). Subclasses override :meth:`process` and optionally :meth:`setup`.

    ``on_error`` says what an exception raised by :meth:`process` does: ``"continue"`` (default: the item is
    skipped; the error is logged with its traceback, recorded as an ``analytics_error`` event and counted in the
    run's summary) or ``"abort"`` (the same, then every mission of the run ends as ``failed``). Set it on the
    instance (``detector.on_error = "abort"``) or the class; anything else is refused before Ray starts.
    ``max_failure_fraction`` (default 0.2, a number in [0, 1]): with ``"continue"``, the run ends ``degraded``
    (exit code 5) when more than this fraction of its items failed (:mod:`aerodaas.recording.health`).

    Its output contract (:mod:`aerodaas.analytics.contract`, docs/extending.md): ``Output`` (a typed main output,
    recorded with its JSON Schema), ``named_outputs`` (further typed outputs, each its own stream and channel, sent
    with :meth:`emit`), :meth:`emit_event` (an event in the recording, the live view and the run's summary) and
    ``consumes`` (checked against the streams that feed it when the application is loaded). An analytics that
    declares none of them keeps a free-form output (``aerodaas.AnalyticsOutput``)."""

    name: str = "analytics"
    #: plug-in declaration (aerodaas.plugins.registry; docs/extending.md): its kind; ``consumes`` names the stream
    #: types it accepts (``"frame"``, ``"odometry"``, ``"stat"``, ``"detections"``, ``"navigation"``, a plug-in
    #: sensor's type, or a message class such as ``Detection`` or a plug-in's pydantic model), checked against every
    #: stream that feeds it before Ray starts (:func:`aerodaas.analytics.contract.check_consumes`; empty: any);
    #: ``produces`` names what it returns, the type of its output stream when it has no ``Output``
    plugin_kind: str = "analytics"
    consumes: tuple = ()
    produces: tuple = ()
    #: the main output's message model (a pydantic BaseModel subclass): :meth:`process` returns one, or a dict of
    #: its fields, or None. Recorded on ``/<robot>/<name>`` as ``<top package>.<model name>`` with the model's JSON
    #: Schema; a downstream analytics receives it as a JSON-ready dict. None: free-form output
    Output: ClassVar[type[BaseModel] | None] = None
    #: further outputs, ``{output name: pydantic model}``: each is a stream of its own (:meth:`output_stream`),
    #: recorded on ``/<robot>/<name>/<output name>``; the analytics sends to one with :meth:`emit`
    named_outputs: ClassVar[dict[str, type[BaseModel]]] = {}
    on_error: str = "continue"
    #: the run is ``degraded`` when more than this fraction of its items failed (aerodaas.recording.health)
    max_failure_fraction: float = DEFAULT_MAX_FAILURE_FRACTION
    #: Most items the runtime should hand to one :meth:`process_batch` call (1: no batching pays off). Read on the
    #: actor after :meth:`setup`; the ONNX detectors raise it when their model takes a dynamic batch.
    max_batch: int = 1
    #: True when the analytics remembers anything between items of one drone (a track, an integrator, a streak):
    #: a runtime that spreads items over ``replicas`` must then send every item of a drone to the same replica
    #: (route by :func:`source_robot`). False (e.g. :class:`ObjectDetector`): any replica may take any item.
    stateful: bool = True
    #: Ray's logical GPUs its own actor asks for (``deploy(compute)``, each replica), so that Ray places it on a
    #: node of the compute that has them (0: none). :class:`~aerodaas.analytics.detector.ObjectDetector` sets it
    #: from its ``providers``; a colocated or scheduled analytics asking for one is refused before Ray starts
    num_gpus: float = 0.0

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if cls.Output is not None and "produces" not in cls.__dict__:  # listed by `aerodaas plugins` as a sensor's
            cls.produces = (cls.Output, *dict(cls.named_outputs or {}).values())

    def __init__(self, name: str | None = None) -> None:
        if name:
            self.name = name
        self.compute = None
        self.colocate = False
        self.replicas = 1
        self.inputs: list[AeroStreamData] = []
        self.output = AeroStreamData(source=self)
        self.named_streams: dict[str, NamedOutputStream] = {}
        self.triggers: list[Analytics] = []
        self.instantiated = False

    def __getstate__(self) -> dict:
        # ship only the analytics itself to its actor, not the build-time dataflow graph around it
        d = self.__dict__.copy()
        for k in ("inputs", "output", "triggers", "compute", "named_streams"):
            d[k] = None
        return d

    # -- IAnalyse
    def deploy(self, compute: Any, *, colocate: bool = False, replicas: int = 1) -> "Analytics":
        """Assign the compute resource (ICompute) this analytics runs on: its actor is placed on a Ray node of the
        resource's tier carrying its labels.

        ``replicas``: run ``n`` actors of this analytics; each drone's items always go to the same replica
        (``index of the drone % n``), so per-drone state (tracks, integrators) stays in one place.
        ``colocate=True``: no actor of its own; a copy runs inside the actor of each drone that feeds it (zero
        actor hops, the drone's own process and GIL: for cheap per-drone analytics such as a follow controller);
        ``compute`` then only names where the drones fly from. Raises ValueError for a ``compute`` that is not a
        compute resource (``deploy("edge")``: a name, not ``env.get_compute_resource_by_id("edge")``; it failed in
        the runtime as an AttributeError), ``replicas`` < 1 or ``replicas`` > 1 with ``colocate``. That it is one
        of the environment's is checked when the application is loaded
        (:func:`aerodaas.runtime.preflight.validate_graph`)."""
        if not (isinstance(getattr(compute, "id", None), str) and getattr(compute, "tier", None) in ("edge", "cloud")):
            hint = f" (use env.get_compute_resource_by_id({compute!r}))" if isinstance(compute, str) else ""
            raise ValueError(f"analytics {self.name!r}: deploy() takes one of the environment's compute resources, "
                             f"got {type(compute).__name__} {compute!r}{hint}")
        if not isinstance(replicas, int) or isinstance(replicas, bool) or replicas < 1:
            raise ValueError(f"analytics {self.name!r}: replicas must be an integer >= 1, got {replicas!r}")
        if colocate and replicas != 1:
            raise ValueError(f"analytics {self.name!r}: replicas={replicas} with colocate=True (a colocated "
                             f"analytics runs once inside each drone's actor)")
        self.compute = compute
        self.colocate = bool(colocate)
        self.replicas = replicas
        return self

    def analyse(self, stream: AeroStreamData) -> AeroStreamData:
        """Subscribe this analytics to ``stream`` (application side, while the dataflow graph is built; nothing runs
        yet) and return this analytics' main output stream, for a downstream analytics' ``analyse`` or a trajectory
        scheduler's ``PriorityQueue``.

        ``stream``: a sensor's ``get_data_stream()``, another analytics' output (what its ``analyse`` returned) or
        one of its named outputs (``output_stream(name)``). May be called several times (one analytics fed by
        several drones or sensors: each item says where it comes from, :func:`source_robot`). At run time every item
        of ``stream`` reaches :meth:`process` as ``(data, meta)``: a camera frame as an (H, W, 3) uint8 BGR array with
        its :class:`~aerodaas.model.types.FrameMeta`; odometry, a stat-stream transition, a plug-in sensor's reading,
        a typed output or a named output as a JSON-ready dict with ``meta`` None; detections (a list of
        :class:`~aerodaas.model.types.Detection`) and navigation with the FrameMeta of the frame they come from
        (docs/extending.md lists every message's fields and units).

        Raises TypeError when ``stream`` is not an AeroStreamData. Whether the stream's type is one this analytics
        ``consumes`` is checked when the application is loaded (all inputs known), before Ray starts."""
        if not isinstance(stream, AeroStreamData):
            raise TypeError(f"{self.name}.analyse expects an AeroStreamData, got {type(stream).__name__}")
        self.inputs.append(stream)
        stream.subscribers.append(self)
        return self.output

    def output_stream(self, output: str) -> NamedOutputStream:
        """The stream of named output ``output`` (declared in ``named_outputs``), for another analytics'
        ``analyse``; the same object on every call. Its items are dicts of the output's model, ``meta`` None.
        Raises KeyError naming the analytics and its declared outputs for an undeclared name."""
        named = dict(self.named_outputs or {})
        if output not in named:
            raise KeyError(f"analytics {self.name!r} has no named output {output!r}; it declares "
                           f"{sorted(named)} (named_outputs)")
        if getattr(self, "named_streams", None) is None:
            self.named_streams = {}
        if output not in self.named_streams:
            self.named_streams[output] = NamedOutputStream(self, output)
        return self.named_streams[output]

    def instantiate(self) -> AeroStreamData:
        """Mark this analytics as fed by an external source (no stream input); returns its output stream."""
        self.instantiated = True
        return self.output

    def trigger(self, other: "Analytics") -> "Analytics":
        """Start ``other`` at run time on this analytics' output (it receives every output of this one)."""
        other.analyse(self.output)
        self.triggers.append(other)
        return other

    # -- executed inside the actor
    def setup(self) -> None:
        """Called once on the actor before the first item (load models here)."""

    def process(self, data: Any, meta: FrameMeta | None) -> Any:
        """Process one delivered item, in the analytics' actor (or, colocated, the drone's), after :meth:`setup`.

        ``data``/``meta``: as :meth:`analyse` describes for the stream it came from (``meta`` None for every item that
        is not a camera frame or derived from one). Returns the item's output, or None for no output:

        * with ``Output`` declared: an ``Output`` instance (or a dict of its fields), recorded on ``/<robot>/<name>``
          with the model's schema and published to the subscribers as a JSON-ready dict;
        * a list of :class:`~aerodaas.model.types.Detection` (recorded as image annotations on
          ``/<robot>/<name>/detections``) or an :class:`~aerodaas.model.types.AeroNavigation` (on
          ``/<robot>/<name>/navigation``; a trajectory scheduler fed by this stream flies it);
        * anything else: free-form, a dict recorded as ``aerodaas.AnalyticsOutput``.

        While processing it may :meth:`emit` to a named output and :meth:`emit_event`; both are recorded with this
        item's robot and time. Raises whatever the analytics raises: the item is then lost, the error recorded as
        an ``analytics_error`` event and counted (``on_error`` decides whether the run goes on); an output that is
        not its declared ``Output`` is such an error too. The default returns None."""
        return None

    def emit(self, output: str, message: BaseModel | dict) -> None:
        """Send ``message`` to named output ``output`` (declared in ``named_outputs``) while processing an item:
        it is recorded on ``/<robot>/<name>/<output>`` and published on :meth:`output_stream` ``(output)`` as a
        JSON-ready dict, with the item's robot and time. ``message``: an instance of the declared model or a dict of
        its fields. Raises KeyError for an undeclared output, pydantic's ValidationError for a message that is not
        the output's model. Outside a run (``process`` called directly) the messages are kept for
        :meth:`take_emissions`."""
        named = dict(self.named_outputs or {})
        if output not in named:
            raise KeyError(f"analytics {self.name!r}: emit to undeclared output {output!r}; named_outputs has "
                           f"{sorted(named)}")
        model = named[output]
        msg = message if isinstance(message, model) else model.model_validate(
            message.model_dump() if isinstance(message, BaseModel) else message)
        em = self._emissions()
        em.outputs.append((em.item, NamedOutput(output, msg)))

    def emit_event(self, kind: str, **fields: Any) -> None:
        """Record event ``kind`` with ``fields`` while processing an item: written to ``/<robot>/events``
        (``aerodaas.MissionEvent``: ``robot`` and ``t`` of the item, ``event`` = ``kind``, ``analytics`` = this
        analytics' name, then ``fields``), shown in the live view, and counted per kind in the run's summary.
        ``kind``: ASCII letters, digits and ``_``, a letter first; ``fields``: JSON-serialisable values (units in
        their names, e.g. ``peak_ppm``), none named ``robot``, ``t``, ``event`` or ``analytics``. Raises ValueError
        naming what is wrong. Outside a run the events are kept for :meth:`take_emissions`."""
        ev = checked_event(kind, fields)
        em = self._emissions()
        em.events.append((em.item, ev))

    def _emissions(self) -> Emissions:
        """Where :meth:`emit`/:meth:`emit_event` go: the runtime's collector of this thread, else this object's own."""
        em = current_emissions(self)
        if em is None:
            em = self.__dict__.setdefault("_own_emissions", Emissions())
        return em

    def take_emissions(self) -> Emissions:
        """What :meth:`emit`/:meth:`emit_event` gathered outside a run (``process`` called directly, e.g. in a unit
        test), and forget it."""
        return self.__dict__.setdefault("_own_emissions", Emissions()).take()

    def process_batch(self, items: Sequence[tuple[Any, FrameMeta | None]]) -> list[Any]:
        """Process several delivered items at once, possibly from different drones (e.g. the latest frame of each
        drone feeding one detector): ``items`` is a sequence of ``(data, meta)`` pairs exactly as :meth:`process`
        takes them; returns one output per item, in the same order (None: no output for that item).

        Default: ``[self.process(data, meta) for data, meta in items]``, so every analytics supports it; an
        analytics whose work vectorises (one DNN inference call for several frames) overrides it and raises
        :attr:`max_batch`. Errors: whatever :meth:`process` raises; when it raises, no output of the batch is
        valid (a runtime re-runs the items one by one with :meth:`process` to attribute the failure, which is safe
        for the analytics that batch: they are not :attr:`stateful`). What :meth:`emit`/:meth:`emit_event` send
        belongs to the item being processed (an override that emits sets ``current_emissions(self).item`` to the
        index first; otherwise it belongs to the batch's first item)."""
        out = []
        em = current_emissions(self)
        for i, (data, meta) in enumerate(items):
            if em is not None:
                em.item = i
            out.append(self.process(data, meta))
        return out

    # -- per-drone state (one analytics object may serve a fleet)
    def drone_state(self, data: Any, meta: Any, factory: Callable[[], _S]) -> _S:
        """This analytics' state object for the drone the item ``(data, meta)`` comes from
        (:func:`source_robot`), made by ``factory()`` on that drone's first item. Keep in it everything remembered
        between items, so that drones sharing this analytics never mix."""
        states = self.__dict__.setdefault("_drone_states", {})
        key = source_robot(data, meta)
        st = states.get(key)
        if st is None:
            st = states.setdefault(key, factory())
        return st

    def drone_states(self) -> dict[str, Any]:
        """The per-drone state objects made so far, by robot id (``""``: items naming no drone)."""
        return dict(self.__dict__.get("_drone_states", {}))

    def reset_drone(self, robot_id: str) -> None:
        """Forget what this analytics remembers about drone ``robot_id`` (e.g. after that drone's actor restarted
        from a checkpoint); a no-op for a drone it has not seen."""
        self.__dict__.get("_drone_states", {}).pop(robot_id, None)


IAnalyse = Analytics


class NavigableAnalytics(Analytics):
    """INavigableAnalyse: an analytics whose output is navigation. Override :meth:`generate_navigation`; its output
    stream goes to a trajectory scheduler (``scheduler.add_navigation(PriorityQueue(stream, priority))``)."""

    produces = ("navigation",)

    def generate_navigation(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        """The navigation for one item (``data``/``meta`` as :meth:`Analytics.process` takes them): an
        :class:`~aerodaas.model.types.AeroNavigation` of waypoints, velocity or action commands, recorded on
        ``/<robot>/<name>/navigation`` and flown by the drone's trajectory scheduler at the stream's priority, or
        None for none. It may :meth:`~Analytics.emit_event` too. The default returns None."""
        return None

    def process(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        """:meth:`generate_navigation` of the item (a navigable analytics' output is its navigation)."""
        return self.generate_navigation(data, meta)


INavigableAnalyse = NavigableAnalytics

