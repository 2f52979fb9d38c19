"""JSON Schemas of the recording's JSON channels, generated from pydantic models.

Every JSON channel AeroDaaS records (``/mission/state``, ``/<robot>/odometry``, ``/<robot>/events``, ...) names a
schema (``aerodaas.MissionState``, ...). This module holds one pydantic model per schema name, documenting each
field with its unit, and :func:`json_schema_for` turns it into the JSON Schema written into the MCAP ``Schema``
record (encoding ``"jsonschema"``), so that Foxglove's Plot and Raw Message panels know the fields and any
JSON Schema validator can check the messages. The schemas come from ``model_json_schema(mode="serialization")``
(JSON Schema draft 2020-12, pydantic's generator), with ``$defs`` inlined where pydantic puts them.

The models describe what the components write; they are not used to build the messages (the hot path writes
plain dicts), so a test validates recorded messages against these schemas (tests/liveview/test_live_and_foxglove.py).
"""
from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any, Optional

from pydantic import BaseModel, ConfigDict, Field

from aerodaas.model.types import AeroNavigation, Odometry, Waypoint

__all__ = ["JSON_SCHEMA_MODELS", "json_schema_for", "plugin_json_schemas"]


class _Open(BaseModel):
    """Known fields typed; further keys allowed (events carry event-specific keys)."""

    model_config = ConfigDict(extra="allow")


class MissionState(BaseModel):
    """A flight-state change of one robot (``/mission/state``)."""

    robot: str
    state: str = Field(description="new state, e.g. NAVIGATING")
    previous: str = Field(description="state before the change")
    t: float = Field(description="simulation or vehicle time, s")


class MissionEvent(_Open):
    """Something that happened to a robot (``/<robot>/events``): ``event`` names it; event-specific keys follow
    (e.g. ``waypoint``, ``error_m`` in metres, ``battery_pct`` in percent)."""

    robot: str
    t: float = Field(description="time of the event, s")
    event: str


class MissionResult(BaseModel):
    """How a robot's mission ended (``/mission/result``)."""

    robot: str
    outcome: str = Field(description="success / incomplete / timeout / interrupted / failed / "
                         "takeoff_stalled / landing_stalled / rtl_stalled")
    visited: int = Field(description="waypoints visited, pre-planned and added in flight")
    preplanned_total: int
    preplanned_reached: Optional[int] = Field(default=None, description="pre-planned waypoints visited")
    t: float = Field(description="time at the end, s")
    error: Optional[str] = None


class NavCommand(_Open):
    """A waypoint command sent to the vehicle (``/<robot>/nav/command``); ``local`` is ENU metres from home."""

    kind: str
    waypoint: Waypoint
    local: list[float] = Field(description="target, ENU metres from home (x east, y north, z up)")
    priority: Optional[int] = None
    autopilot_item: Optional[int] = None


class TargetTruth(_Open):
    """Ground truth of one simulated target at capture time."""

    id: str
    class_name: str
    x: float = Field(description="ENU metres east of home")
    y: float = Field(description="ENU metres north of home")
    heading: float = Field(description="degrees counter-clockwise from east")
    vx: float = Field(description="m/s east")
    vy: float = Field(description="m/s north")
    present: bool
    in_view: bool = False
    fully_in_view: bool = False
    bbox_px: Optional[list[float]] = Field(default=None, description="pixel box (x0, y0, x1, y1) in the frame")


class GroundTruth(BaseModel):
    """Targets' ground truth for one rendered frame (``/world/targets``)."""

    robot: str
    seq: int
    t: float = Field(description="capture time, s")
    targets: list[TargetTruth]


class AnalyticsOutput(_Open):
    """Free-form output of an analytics (``/<robot>/<analytics>``): whatever dict it returned."""


class AnalyticsTask(BaseModel):
    """One analytics-scheduler task in its terminal state (``/<robot>/<analytics>/tasks``); times in ms since the
    scheduler started."""

    task_id: int | str
    model: str
    state: str = Field(description="done_on_time / done_late / dropped_time / dropped_cost / expired_edge / failed")
    tier: Optional[str] = Field(default=None, description="edge or cloud (None when never run)")
    reason: Optional[str] = None
    arrival_ms: float
    deadline_ms: float
    start_ms: Optional[float] = None
    end_ms: Optional[float] = None
    utility: Optional[float] = Field(default=None, description="the task's utility (benefit if on time, less its "
                                                                "cost), as its dispatcher computed it")
    cost: Optional[float] = Field(default=None, description="the edge or cloud cost charged for it (0: none)")
    scheduler: Optional[str] = Field(default=None, description="the analytics scheduler's name (DEMS, ...)")


class FrameLatency(BaseModel):
    """Per-frame latency from frame capture to the navigation command reaching the vehicle (``/<robot>/latency``)."""

    robot: str
    t: float = Field(description="capture time of the frame, s")
    e2e_ms: float = Field(description="capture to command applied, ms")
    applied: bool
    inference_ms: float
    post_ms: float
    overhead_ms: float = Field(description="e2e_ms - inference_ms - post_ms: the framework's share, ms")


class PlanItem(BaseModel):
    id: str
    local: list[float] = Field(description="ENU metres from home")
    hover_duration: float = Field(description="s")


class PlanMission(BaseModel):
    name: str
    priority: int
    items: list[PlanItem]


class MissionPlan(BaseModel):
    """The queued waypoints of a robot whenever they change (``/<robot>/mission/plan``)."""

    robot: str
    t: float
    missions: list[PlanMission]


class RecorderDrops(BaseModel):
    """The frames the recorder refused (its bounded queue full, or closed), per image topic offered: the recording's
    last message (``/run/recorder_drops``), so a reader accounts for every frame a camera took."""

    frames_dropped: dict[str, int] = Field(description="image topic -> frames refused (0: none)")
    total: int


class ChannelProduced(BaseModel):
    """One stream's producers' count (``/run/accounting``)."""

    produced: int = Field(description="messages its producers numbered (sequence numbers handed out), the ones "
                                      "dropped before the file included")
    duplicates: int = Field(description="messages sent again by a restarted drone actor, deliberately not recorded")


class AnalyticsInputs(BaseModel):
    """One analytics' inputs for one robot (``/run/accounting``)."""

    offered: int = Field(description="items its senders handed it")
    no_output: int = Field(description="items it took without recording an output (None, raised, stale, not run)")


class SchedulerTasks(BaseModel):
    """One analytics scheduler's task records in the recording, every segment (``/run/accounting`` ``tasks``,
    :class:`aerodaas.recording.task_tally.TaskCounts`)."""

    tasks: int = Field(description="task records (one per task, in its terminal state)")
    states: dict[str, int] = Field(description="terminal state -> tasks")
    tiers: dict[str, int] = Field(description="edge / cloud / none (never run) -> tasks")
    on_time: int = Field(description="tasks done on time")
    utility: float = Field(description="the sum of their utility")
    cost: float = Field(description="the sum of the edge and cloud cost charged")
    cost_by_tier: dict[str, float] = Field(default_factory=dict, description="tier -> cost charged")


class RunAccounting(BaseModel):
    """The recording's accounting (``/run/accounting``, its last message): per stream (topic) what its producers
    numbered; a channel's loss is ``produced - duplicates - messages in the recording`` (all segments); per
    analytics (``/<robot>/<name>``) its inputs, against which its output topics are accounted; per analytics
    scheduler its task records (counted by the recorder, so the counts survive a dispatcher actor's restart)."""

    channels: dict[str, ChannelProduced]
    analytics: dict[str, AnalyticsInputs] = Field(default_factory=dict)
    tasks: dict[str, SchedulerTasks] = Field(default_factory=dict)


class GimbalAttitude(BaseModel):
    """A robot's camera gimbal attitude (``/<robot>/gimbal``): the simulator's gimbal model, or the vehicle's
    GIMBAL_DEVICE_ATTITUDE_STATUS (gimbal protocol v2 conventions: pitch 0 at the horizon, -90 straight down; yaw
    relative to the vehicle's nose, positive right, unless ``yaw_in_earth_frame``)."""

    robot: str
    t: float = Field(description="vehicle time, s (a MAVLink report: when it was received)")
    q: list[float] = Field(description="attitude quaternion (w, x, y, z), FRD, ZYX order, as MAVLink's q")
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    yaw_in_earth_frame: bool = Field(description="yaw from north (clockwise) instead of from the vehicle's nose")
    source: str = Field(description="sim (the simulator's gimbal) or mavlink (the vehicle's report)")


class FramePose(BaseModel):
    """The pose a camera frame was rendered or tagged with (``/<robot>/camera/<sensor>/pose``, robots with a
    gimbal): the vehicle's position, the camera's heading and pitch from the gimbal's attitude at capture."""

    robot: str
    sensor: str
    seq: int
    t: float = Field(description="capture time, s")
    position: list[float] = Field(description="ENU metres from home")
    yaw: float = Field(description="camera heading, degrees counter-clockwise from east (ENU)")
    camera_pitch: float = Field(description="camera pitch below the horizon, degrees (90 = nadir)")
    gimbal_pitch_deg: float
    gimbal_yaw_deg: float = Field(description="relative to the vehicle's nose, positive right")


#: schema name written on the channel -> the pydantic model describing its messages
JSON_SCHEMA_MODELS: dict[str, type[BaseModel]] = {
    "aerodaas.Odometry": Odometry,
    "aerodaas.MissionState": MissionState,
    "aerodaas.MissionEvent": MissionEvent,
    "aerodaas.MissionResult": MissionResult,
    "aerodaas.NavCommand": NavCommand,
    "aerodaas.GroundTruth": GroundTruth,
    "aerodaas.AeroNavigation": AeroNavigation,
    "aerodaas.AnalyticsOutput": AnalyticsOutput,
    "aerodaas.AnalyticsTask": AnalyticsTask,
    "aerodaas.FrameLatency": FrameLatency,
    "aerodaas.MissionPlan": MissionPlan,
    "aerodaas.RecorderDrops": RecorderDrops,
    "aerodaas.RunAccounting": RunAccounting,
    "aerodaas.GimbalAttitude": GimbalAttitude,
    "aerodaas.FramePose": FramePose,
}


def plugin_json_schemas(schemas: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, Any]]:
    """The schemas plug-ins declared (schema name -> JSON Schema dict, e.g. a sensor plug-in's message model,
    :meth:`aerodaas.plugins.sensor.SensorPlugin.json_schema`), checked and copied for the recorder that writes
    their messages (:class:`aerodaas.recording.writer.McapRecorder`'s ``json_schemas``). A built-in name cannot be
    replaced (ValueError naming it)."""
    out: dict[str, dict[str, Any]] = {}
    for schema_name, schema in (schemas or {}).items():
        if schema_name in JSON_SCHEMA_MODELS:
            raise ValueError(f"schema {schema_name!r} is built in; a plug-in names its own schema")
        out[schema_name] = dict(schema)
    return out


#: free-form schemas: their fields are taken from an example message (json_schema_for's ``example``)
FREE_FORM = ("aerodaas.AnalyticsOutput",)
_JSON_TYPES = ((bool, "boolean"), ((int, float), "number"), (str, "string"), (list, "array"), (dict, "object"))


def _field_schema(value: Any) -> dict[str, Any]:
    for types, name in _JSON_TYPES:
        if isinstance(value, types):
            if name == "array" and value and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                  for v in value):
                return {"type": "array", "items": {"type": "number"}}
            return {"type": name}
    return {}  # null or unknown: any value


def json_schema_for(schema_name: str, example: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The JSON Schema (a dict, ``"type": "object"``, ``"title"`` = ``schema_name``) of a registered schema name,
    or None for a name this module does not know. For a free-form schema (:data:`FREE_FORM`) with an ``example``
    message (plain JSON types), each top-level field of the example is declared with its JSON type (numbers as
    ``number``; a ``null`` accepts anything); other fields stay allowed. Generated once per name (cached). A
    plug-in's schema is not known here: the recorder holds those (:func:`plugin_json_schemas`)."""
    if schema_name in FREE_FORM and example:
        base = dict(json_schema_for(schema_name) or {})
        base["properties"] = {str(k): _field_schema(v) for k, v in example.items()}
        return base
    return _model_schema(schema_name)


@functools.cache
def _model_schema(schema_name: str) -> dict[str, Any] | None:
    """The JSON Schema of the built-in model of ``schema_name`` (None: not built in), generated once per name
    (``functools.cache``: a memo of a pure function of the name)."""
    model = JSON_SCHEMA_MODELS.get(schema_name)
    if model is None:
        return None
    got = model.model_json_schema(mode="serialization")
    got["title"] = schema_name
    got.setdefault("type", "object")
    got["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return got
