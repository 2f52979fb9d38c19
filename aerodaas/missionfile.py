"""Mission files: QGroundControl ``.plan`` (JSON) and Mission Planner / ArduPilot ``QGC WPL 110`` (text).

Both formats carry MAVLink ``MISSION_ITEM`` rows: a command (``MAV_CMD``), a coordinate frame (``MAV_FRAME``),
``param1``..``param4``, ``x`` = latitude (degrees), ``y`` = longitude (degrees), ``z`` = altitude (metres;
above mean sea level in ``MAV_FRAME_GLOBAL`` 0 / ``MAV_FRAME_GLOBAL_INT`` 5, above home in
``MAV_FRAME_GLOBAL_RELATIVE_ALT`` 3 / ``..._INT`` 6) and an auto-continue flag.

* :func:`load_mission` reads either format (auto-detected from the content), :func:`load_plan` /
  :func:`load_wpl` one of them; :func:`save_plan` / :func:`save_wpl` write them. Loading and saving is
  lossless for every item: ``.plan`` ComplexItems (survey, corridor scan, structure scan, landing patterns)
  are kept verbatim in :attr:`MissionItem.raw` and written back unchanged.
* :func:`plan_to_flight` turns a plan into what an AeroDaaS drone flies: an ordered
  :class:`~aerodaas.models.AeroNavigation` of absolute waypoints (latitude, longitude, metres above home), a
  terminal action (land, return to launch, or hover) and the plan's geofence. :func:`plan_to_navigation` is
  the shortcut to the navigation alone; :func:`navigation_to_plan` goes the other way.
* Nothing is dropped silently. Commands the drone cannot honour raise :class:`MissionFileError` naming the
  file, the item (sequence number), the command number and name; commands that only drive a payload may be
  skipped explicitly with ``skip_commands`` (e.g. :data:`PAYLOAD_COMMANDS`) and are then listed in
  :attr:`FlightPlan.skipped`.

Complex items are expanded into MAVLink items the way QGroundControl uploads them:

* ``survey`` and ``CorridorScan`` (``TransectStyleComplexItem``): the ``Items`` array the plan carries, which is
  exactly what QGroundControl sends to the vehicle for a loaded plan (``_loadedMissionItems``), renumbered
  from the complex item's sequence number.
* ``StructureScan`` (version 3): regenerated with QGroundControl's ``StructureScanComplexItem::
  appendMissionItems`` algorithm — the structure polygon is offset outward by ``CameraCalc.DistanceToSurface``
  (``QGCMapPolygon::offset``, Qt ``QLineF`` geometry in a local tangent plane at vertex 0, WGS-84 as current
  QGroundControl's GeographicLib ``LocalCartesian``; older QGroundControl releases used a spherical azimuthal
  projection, which moves the offset vertices by about 0.3 % of the offset distance), then: entrance
  waypoint, ``MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET`` (196), per layer one waypoint per vertex plus the closing
  vertex with ``MAV_CMD_DO_SET_CAM_TRIGG_DIST`` (206) start/stop, ``MAV_CMD_DO_SET_ROI_NONE`` (197) and the
  exit waypoint. A scan whose stored ``Layers`` disagrees with QGroundControl's layer formula, or whose polygon
  cannot be offset, is rejected rather than guessed.
* Other complex items (fixed-wing / VTOL landing patterns, unknown types) are rejected by name when they must
  be expanded (WPL export, flight conversion); ``.plan`` round trips keep them.

Sources: QGroundControl plan file format (``docs/en/qgc-dev-guide/file_formats/plan.md``) and loader/saver
(``MissionController``, ``SimpleMissionItem``, ``MissionItem``, ``GeoFenceController``, ``QGCFencePolygon``,
``QGCFenceCircle``, ``TransectStyleComplexItem``, ``StructureScanComplexItem``, ``QGCMapPolygon``), MAVSDK
``mission_raw/mission_import.cpp``, the MAVLink plain-text mission format (mavlink.io ``file_formats``) and
MAVLink ``common.xml`` (``MAV_CMD``, ``MAV_FRAME``).
"""
from __future__ import annotations

import copy
import json
import math
from decimal import Decimal
from pathlib import Path
from typing import Any, Iterable, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .geo import enu_to_geodetic, geodetic_to_enu
from .geofence import Geofence, GeofenceCircle, GeofenceConfig, GeofencePolygon
from .models import AeroNavigation, GeoPoint, NavigationType, SchedulingType, VelocityCommand, Waypoint

__all__ = [
    "MissionFileError", "MissionItem", "MissionPlan", "FlightPlan",
    "load_mission", "load_plan", "load_wpl", "save_plan", "save_wpl",
    "plan_to_flight", "plan_to_navigation", "navigation_to_plan", "expand_items",
    "command_name", "frame_name", "PAYLOAD_COMMANDS", "COMPLEX_ITEM_COMMAND",
    "MAV_CMD_NAV_WAYPOINT", "MAV_CMD_NAV_LOITER_UNLIM", "MAV_CMD_NAV_LOITER_TIME",
    "MAV_CMD_NAV_RETURN_TO_LAUNCH", "MAV_CMD_NAV_LAND", "MAV_CMD_NAV_TAKEOFF", "MAV_CMD_DO_CHANGE_SPEED",
    "MAV_FRAME_GLOBAL", "MAV_FRAME_MISSION", "MAV_FRAME_GLOBAL_RELATIVE_ALT",
]


class MissionFileError(ValueError):
    """A mission file or plan that cannot be read, written or flown. The message names the file, the line or
    item (sequence number, command number and name) and the offending value."""


# --- MAVLink constants (common.xml) ----------------------------------------------------------------------

MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_UNLIM = 17
MAV_CMD_NAV_LOITER_TIME = 19
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_JUMP = 177
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET = 196
MAV_CMD_DO_SET_ROI_NONE = 197
MAV_CMD_DO_SET_CAM_TRIGG_DIST = 206

MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3

#: ``MissionItem.command`` of a verbatim ``.plan`` ComplexItem (MAVLink defines no command 0).
COMPLEX_ITEM_COMMAND = 0

_CMD_NAMES: dict[int, str] = {
    16: "NAV_WAYPOINT", 17: "NAV_LOITER_UNLIM", 18: "NAV_LOITER_TURNS", 19: "NAV_LOITER_TIME",
    20: "NAV_RETURN_TO_LAUNCH", 21: "NAV_LAND", 22: "NAV_TAKEOFF", 23: "NAV_LAND_LOCAL", 24: "NAV_TAKEOFF_LOCAL",
    25: "NAV_FOLLOW", 30: "NAV_CONTINUE_AND_CHANGE_ALT", 31: "NAV_LOITER_TO_ALT", 32: "DO_FOLLOW",
    33: "DO_FOLLOW_REPOSITION", 80: "NAV_ROI", 81: "NAV_PATHPLANNING", 82: "NAV_SPLINE_WAYPOINT",
    83: "NAV_ALTITUDE_WAIT", 84: "NAV_VTOL_TAKEOFF", 85: "NAV_VTOL_LAND", 92: "NAV_GUIDED_ENABLE",
    93: "NAV_DELAY", 94: "NAV_PAYLOAD_PLACE", 112: "CONDITION_DELAY", 113: "CONDITION_CHANGE_ALT",
    114: "CONDITION_DISTANCE", 115: "CONDITION_YAW", 176: "DO_SET_MODE", 177: "DO_JUMP", 178: "DO_CHANGE_SPEED",
    179: "DO_SET_HOME", 180: "DO_SET_PARAMETER", 181: "DO_SET_RELAY", 182: "DO_REPEAT_RELAY",
    183: "DO_SET_SERVO", 184: "DO_REPEAT_SERVO", 185: "DO_FLIGHTTERMINATION", 186: "DO_CHANGE_ALTITUDE",
    188: "DO_RETURN_PATH_START", 189: "DO_LAND_START", 190: "DO_RALLY_LAND", 191: "DO_GO_AROUND",
    192: "DO_REPOSITION", 193: "DO_PAUSE_CONTINUE", 194: "DO_SET_REVERSE", 195: "DO_SET_ROI_LOCATION",
    196: "DO_SET_ROI_WPNEXT_OFFSET", 197: "DO_SET_ROI_NONE", 198: "DO_SET_ROI_SYSID", 200: "DO_CONTROL_VIDEO",
    201: "DO_SET_ROI", 202: "DO_DIGICAM_CONFIGURE", 203: "DO_DIGICAM_CONTROL", 204: "DO_MOUNT_CONFIGURE",
    205: "DO_MOUNT_CONTROL", 206: "DO_SET_CAM_TRIGG_DIST", 207: "DO_FENCE_ENABLE", 208: "DO_PARACHUTE",
    211: "DO_GRIPPER", 212: "DO_AUTOTUNE_ENABLE", 213: "NAV_SET_YAW_SPEED", 214: "DO_SET_CAM_TRIGG_INTERVAL",
    220: "DO_MOUNT_CONTROL_QUAT", 223: "DO_ENGINE_CONTROL", 224: "DO_SET_MISSION_CURRENT", 300: "MISSION_START",
    400: "COMPONENT_ARM_DISARM", 530: "SET_CAMERA_MODE", 531: "SET_CAMERA_ZOOM", 532: "SET_CAMERA_FOCUS",
    1000: "DO_GIMBAL_MANAGER_PITCHYAW", 1001: "DO_GIMBAL_MANAGER_CONFIGURE", 2000: "IMAGE_START_CAPTURE",
    2001: "IMAGE_STOP_CAPTURE", 2003: "DO_TRIGGER_CONTROL", 2500: "VIDEO_START_CAPTURE",
    2501: "VIDEO_STOP_CAPTURE", 3000: "DO_VTOL_TRANSITION", 5000: "NAV_FENCE_RETURN_POINT",
    5001: "NAV_FENCE_POLYGON_VERTEX_INCLUSION", 5002: "NAV_FENCE_POLYGON_VERTEX_EXCLUSION",
    5003: "NAV_FENCE_CIRCLE_INCLUSION", 5004: "NAV_FENCE_CIRCLE_EXCLUSION", 5100: "NAV_RALLY_POINT",
}

_FRAME_NAMES: dict[int, str] = {
    0: "GLOBAL", 1: "LOCAL_NED", 2: "MISSION", 3: "GLOBAL_RELATIVE_ALT", 4: "LOCAL_ENU", 5: "GLOBAL_INT",
    6: "GLOBAL_RELATIVE_ALT_INT", 7: "LOCAL_OFFSET_NED", 8: "BODY_NED", 9: "BODY_OFFSET_NED",
    10: "GLOBAL_TERRAIN_ALT", 11: "GLOBAL_TERRAIN_ALT_INT", 12: "BODY_FRD", 20: "LOCAL_FRD", 21: "LOCAL_FLU",
}

#: Frames a mission item in a file may use: global (AMSL, relative to home, terrain) and MAV_FRAME_MISSION.
MISSION_FRAMES = frozenset({0, 2, 3, 5, 6, 10, 11})
_GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})
_AMSL_FRAMES = frozenset({0, 5})
_RELATIVE_FRAMES = frozenset({3, 6})
_TERRAIN_FRAMES = frozenset({10, 11})

#: Commands that only drive the camera, gimbal or region of interest and leave the flight path unchanged:
#: DO_SET_ROI_LOCATION 195, DO_SET_ROI_WPNEXT_OFFSET 196, DO_SET_ROI_NONE 197, DO_SET_ROI 201,
#: DO_DIGICAM_CONFIGURE 202, DO_DIGICAM_CONTROL 203, DO_MOUNT_CONFIGURE 204, DO_MOUNT_CONTROL 205,
#: DO_SET_CAM_TRIGG_DIST 206, DO_SET_CAM_TRIGG_INTERVAL 214, SET_CAMERA_MODE 530, SET_CAMERA_ZOOM 531,
#: SET_CAMERA_FOCUS 532, DO_GIMBAL_MANAGER_PITCHYAW 1000, DO_GIMBAL_MANAGER_CONFIGURE 1001,
#: IMAGE_START_CAPTURE 2000, IMAGE_STOP_CAPTURE 2001, DO_TRIGGER_CONTROL 2003, VIDEO_START_CAPTURE 2500,
#: VIDEO_STOP_CAPTURE 2501. AeroDaaS cameras stream continuously, so a caller may pass these as
#: ``plan_to_flight(..., skip_commands=PAYLOAD_COMMANDS)``; skipped items are reported, never hidden.
PAYLOAD_COMMANDS = frozenset({195, 196, 197, 201, 202, 203, 204, 205, 206, 214, 530, 531, 532, 1000, 1001,
                              2000, 2001, 2003, 2500, 2501})

#: Commands :func:`plan_to_flight` interprets itself (they cannot be skipped).
_FLIGHT_COMMANDS = frozenset({16, 17, 19, 20, 21, 22, 178})


def command_name(command: int) -> str:
    """``"MAV_CMD_NAV_LAND (21)"``; commands outside the table read ``"MAV_CMD 31000 (not in common.xml)"``."""
    if command == COMPLEX_ITEM_COMMAND:
        return "ComplexItem"
    name = _CMD_NAMES.get(command)
    return f"MAV_CMD_{name} ({command})" if name else f"MAV_CMD {command} (not in common.xml)"


def frame_name(frame: int) -> str:
    """``"MAV_FRAME_GLOBAL_RELATIVE_ALT (3)"``."""
    name = _FRAME_NAMES.get(frame)
    return f"MAV_FRAME_{name} ({frame})" if name else f"unknown MAV_FRAME {frame}"


# --- models ----------------------------------------------------------------------------------------------


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class MissionItem(_Model):
    """One MAVLink mission item (``MISSION_ITEM_INT``), or one verbatim QGroundControl ComplexItem.

    * ``seq``: mission sequence number with the home position at 0 (ArduPilot / Mission Planner row number,
      QGroundControl ``doJumpId``); ``MAV_CMD_DO_JUMP`` targets refer to it.
    * ``command``: ``MAV_CMD`` number (e.g. ``MAV_CMD_NAV_WAYPOINT`` = 16).
    * ``frame``: ``MAV_FRAME`` of ``x``/``y``/``z`` (0 AMSL, 2 mission/no position, 3 relative to home, 5/6 the
      ``_INT`` aliases of 0/3, 10/11 above terrain).
    * ``params``: exactly 7 values ``[param1, param2, param3, param4, x, y, z]``: for positional commands ``x``
      is latitude (degrees), ``y`` longitude (degrees), ``z`` altitude (metres, per ``frame``). ``None`` stands
      for NaN ("unset", JSON ``null``).
    * ``autocontinue``: continue to the next item when this one completes.
    * ``raw``: the verbatim ``.plan`` JSON object of a ComplexItem; then ``command`` is
      :data:`COMPLEX_ITEM_COMMAND` (0), ``frame`` is 2 and every param is ``None``.
    """

    seq: int = Field(ge=0)
    command: int = Field(ge=0, le=65535)
    frame: int = Field(ge=0, le=255)
    params: list[float | None] = Field(default_factory=lambda: [None] * 7)
    autocontinue: bool = True
    raw: dict[str, Any] | None = None

    @field_validator("params", mode="before")
    @classmethod
    def _seven_params(cls, v: Any) -> list[float | None]:
        if not isinstance(v, (list, tuple)) or len(v) != 7:
            raise ValueError(f"params must hold exactly 7 values [param1..param4, x, y, z], got {v!r}")
        out: list[float | None] = []
        for i, p in enumerate(v):
            if p is None:
                out.append(None)
                continue
            if isinstance(p, bool) or not isinstance(p, (int, float)):
                raise ValueError(f"params[{i}] must be a number or null, got {p!r}")
            f = float(p)
            if math.isnan(f):
                out.append(None)
            elif math.isinf(f):
                raise ValueError(f"params[{i}] must be finite, got {p!r}")
            else:
                out.append(f)
        return out

    @model_validator(mode="after")
    def _consistent(self) -> "MissionItem":
        if self.raw is not None:
            if self.command != COMPLEX_ITEM_COMMAND or any(p is not None for p in self.params):
                raise ValueError("a ComplexItem (raw set) must have command 0 and all params None")
            if not isinstance(self.raw.get("complexItemType"), str):
                raise ValueError(f"raw: a ComplexItem needs a string 'complexItemType', got {self.raw!r:.200}")
        elif self.command == COMPLEX_ITEM_COMMAND:
            raise ValueError("command 0 is not a MAVLink command (only ComplexItems, with raw, use 0)")
        return self

    @property
    def is_complex(self) -> bool:
        """True for a verbatim ``.plan`` ComplexItem."""
        return self.raw is not None

    @property
    def complex_type(self) -> str | None:
        """``complexItemType`` of a ComplexItem (``"survey"``, ``"CorridorScan"``, ``"StructureScan"``...)."""
        return self.raw.get("complexItemType") if self.raw is not None else None

    def describe(self) -> str:
        """``"item 3 (MAV_CMD_NAV_LAND (21))"`` / ``"item 2 (ComplexItem 'StructureScan')"`` for messages."""
        if self.raw is not None:
            return f"item {self.seq} (ComplexItem {self.complex_type!r})"
        return f"item {self.seq} ({command_name(self.command)})"


class MissionPlan(_Model):
    """A mission as the files hold it.

    * ``home``: planned home position (``plannedHomePosition`` / WPL row 0), latitude/longitude in degrees and
      altitude in metres above mean sea level; ``None`` when the file has none.
    * ``items``: mission items in order (see :class:`MissionItem`).
    * ``geofence``: inclusion/exclusion polygons and circles (``geoFence``).
    * ``cruise_speed`` / ``hover_speed``: QGroundControl's planning speeds in m/s (fixed-wing / multirotor).
      They are planning defaults for time estimates, not uploaded to the vehicle, so :func:`plan_to_flight`
      does not apply them (a ``MAV_CMD_DO_CHANGE_SPEED`` item does).
    * ``firmware_type`` (``MAV_AUTOPILOT``, 12 = PX4, 3 = ArduPilot) / ``vehicle_type`` (``MAV_TYPE``, 2 =
      quadrotor): as stored in a ``.plan``. QGroundControl requires ``firmwareType``, so ``None`` writes 12
      (PX4); ``vehicleType`` is optional and omitted when ``None``.
    * ``rally_points``: ``(latitude, longitude, altitude above home m)`` safe points (``rallyPoints``).
    * ``breach_return``: fence breach return point ``(latitude, longitude, altitude m)`` (``geoFence.breachReturn``).
    * ``source``: the file the plan was read from (used in error messages; not part of the mission).
    """

    home: GeoPoint | None = None
    items: list[MissionItem] = Field(default_factory=list)
    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    cruise_speed: float | None = Field(default=None, ge=0.0)
    hover_speed: float | None = Field(default=None, ge=0.0)
    firmware_type: int | None = None
    vehicle_type: int | None = None
    rally_points: list[tuple[float, float, float]] = Field(default_factory=list)
    breach_return: tuple[float, float, float] | None = None
    source: str | None = None

    def expanded_items(self) -> list[MissionItem]:
        """The MAVLink items a vehicle would receive: ComplexItems expanded (see module docs), simple items as
        they are. Raises :class:`MissionFileError` naming any ComplexItem that cannot be expanded faithfully."""
        return expand_items(self)

    def same_mission(self, other: "MissionPlan") -> bool:
        """True when both plans describe the same mission (everything except ``source``)."""
        return self.model_dump(exclude={"source"}) == other.model_dump(exclude={"source"})


class FlightPlan(_Model):
    """What an AeroDaaS drone flies for a mission plan.

    * ``navigation``: ORDERED, DISTANCE_DRIVEN absolute waypoints (``x`` latitude, ``y`` longitude in degrees,
      ``z`` metres above home) with ids ``"item<seq>"``.
    * ``final_action``: what follows the last waypoint: ``"land"`` (``MAV_CMD_NAV_LAND`` 21), ``"rtl"``
      (``MAV_CMD_NAV_RETURN_TO_LAUNCH`` 20) or ``"hover"`` (no terminal command, or a final
      ``MAV_CMD_NAV_LOITER_UNLIM`` 17: hold position at the last waypoint, as PX4 and ArduPilot do).
    * ``geofence``: the plan's fence; ``home``: the home used for altitudes (``None`` if unknown).
    * ``skipped``: one line per item skipped through ``skip_commands``.
    """

    navigation: AeroNavigation
    final_action: Literal["land", "rtl", "hover"] = "hover"
    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    home: GeoPoint | None = None
    skipped: list[str] = Field(default_factory=list)


# --- helpers ---------------------------------------------------------------------------------------------


def _fail(src: str, where: str, msg: str) -> MissionFileError:
    return MissionFileError(f"{src}: {where}: {msg}")


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise MissionFileError(f"{path}: cannot read mission file ({e.strerror or e})") from e
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise MissionFileError(f"{path}: not UTF-8 text (byte {e.start}: {data[e.start:e.start + 1]!r})") from e
    return text


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_position(src: str, where: str, frame: int, params: list[float | None]) -> None:
    """Latitude/longitude range check for items in a global frame (x, y are degrees there)."""
    if frame not in _GLOBAL_FRAMES:
        return
    lat, lon = params[4], params[5]
    if lat is not None and not -90.0 <= lat <= 90.0:
        raise _fail(src, where, f"latitude (x) {lat!r} is outside [-90, 90] degrees")
    if lon is not None and not -180.0 <= lon <= 180.0:
        raise _fail(src, where, f"longitude (y) {lon!r} is outside [-180, 180] degrees")


def _check_command_frame(src: str, where: str, command: Any, frame: Any) -> None:
    if not isinstance(command, int) or isinstance(command, bool) or not 0 < command <= 65535:
        raise _fail(src, where, f"command must be a MAV_CMD number 1..65535, got {command!r}")
    if not isinstance(frame, int) or isinstance(frame, bool):
        raise _fail(src, where, f"frame must be an integer MAV_FRAME, got {frame!r}")
    if frame not in MISSION_FRAMES:
        what = frame_name(frame) if frame in _FRAME_NAMES else f"unknown frame {frame}"
        raise _fail(src, where, f"{what} is not a mission frame (expected one of "
                                f"{', '.join(frame_name(f) for f in sorted(MISSION_FRAMES))})")


def _geopoint(src: str, where: str, value: Any, need_alt: bool = True) -> GeoPoint:
    n = 3 if need_alt else 2
    if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
        raise _fail(src, where, f"expected [latitude, longitude{', altitude' if need_alt else ''}] numbers, "
                                f"got {value!r}")
    try:
        return GeoPoint(lat=value[0], lon=value[1], alt=value[2] if need_alt else 0.0)
    except ValidationError as e:
        raise _fail(src, where, f"{value!r}: {_first_error(e)}") from None


def _first_error(e: ValidationError) -> str:
    err = e.errors()[0]
    loc = ".".join(str(x) for x in err.get("loc", ()))
    return f"{loc}: {err['msg']} (got {err.get('input')!r})" if loc else f"{err['msg']} (got {err.get('input')!r})"


# --- .plan -----------------------------------------------------------------------------------------------


def _parse_simple_item(src: str, where: str, obj: Any, default_seq: int) -> MissionItem:
    """A QGroundControl ``SimpleItem`` (``MissionItem::load``: type/command/frame/params/autoContinue required,
    doJumpId optional; the v2 ``coordinate`` key is folded into params like QGroundControl does)."""
    if not isinstance(obj, dict):
        raise _fail(src, where, f"mission item must be a JSON object, got {obj!r:.80}")
    if obj.get("type") != "SimpleItem":
        raise _fail(src, where, f"type must be 'SimpleItem', got {obj.get('type')!r}")
    for key in ("command", "frame", "params", "autoContinue"):
        if key not in obj:
            raise _fail(src, where, f"missing required key {key!r}")
    seq = obj.get("doJumpId", default_seq)
    if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
        raise _fail(src, where, f"doJumpId must be a non-negative integer, got {seq!r}")
    command, frame = obj["command"], obj["frame"]
    _check_command_frame(src, f"{where} (doJumpId {seq})", command, frame)
    where = f"{where} (doJumpId {seq}, {command_name(command)})"
    params = obj["params"]
    if "coordinate" in obj and isinstance(params, list) and len(params) == 4:
        coord = obj["coordinate"]
        if not isinstance(coord, list) or len(coord) != 3:
            raise _fail(src, where, f"coordinate must be [latitude, longitude, altitude], got {coord!r}")
        params = list(params) + list(coord)
    if not isinstance(params, list) or len(params) != 7:
        raise _fail(src, where, f"params must be a list of 7 values, got {params!r}")
    for i, p in enumerate(params):
        if p is not None and not _is_number(p):
            raise _fail(src, where, f"params[{i}] must be a number or null, got {p!r}")
        if _is_number(p) and math.isinf(p):
            raise _fail(src, where, f"params[{i}] must be finite, got {p!r}")
    if not isinstance(obj["autoContinue"], bool):
        raise _fail(src, where, f"autoContinue must be true or false, got {obj['autoContinue']!r}")
    item = MissionItem(seq=seq, command=command, frame=frame, params=params, autocontinue=obj["autoContinue"])
    _check_position(src, where, frame, item.params)
    return item


def _complex_item_count(raw: dict[str, Any]) -> int:
    """How many MAVLink items a ComplexItem expands to (QGroundControl's ``lastSequenceNumber`` arithmetic),
    used only to number the items that follow it when they lack a ``doJumpId``."""
    tsci = raw.get("TransectStyleComplexItem")
    if isinstance(tsci, dict) and isinstance(tsci.get("Items"), list):
        return max(len(tsci["Items"]), 1)
    if raw.get("complexItemType") == "StructureScan":
        poly, layers = raw.get("polygon"), raw.get("Layers")
        if isinstance(poly, list) and _is_number(layers):
            return max((len(poly) + 1 + 2) * int(layers) + 4, 1)
    return 1


def _parse_plan(text: str, src: str) -> MissionPlan:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise MissionFileError(f"{src}: line {e.lineno} column {e.colno}: invalid JSON ({e.msg})") from None
    if not isinstance(doc, dict):
        raise _fail(src, "top level", f"expected a JSON object, got {type(doc).__name__}")
    if doc.get("fileType") != "Plan":
        raise _fail(src, "fileType", f"expected 'Plan', got {doc.get('fileType')!r}")
    if doc.get("version") != 1:
        raise _fail(src, "version", f"only .plan version 1 is supported, got {doc.get('version')!r}")
    mission = doc.get("mission")
    if not isinstance(mission, dict):
        raise _fail(src, "mission", f"expected a JSON object, got {mission!r:.80}")
    if mission.get("version") != 2:
        raise _fail(src, "mission.version", f"only mission version 2 is supported, got {mission.get('version')!r}")
    raw_items = mission.get("items")
    if not isinstance(raw_items, list):
        raise _fail(src, "mission.items", f"expected a list, got {raw_items!r:.80}")

    home = None
    if mission.get("plannedHomePosition") is not None:
        home = _geopoint(src, "mission.plannedHomePosition", mission["plannedHomePosition"])
    speeds: dict[str, float | None] = {}
    for key, name in (("cruiseSpeed", "cruise_speed"), ("hoverSpeed", "hover_speed")):
        v = mission.get(key)
        if v is not None and (not _is_number(v) or v < 0 or math.isinf(v)):
            raise _fail(src, f"mission.{key}", f"expected a speed >= 0 m/s, got {v!r}")
        speeds[name] = None if v is None else float(v)
    types: dict[str, int | None] = {}
    for key, name in (("firmwareType", "firmware_type"), ("vehicleType", "vehicle_type")):
        v = mission.get(key)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
            raise _fail(src, f"mission.{key}", f"expected an integer, got {v!r}")
        types[name] = v

    items: list[MissionItem] = []
    next_seq = 1  # QGroundControl numbers mission items from 1; the home position is 0
    for k, obj in enumerate(raw_items):
        where = f"mission.items[{k}]"
        if isinstance(obj, dict) and obj.get("type") == "ComplexItem":
            ctype = obj.get("complexItemType")
            if not isinstance(ctype, str):
                raise _fail(src, where, f"ComplexItem needs a string complexItemType, got {ctype!r}")
            seq = next_seq
            tsci = obj.get("TransectStyleComplexItem")
            if isinstance(tsci, dict) and isinstance(tsci.get("Items"), list) and tsci["Items"]:
                first = tsci["Items"][0]
                if isinstance(first, dict) and isinstance(first.get("doJumpId"), int) and first["doJumpId"] >= 0:
                    seq = first["doJumpId"]
            items.append(MissionItem(seq=seq, command=COMPLEX_ITEM_COMMAND, frame=MAV_FRAME_MISSION,
                                     raw=copy.deepcopy(obj)))
            next_seq = seq + _complex_item_count(obj)
        else:
            item = _parse_simple_item(src, where, obj, next_seq)
            items.append(item)
            next_seq = item.seq + 1

    geofence, breach_return = _parse_geofence(src, doc.get("geoFence"))
    rally = _parse_rally(src, doc.get("rallyPoints"))
    return MissionPlan(home=home, items=items, geofence=geofence, rally_points=rally,
                       breach_return=breach_return, source=src, **speeds, **types)


def _parse_geofence(src: str, fence: Any) -> tuple[GeofenceConfig, tuple[float, float, float] | None]:
    if fence is None:
        return GeofenceConfig(), None
    if not isinstance(fence, dict):
        raise _fail(src, "geoFence", f"expected a JSON object, got {fence!r:.80}")
    if fence.get("version") != 2:
        if any(fence.get(k) for k in ("polygons", "circles", "polygon", "circle", "breachReturn")):
            raise _fail(src, "geoFence.version", f"only geofence version 2 is supported, got {fence.get('version')!r} "
                                                 "(re-save the plan with a current QGroundControl)")
        return GeofenceConfig(), None
    polygons, circles = [], []
    for key in ("polygons", "circles"):
        if not isinstance(fence.get(key, []), list):
            raise _fail(src, f"geoFence.{key}", f"expected a list, got {fence.get(key)!r:.80}")
    for i, obj in enumerate(fence.get("polygons", [])):
        where = f"geoFence.polygons[{i}]"
        if not isinstance(obj, dict) or not isinstance(obj.get("polygon"), list):
            raise _fail(src, where, f"expected {{'polygon': [[lat, lon], ...], 'inclusion': bool}}, got {obj!r:.120}")
        if not isinstance(obj.get("inclusion"), bool):
            raise _fail(src, where + ".inclusion", f"expected true or false, got {obj.get('inclusion')!r}")
        pts = []
        for j, p in enumerate(obj["polygon"]):
            if not isinstance(p, list) or len(p) < 2 or not all(_is_number(v) for v in p[:2]):
                raise _fail(src, f"{where}.polygon[{j}]", f"expected [latitude, longitude], got {p!r}")
            pts.append((float(p[0]), float(p[1])))
        try:
            polygons.append(GeofencePolygon(points=pts, inclusion=obj["inclusion"]))
        except ValidationError as e:
            raise _fail(src, where, _first_error(e)) from None
    for i, obj in enumerate(fence.get("circles", [])):
        where = f"geoFence.circles[{i}]"
        circle = obj.get("circle") if isinstance(obj, dict) else None
        if not isinstance(circle, dict) or not isinstance(circle.get("center"), list) \
                or not _is_number(circle.get("radius")):
            raise _fail(src, where, f"expected {{'circle': {{'center': [lat, lon], 'radius': m}}, 'inclusion': bool}}, "
                                    f"got {obj!r:.120}")
        if not isinstance(obj.get("inclusion"), bool):
            raise _fail(src, where + ".inclusion", f"expected true or false, got {obj.get('inclusion')!r}")
        c = circle["center"]
        if len(c) < 2 or not all(_is_number(v) for v in c[:2]):
            raise _fail(src, where + ".circle.center", f"expected [latitude, longitude], got {c!r}")
        try:
            circles.append(GeofenceCircle(center=(float(c[0]), float(c[1])), radius=circle["radius"],
                                          inclusion=obj["inclusion"]))
        except ValidationError as e:
            raise _fail(src, where, _first_error(e)) from None
    breach = None
    if fence.get("breachReturn") is not None:
        p = _geopoint(src, "geoFence.breachReturn", fence["breachReturn"])
        breach = (p.lat, p.lon, p.alt)
    return GeofenceConfig(polygons=polygons, circles=circles), breach


def _parse_rally(src: str, rally: Any) -> list[tuple[float, float, float]]:
    if rally is None:
        return []
    if not isinstance(rally, dict):
        raise _fail(src, "rallyPoints", f"expected a JSON object, got {rally!r:.80}")
    if rally.get("version") != 2:
        if rally.get("points"):
            raise _fail(src, "rallyPoints.version", f"only rally point version 2 is supported, got "
                                                    f"{rally.get('version')!r}")
        return []
    points = rally.get("points", [])
    if not isinstance(points, list):
        raise _fail(src, "rallyPoints.points", f"expected a list, got {points!r:.80}")
    out = []
    for i, p in enumerate(points):
        g = _geopoint(src, f"rallyPoints.points[{i}]", p)
        out.append((g.lat, g.lon, g.alt))
    return out


def load_plan(path: str | Path) -> MissionPlan:
    """Read a QGroundControl ``.plan`` (``fileType`` "Plan", version 1, mission version 2, geoFence and
    rallyPoints version 2). SimpleItems become :class:`MissionItem` rows (``seq`` = ``doJumpId``), ComplexItems
    are kept verbatim. Raises :class:`MissionFileError` naming the file, the JSON path and the bad value."""
    path = Path(path)
    return _parse_plan(_read_text(path), str(path))


def _json_number(v: float | None) -> float | int | None:
    if v is None:
        return None
    return int(v) if float(v).is_integer() and abs(v) < 2 ** 53 else v


def plan_to_json(plan: MissionPlan) -> dict[str, Any]:
    """The ``.plan`` JSON object for ``plan`` (what :func:`save_plan` writes)."""
    src = plan.source or "<plan>"
    if plan.home is None:
        raise _fail(src, "home", "a QGroundControl .plan requires plannedHomePosition; set plan.home "
                                 "(latitude, longitude, AMSL altitude) before saving")
    items: list[dict[str, Any]] = []
    for item in plan.items:
        if item.raw is not None:
            items.append(copy.deepcopy(item.raw))
            continue
        items.append({
            "autoContinue": item.autocontinue, "command": item.command, "doJumpId": item.seq,
            "frame": item.frame, "params": [_json_number(p) for p in item.params], "type": "SimpleItem",
        })
    mission: dict[str, Any] = {
        "firmwareType": 12 if plan.firmware_type is None else plan.firmware_type,
        "items": items,
        "plannedHomePosition": [_json_number(plan.home.lat), _json_number(plan.home.lon),
                                _json_number(plan.home.alt)],
        "version": 2,
    }
    if plan.vehicle_type is not None:
        mission["vehicleType"] = plan.vehicle_type
    if plan.cruise_speed is not None:
        mission["cruiseSpeed"] = _json_number(plan.cruise_speed)
    if plan.hover_speed is not None:
        mission["hoverSpeed"] = _json_number(plan.hover_speed)
    fence: dict[str, Any] = {
        "circles": [{"circle": {"center": [_json_number(c.center[0]), _json_number(c.center[1])],
                                "radius": _json_number(c.radius)},
                     "inclusion": c.inclusion, "version": 1} for c in plan.geofence.circles],
        "polygons": [{"inclusion": p.inclusion,
                      "polygon": [[_json_number(a), _json_number(b)] for a, b in p.points],
                      "version": 1} for p in plan.geofence.polygons],
        "version": 2,
    }
    if plan.breach_return is not None:
        fence["breachReturn"] = [_json_number(v) for v in plan.breach_return]
    return {
        "fileType": "Plan",
        "geoFence": fence,
        "groundStation": "AeroDaaS",
        "mission": mission,
        "rallyPoints": {"points": [[_json_number(v) for v in p] for p in plan.rally_points], "version": 2},
        "version": 1,
    }


def save_plan(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as a QGroundControl ``.plan`` (JSON, keys sorted, 4-space indent as QGroundControl does).
    ComplexItems are written back verbatim. Requires ``plan.home`` (QGroundControl's required
    ``plannedHomePosition``); raises :class:`MissionFileError` otherwise."""
    doc = plan_to_json(plan)
    Path(path).write_text(json.dumps(doc, indent=4, sort_keys=True, allow_nan=False) + "\n", encoding="utf-8")


# --- WPL 110 ---------------------------------------------------------------------------------------------

_WPL_FIELDS = ("seq", "current", "frame", "command", "param1", "param2", "param3", "param4",
               "x (latitude)", "y (longitude)", "z (altitude)", "autocontinue")


def _parse_wpl(text: str, src: str) -> MissionPlan:
    lines = text.splitlines()
    if not lines:
        raise _fail(src, "line 1", "empty file; expected the header 'QGC WPL 110'")
    header = lines[0].strip()
    parts = header.split()
    if len(parts) != 3 or parts[0] != "QGC" or parts[1] != "WPL" or parts[2] not in ("110", "120"):
        raise _fail(src, "line 1", f"expected the header 'QGC WPL 110', got {header!r:.80}")
    home_row_allowed = parts[2] == "110"  # QGroundControl: 110 = ArduPilot file with home in row 0; 120 = no home

    rows: list[tuple[int, MissionItem]] = []
    for lineno, line in enumerate(lines[1:], start=2):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        where = f"line {lineno}"
        fields = s.split()
        if len(fields) != 12:
            raise _fail(src, where, f"expected 12 tab-separated fields ({' '.join(_WPL_FIELDS)}), got "
                                    f"{len(fields)}: {s!r:.120}")
        ints: dict[int, int] = {}
        for i in (0, 1, 2, 3, 11):
            try:
                ints[i] = int(fields[i])
            except ValueError:
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be an integer, got {fields[i]!r}") from None
        for i in (1, 11):
            if ints[i] not in (0, 1):
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be 0 or 1, got {fields[i]!r}")
        if ints[0] < 0:
            raise _fail(src, where, f"seq must be >= 0, got {fields[0]!r}")
        command, frame = ints[3], ints[2]
        _check_command_frame(src, where, command, frame)
        where = f"{where} ({command_name(command)})"
        params: list[float | None] = []
        for i in range(4, 11):
            try:
                v = float(fields[i])
            except ValueError:
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be a number, got {fields[i]!r}") from None
            if math.isinf(v):
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be finite, got {fields[i]!r}")
            params.append(None if math.isnan(v) else v)
        _check_position(src, where, frame, params)
        rows.append((lineno, MissionItem(seq=0, command=command, frame=frame, params=params,
                                         autocontinue=bool(ints[11]))))

    home = None
    home_row = bool(rows) and home_row_allowed and rows[0][1].command == MAV_CMD_NAV_WAYPOINT
    if home_row:
        lineno, h = rows.pop(0)
        lat, lon, alt = h.params[4], h.params[5], h.params[6]
        if not (lat in (None, 0.0) and lon in (None, 0.0)):  # all-zero row = home not set (Mission Planner)
            if h.frame not in _AMSL_FRAMES:
                raise _fail(src, f"line {lineno} (home position)",
                            f"the home row must be in MAV_FRAME_GLOBAL (0) with an AMSL altitude, got "
                            f"{frame_name(h.frame)}")
            if lat is None or lon is None or alt is None:
                raise _fail(src, f"line {lineno} (home position)", f"latitude/longitude/altitude must be set, "
                                                                   f"got {lat!r}, {lon!r}, {alt!r}")
            home = GeoPoint(lat=lat, lon=lon, alt=alt)
    items = []
    for k, (_, item) in enumerate(rows):
        params = list(item.params)
        if not home_row and item.command == MAV_CMD_DO_JUMP and params[0] is not None:
            params[0] += 1  # DO_JUMP targets in a file without home row count from 0; ours count home as 0
        items.append(item.model_copy(update={"seq": k + 1, "params": params}))
    return MissionPlan(home=home, items=items, source=src)


def load_wpl(path: str | Path) -> MissionPlan:
    """Read a ``QGC WPL 110`` waypoint file (Mission Planner, ArduPilot, MAVSDK, QGroundControl export): a header
    line, then one tab-separated row per item ``seq current frame command param1 param2 param3 param4 x y z
    autocontinue``; CRLF or LF line ends, blank and ``#`` lines ignored.

    Row 0 is the home position when it is a ``MAV_CMD_NAV_WAYPOINT`` (the ArduPilot / Mission Planner /
    QGroundControl convention; an all-zero home row means "home not set"). A file whose first row is another
    command (MAVSDK's PX4 sample starts with ``MAV_CMD_NAV_TAKEOFF``), or a ``QGC WPL 120`` file, has no home row:
    every row is a mission item and ``MAV_CMD_DO_JUMP`` targets are shifted by one, as QGroundControl does.
    Items are numbered 1..n (``seq``) in file order. Raises :class:`MissionFileError` naming the file, line and
    value for a wrong header, a malformed row, an unknown frame or an out-of-range latitude/longitude."""
    path = Path(path)
    return _parse_wpl(_read_text(path), str(path))


def _wpl_number(v: float | None) -> str:
    if v is None:
        return "NaN"
    if float(v).is_integer() and abs(v) < 2 ** 53:
        return str(int(v))
    s = repr(float(v))
    return format(Decimal(s), "f") if "e" in s or "E" in s else s


def wpl_text(plan: MissionPlan) -> str:
    """The ``QGC WPL 110`` text for ``plan`` (what :func:`save_wpl` writes)."""
    items = expand_items(plan)
    home_row = plan.home is not None or (bool(items) and items[0].command == MAV_CMD_NAV_WAYPOINT)
    lines = ["QGC WPL 110"]
    if home_row:
        h = plan.home
        hp = [0.0, 0.0, 0.0, 0.0] + ([h.lat, h.lon, h.alt] if h is not None else [0.0, 0.0, 0.0])
        lines.append("\t".join(["0", "1", str(MAV_FRAME_GLOBAL), str(MAV_CMD_NAV_WAYPOINT)]
                               + [_wpl_number(p) for p in hp] + ["1"]))
    for k, item in enumerate(items):
        params = list(item.params)
        if not home_row and item.command == MAV_CMD_DO_JUMP and params[0] is not None:
            params[0] -= 1
        seq = k + 1 if home_row else k
        current = 1 if (not home_row and k == 0) else 0
        lines.append("\t".join([str(seq), str(current), str(item.frame), str(item.command)]
                               + [_wpl_number(p) for p in params] + [str(int(item.autocontinue))]))
    return "\n".join(lines) + "\n"


def save_wpl(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as a ``QGC WPL 110`` file (tab-separated, LF line ends, NaN for unset params).

    Row 0 is the home position (``MAV_FRAME_GLOBAL``, AMSL) when ``plan.home`` is set; without a home, a
    placeholder all-zero home row is written if the first item is a ``MAV_CMD_NAV_WAYPOINT`` (so it is not
    mistaken for home on reading), otherwise the items start at row 0 (PX4 / MAVSDK style). ComplexItems are
    expanded (WPL has no complex items); one that cannot be expanded raises :class:`MissionFileError`. The
    geofence and rally points cannot be stored in WPL and are not written."""
    Path(path).write_text(wpl_text(plan), encoding="utf-8")


def load_mission(path: str | Path) -> MissionPlan:
    """Read a mission file of either format, detected from its content: JSON (``{``) is a QGroundControl
    ``.plan``, a first line ``QGC WPL ...`` is a waypoint file. Raises :class:`MissionFileError` otherwise."""
    path = Path(path)
    text = _read_text(path)
    head = text.lstrip()
    if head.startswith("{"):
        return _parse_plan(text, str(path))
    if head.startswith("QGC WPL"):
        return _parse_wpl(text, str(path))
    first = head.splitlines()[0] if head else ""
    raise _fail(str(path), "line 1", f"not a QGroundControl .plan (JSON) nor a 'QGC WPL 110' file: {first!r:.80}")


# --- complex item expansion ------------------------------------------------------------------------------


def expand_items(plan: MissionPlan) -> list[MissionItem]:
    """See :meth:`MissionPlan.expanded_items`."""
    src = plan.source or "<plan>"
    out: list[MissionItem] = []
    for k, item in enumerate(plan.items):
        if item.raw is None:
            out.append(item)
            continue
        ctype = item.complex_type
        where = f"mission.items[{k}] (ComplexItem {ctype!r}, item {item.seq})"
        tsci = item.raw.get("TransectStyleComplexItem")
        if ctype in ("survey", "CorridorScan"):
            if not isinstance(tsci, dict) or not isinstance(tsci.get("Items"), list) or not tsci["Items"]:
                raise _fail(src, where, "has no TransectStyleComplexItem.Items to expand; open and re-save it in "
                                        "QGroundControl, which stores the generated items")
            for j, sub in enumerate(tsci["Items"]):
                sub_item = _parse_simple_item(src, f"{where} TransectStyleComplexItem.Items[{j}]", sub, item.seq + j)
                out.append(sub_item.model_copy(update={"seq": item.seq + j}))
        elif ctype == "StructureScan":
            out.extend(_expand_structure_scan(src, where, item.raw, item.seq))
        else:
            raise _fail(src, where, "AeroDaaS cannot expand this ComplexItem into MAVLink items (supported: survey, "
                                    "CorridorScan, StructureScan); it is kept verbatim in .plan exports only")
    return out


class _QLine:
    """The parts of Qt's ``QLineF`` that ``QGCMapPolygon::offset`` uses (angles counter-clockwise in Qt's
    y-down convention, i.e. ``atan2(-dy, dx)``)."""

    def __init__(self, x1: float, y1: float, x2: float, y2: float) -> None:
        self.x1, self.y1, self.x2, self.y2 = x1, y1, x2, y2

    def length(self) -> float:
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)

    def angle(self) -> float:
        theta = math.degrees(math.atan2(-(self.y2 - self.y1), self.x2 - self.x1))
        theta = theta + 360.0 if theta < 0 else theta
        return 0.0 if abs(theta - 360.0) <= 1e-12 * 360.0 else theta

    def set_length(self, length: float) -> None:
        old = self.length()
        if old > 0:
            self.x2 = self.x1 + length * ((self.x2 - self.x1) / old)
            self.y2 = self.y1 + length * ((self.y2 - self.y1) / old)

    def set_angle(self, angle: float) -> None:
        r = math.radians(angle)
        length = self.length()
        self.x2 = self.x1 + math.cos(r) * length
        self.y2 = self.y1 - math.sin(r) * length

    def intersects(self, other: "_QLine") -> tuple[float, float] | None:
        ax, ay = self.x2 - self.x1, self.y2 - self.y1
        bx, by = other.x1 - other.x2, other.y1 - other.y2
        cx, cy = self.x1 - other.x1, self.y1 - other.y1
        den = ay * bx - ax * by
        if den == 0 or not math.isfinite(den):
            return None
        na = (by * cx - bx * cy) / den
        return (self.x1 + ax * na, self.y1 + ay * na)


def _offset_polygon(vertices: list[tuple[float, float]], distance: float) -> list[tuple[float, float]] | None:
    """``QGCMapPolygon::offset``: shift every edge by ``distance`` metres to its left (outward for the clockwise
    polygons QGroundControl draws) in a WGS-84 tangent plane at vertex 0, intersect consecutive shifted edges.
    Returns ``None`` where QGroundControl's intersection fails (parallel consecutive edges)."""
    lat0, lon0 = vertices[0]
    origin = GeoPoint(lat=lat0, lon=lon0, alt=0.0)
    pts = [(0.0, 0.0)] + [geodetic_to_enu(lat, lon, 0.0, origin)[:2] for lat, lon in vertices[1:]]
    edges: list[_QLine] = []
    n = len(pts)
    for i in range(n):
        p, q = pts[i], pts[(i + 1) % n]
        worker = _QLine(p[0], p[1], q[0], q[1])
        worker.set_length(distance)
        worker.set_angle(worker.angle() - 90.0)
        p1 = (worker.x2, worker.y2)
        worker = _QLine(q[0], q[1], p[0], p[1])
        worker.set_length(distance)
        worker.set_angle(worker.angle() + 90.0)
        edges.append(_QLine(p1[0], p1[1], worker.x2, worker.y2))
    out = []
    for i in range(n):
        hit = edges[i - 1].intersects(edges[i])
        if hit is None:
            return None
        g = enu_to_geodetic(hit[0], hit[1], 0.0, origin)
        out.append((g.lat, g.lon))
    return out


def _expand_structure_scan(src: str, where: str, raw: dict[str, Any], seq0: int) -> list[MissionItem]:
    """QGroundControl ``StructureScanComplexItem`` (version 3) -> MAVLink items, as ``appendMissionItems`` builds
    them (entry vertex 0, which QGroundControl does not save and resets to 0 on load)."""
    if raw.get("version") != 3:
        raise _fail(src, where, f"only StructureScan version 3 can be expanded, got version {raw.get('version')!r}")
    for key in ("ScanBottomAlt", "StructureHeight", "Layers", "EntranceAltitude", "GimbalPitch"):
        if not _is_number(raw.get(key)):
            raise _fail(src, where, f"{key} must be a number, got {raw.get(key)!r}")
    if not isinstance(raw.get("StartFromTop"), bool):
        raise _fail(src, where, f"StartFromTop must be true or false, got {raw.get('StartFromTop')!r}")
    cam = raw.get("CameraCalc")
    if not isinstance(cam, dict):
        raise _fail(src, where, f"CameraCalc must be an object, got {cam!r:.80}")
    for key in ("AdjustedFootprintFrontal", "AdjustedFootprintSide", "DistanceToSurface"):
        if not _is_number(cam.get(key)):
            raise _fail(src, where, f"CameraCalc.{key} must be a number, got {cam.get(key)!r}")
    poly = raw.get("polygon")
    if not isinstance(poly, list) or len(poly) < 3 or not all(
            isinstance(p, list) and len(p) >= 2 and _is_number(p[0]) and _is_number(p[1]) for p in poly):
        raise _fail(src, where, f"polygon must hold at least 3 [latitude, longitude] vertices, got {poly!r:.120}")
    for j, p in enumerate(poly):
        if not (-90 <= p[0] <= 90 and -180 <= p[1] <= 180):
            raise _fail(src, where, f"polygon[{j}] = {p!r} is not a valid latitude/longitude")

    frontal = float(cam["AdjustedFootprintFrontal"])
    side = float(cam["AdjustedFootprintSide"])
    if frontal <= 0:
        raise _fail(src, where, f"CameraCalc.AdjustedFootprintFrontal must be > 0 m, got {frontal!r}")
    height, bottom = float(raw["StructureHeight"]), float(raw["ScanBottomAlt"])
    layers = int(raw["Layers"])
    expected_layers = max(math.ceil(max(height - bottom, 0.0) / frontal), 1)  # StructureScan::_recalcLayerInfo
    if layers != raw["Layers"] or layers != expected_layers:
        raise _fail(src, where, f"Layers = {raw['Layers']!r} disagrees with QGroundControl's layer count "
                                f"ceil((StructureHeight {height:g} - ScanBottomAlt {bottom:g}) / "
                                f"AdjustedFootprintFrontal {frontal:g}) = {expected_layers}; QGroundControl would "
                                "recompute it on load, so the flown layers are ambiguous")
    if layers > 10000:
        raise _fail(src, where, f"Layers = {layers} is not a plausible structure scan")
    flight = _offset_polygon([(float(p[0]), float(p[1])) for p in poly], float(cam["DistanceToSurface"]))
    if flight is None:
        raise _fail(src, where, "the structure polygon has parallel consecutive edges; QGroundControl cannot "
                                "offset it (it would fly the structure outline itself)")

    start_from_top = raw["StartFromTop"]
    entrance_alt = float(raw["EntranceAltitude"])
    nan = None
    items: list[MissionItem] = []

    def add(command: int, frame: int, params: list[float | None]) -> None:
        items.append(MissionItem(seq=seq0 + len(items), command=command, frame=frame, params=params))

    entry = flight[0]
    add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, entry[0], entry[1], entrance_alt])
    add(MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET, MAV_FRAME_MISSION, [0, 0, 0, 0, float(raw["GimbalPitch"]), 0, 90])
    half = frontal / 2.0
    layer_alt = (height - half) if start_from_top else (bottom + half)
    for _layer in range(layers):
        for k in range(len(flight) + 1):
            v = flight[k % len(flight)]
            add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, v[0], v[1], layer_alt])
            if k == 0:
                add(MAV_CMD_DO_SET_CAM_TRIGG_DIST, MAV_FRAME_MISSION, [side, 0, 1, 0, 0, 0, 0])
        add(MAV_CMD_DO_SET_CAM_TRIGG_DIST, MAV_FRAME_MISSION, [0, 0, 0, 0, 0, 0, 0])
        layer_alt += -2 * half if start_from_top else 2 * half
    add(MAV_CMD_DO_SET_ROI_NONE, MAV_FRAME_MISSION, [0, 0, 0, 0, 0, 0, 0])
    add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, entry[0], entry[1], entrance_alt])
    return items


# --- conversion to / from AeroDaaS navigation ------------------------------------------------------------


def _latlon_missing(lat: float | None, lon: float | None) -> bool:
    return lat is None or lon is None or (lat == 0.0 and lon == 0.0)


def plan_to_flight(plan: MissionPlan, home: GeoPoint | None = None, *, skip_commands: Iterable[int] = (),
                   check_geofence: bool = True, min_altitude: float | None = 0.0) -> FlightPlan:
    """Convert a mission plan into the navigation an AeroDaaS drone flies.

    ``home`` (WGS-84, AMSL altitude) overrides ``plan.home``; it is needed for AMSL altitudes
    (``MAV_FRAME_GLOBAL`` 0 / ``_INT`` 5: above-home = z - home altitude) and for takeoff / loiter items without
    a position. Relative altitudes (frames 3 / 6) are used as they are. Items, after ComplexItem expansion:

    * ``MAV_CMD_NAV_WAYPOINT`` (16) -> waypoint; param1 hold time (s) -> ``hover_duration``, param2 acceptance
      radius (m) -> ``acceptance_radius`` when > 0. param3 (pass radius) and param4 (yaw) are not modelled.
    * ``MAV_CMD_NAV_TAKEOFF`` (22) -> waypoint at the takeoff position and altitude (home position if latitude
      and longitude are 0 or unset).
    * ``MAV_CMD_NAV_LOITER_TIME`` (19) -> waypoint with ``hover_duration`` = param1 (s) (current position if
      latitude/longitude are 0 or unset).
    * ``MAV_CMD_NAV_LOITER_UNLIM`` (17) as the last item -> waypoint, then ``final_action="hover"``.
    * ``MAV_CMD_NAV_LAND`` (21) -> ``final_action="land"`` (a transit waypoint at the previous altitude first if
      it names a different location); ``MAV_CMD_NAV_RETURN_TO_LAUNCH`` (20) -> ``final_action="rtl"``.
    * ``MAV_CMD_DO_CHANGE_SPEED`` (178), speed type 0/1 -> ``speed`` (m/s) of the following waypoints (-1 keeps,
      -2 restores the default).
    * commands in ``skip_commands`` (e.g. :data:`PAYLOAD_COMMANDS`) are skipped and listed in ``skipped``.

    Anything else — other NAV commands, DO_JUMP, conditions, terrain frames, items after LAND/RTL — raises
    :class:`MissionFileError` naming the file, the item, the command number and name. A waypoint lower than
    ``min_altitude`` metres above home (default 0: below the take-off point, typically an AMSL altitude that
    was meant relative) raises too; ``None`` disables that check. With ``check_geofence`` every waypoint and
    leg (from home, and back to home for RTL) must satisfy the plan's geofence."""
    src = plan.source or "<plan>"
    skip = frozenset(int(c) for c in skip_commands)
    clash = skip & _FLIGHT_COMMANDS
    if clash:
        raise ValueError(f"skip_commands may not contain commands plan_to_flight flies: "
                         f"{', '.join(command_name(c) for c in sorted(clash))}")
    home = home if home is not None else plan.home
    items = expand_items(plan)

    waypoints: list[Waypoint] = []
    skipped: list[str] = []
    final: str | None = None
    terminal: MissionItem | None = None
    speed: float | None = None
    last: tuple[float, float, float] | None = None  # lat, lon, altitude above home of the previous waypoint

    def altitude(item: MissionItem, tag: str) -> float:
        z = item.params[6]
        if item.frame in _TERRAIN_FRAMES:
            raise _fail(src, tag, f"{frame_name(item.frame)} altitudes are above terrain; AeroDaaS has no "
                                  "terrain model")
        if item.frame not in _AMSL_FRAMES and item.frame not in _RELATIVE_FRAMES:
            raise _fail(src, tag, f"{frame_name(item.frame)} carries no global position")
        if z is None:
            raise _fail(src, tag, "altitude (z) is not set")
        if item.frame in _RELATIVE_FRAMES:
            return z
        if home is None:
            raise _fail(src, tag, f"{frame_name(item.frame)} altitude {z:g} m is above mean sea level; converting "
                                  "it to altitude above home needs the home position (plan has none; pass home=)")
        return z - home.alt

    def add_waypoint(item: MissionItem, tag: str, lat: float, lon: float, z: float, hover: float = 0.0,
                     radius: float | None = None, wp_id: str | None = None) -> None:
        nonlocal last
        if min_altitude is not None and z < min_altitude:
            raise _fail(src, tag, f"altitude {z:g} m above home is below min_altitude {min_altitude:g} m "
                                  f"({frame_name(item.frame)}, z={item.params[6]!r}"
                                  f"{f', home altitude {home.alt:g} m AMSL' if home is not None else ''})")
        kwargs: dict[str, Any] = {}
        if radius is not None and radius > 0:
            kwargs["acceptance_radius"] = radius
        try:
            waypoints.append(Waypoint(id=wp_id or f"item{item.seq}", x=lat, y=lon, z=z, hover_duration=hover,
                                      waypoint_type="absolute", speed=speed, **kwargs))
        except ValidationError as e:
            raise _fail(src, tag, _first_error(e)) from None
        last = (lat, lon, z)

    for k, item in enumerate(items):
        tag = item.describe()
        cmd = item.command
        if cmd in skip:
            skipped.append(f"{tag} skipped")
            continue
        if terminal is not None:
            raise _fail(src, tag, f"comes after the terminal {terminal.describe()} and would never run")
        p = item.params
        if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LOITER_UNLIM):
            lat, lon = p[4], p[5]
            if _latlon_missing(lat, lon):
                if cmd == MAV_CMD_NAV_WAYPOINT:
                    raise _fail(src, tag, f"latitude/longitude not set (x={lat!r}, y={lon!r})")
                if cmd != MAV_CMD_NAV_TAKEOFF and last is not None:
                    lat, lon = last[0], last[1]  # loiter at the current position
                elif home is not None:
                    lat, lon = home.lat, home.lon
                else:
                    raise _fail(src, tag, "has no latitude/longitude, so it acts at the vehicle's current (home) "
                                          "position, which is unknown (plan has no home; pass home=)")
            z = altitude(item, tag)
            hover, radius = 0.0, None
            if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME):
                hover = p[0] or 0.0
                if hover < 0:
                    raise _fail(src, tag, f"param1 (hold/loiter time) must be >= 0 s, got {hover!r}")
            if cmd == MAV_CMD_NAV_WAYPOINT:
                radius = p[1]
            if cmd == MAV_CMD_NAV_LOITER_UNLIM:
                rest = [it for it in items[k + 1:] if it.command not in skip]
                if rest:
                    raise _fail(src, tag, f"loiters forever, so the following {rest[0].describe()} would never run")
                final = "hover"
            add_waypoint(item, tag, lat, lon, z, hover, radius)
        elif cmd == MAV_CMD_NAV_LAND:
            lat, lon = p[4], p[5]
            if item.frame != MAV_FRAME_MISSION and not _latlon_missing(lat, lon):
                here = last[:2] if last is not None else (home.lat, home.lon) if home is not None else None
                if here is None or abs(lat - here[0]) > 1e-7 or abs(lon - here[1]) > 1e-7:
                    if last is None:
                        raise _fail(src, tag, f"lands at ({lat}, {lon}) before any waypoint gave an altitude to fly "
                                              "there at; add a takeoff or waypoint first")
                    add_waypoint(item, tag, lat, lon, last[2], wp_id=f"item{item.seq}_approach")
            final, terminal = "land", item
        elif cmd == MAV_CMD_NAV_RETURN_TO_LAUNCH:
            final, terminal = "rtl", item
        elif cmd == MAV_CMD_DO_CHANGE_SPEED:
            kind, value = p[0], p[1]
            if kind not in (0.0, 1.0, None):
                raise _fail(src, tag, f"param1 speed type {kind!r} (climb/descent speed) is not supported; only "
                                      "0 (airspeed) and 1 (ground speed)")
            if value is None or value == -1:
                pass
            elif value == -2:
                speed = None
            elif value > 0:
                speed = value
            else:
                raise _fail(src, tag, f"param2 speed must be > 0 m/s, -1 (no change) or -2 (default), got {value!r}")
        else:
            hint = " (pass skip_commands=PAYLOAD_COMMANDS to skip camera/gimbal commands)" \
                if cmd in PAYLOAD_COMMANDS else ""
            raise _fail(src, tag, f"{command_name(cmd)} is not supported by AeroDaaS navigation{hint}")

    ids = [w.id for w in waypoints]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise _fail(src, "items", f"duplicate sequence numbers give duplicate waypoint ids {dup}")
    if check_geofence and not plan.geofence.is_empty and waypoints:
        _check_flight_geofence(src, plan.geofence, home, waypoints, final)
    name = Path(plan.source).stem if plan.source else "mission"
    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.ORDERED, name=name)
    return FlightPlan(navigation=nav, final_action=final or "hover", geofence=plan.geofence, home=home,
                      skipped=skipped)


def _check_flight_geofence(src: str, config: GeofenceConfig, home: GeoPoint | None, waypoints: list[Waypoint],
                           final: str | None) -> None:
    origin = home if home is not None else GeoPoint(lat=waypoints[0].x, lon=waypoints[0].y, alt=0.0)
    try:
        fence = Geofence(config, origin)
    except ValueError as e:
        raise _fail(src, "geoFence", str(e)) from None
    pts: list[tuple[str, tuple[float, float]]] = []
    if home is not None:
        pts.append(("home", (0.0, 0.0)))
    pts += [(w.id, w.to_local(origin)[:2]) for w in waypoints]
    if final == "rtl" and home is not None:
        pts.append(("home (return to launch)", (0.0, 0.0)))
    for label, (x, y) in pts:
        reason = fence.check_point(x, y)
        if reason:
            raise _fail(src, f"geofence: {label}", reason)
    for (la, a), (lb, b) in zip(pts, pts[1:]):
        reason = fence.check_segment(a, b)
        if reason:
            raise _fail(src, f"geofence: leg {la} -> {lb}", reason)


def plan_to_navigation(plan: MissionPlan, home: GeoPoint | None = None, **kwargs: Any) -> AeroNavigation:
    """``plan_to_flight(plan, home, **kwargs).navigation``: the waypoints only (the terminal land/RTL action and
    the geofence are in :func:`plan_to_flight`'s result)."""
    return plan_to_flight(plan, home, **kwargs).navigation


def navigation_to_plan(nav: AeroNavigation, home: GeoPoint, final_action: Literal["land", "rtl", "hover"] = "land",
                       geofence: GeofenceConfig | None = None, *, takeoff_altitude: float | None = None) -> MissionPlan:
    """Turn an AeroDaaS navigation into a mission plan (for :func:`save_plan` / :func:`save_wpl`).

    Waypoints become ``MAV_CMD_NAV_WAYPOINT`` (16) items in ``MAV_FRAME_GLOBAL_RELATIVE_ALT`` (3): relative
    waypoints (ENU metres from ``home``) are converted to latitude/longitude with pymap3d, absolute ones are
    used as they are; ``z`` is the altitude above home (m), ``hover_duration`` the hold time (param1),
    ``acceptance_radius`` param2. A change of ``speed`` emits ``MAV_CMD_DO_CHANGE_SPEED`` (178, ground speed,
    -2 back to the default). ``takeoff_altitude`` (m above home) prepends a ``MAV_CMD_NAV_TAKEOFF`` (22) at
    home. ``final_action`` appends ``MAV_CMD_NAV_LAND`` (21) at the last waypoint, ``MAV_CMD_NAV_RETURN_TO_LAUNCH``
    (20) or nothing (``"hover"``); a land / rtl action command ending the navigation takes its place. The
    order is the navigation's order (an UNORDERED navigation is exported as given). Velocity commands have no
    mission equivalent and raise :class:`MissionFileError`."""
    if final_action not in ("land", "rtl", "hover"):
        raise ValueError(f"final_action must be 'land', 'rtl' or 'hover', got {final_action!r}")
    items: list[MissionItem] = []

    def add(command: int, frame: int, params: list[float | None]) -> None:
        items.append(MissionItem(seq=len(items) + 1, command=command, frame=frame, params=params))

    speed: float | None = None
    last: tuple[float | None, float | None] = (None, None)  # NAV_LAND with NaN position lands where it is
    if takeoff_altitude is not None:
        add(MAV_CMD_NAV_TAKEOFF, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, None, home.lat, home.lon, takeoff_altitude])
        last = (home.lat, home.lon)
    terminal: str | None = None
    for n, cmd in enumerate(nav.waypoints):
        if isinstance(cmd, VelocityCommand):
            raise MissionFileError(f"navigation {nav.name!r}: velocity command {cmd.id!r} has no mission-file "
                                   "equivalent (only waypoints can be exported)")
        if not isinstance(cmd, Waypoint):
            action = getattr(cmd, "action", None)  # a terminal land / rtl action command
            if action not in ("land", "rtl"):
                raise MissionFileError(f"navigation {nav.name!r}: item {getattr(cmd, 'id', n)!r} "
                                       f"({type(cmd).__name__}) has no mission-file equivalent")
            if n != len(nav.waypoints) - 1:
                raise MissionFileError(f"navigation {nav.name!r}: {action} action {cmd.id!r} ends the flight, so "
                                       f"the following item {getattr(nav.waypoints[n + 1], 'id', n + 1)!r} would "
                                       "never run")
            terminal = action
            break
        if cmd.speed != speed:
            add(MAV_CMD_DO_CHANGE_SPEED, MAV_FRAME_MISSION, [1, -2 if cmd.speed is None else cmd.speed, -1, 0, 0, 0, 0])
            speed = cmd.speed
        if cmd.waypoint_type == "absolute":
            lat, lon = cmd.x, cmd.y
        else:
            g = enu_to_geodetic(cmd.x, cmd.y, 0.0, home)
            lat, lon = g.lat, g.lon
        add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT,
            [cmd.hover_duration, cmd.acceptance_radius, 0, None, lat, lon, cmd.z])
        last = (lat, lon)
    final_action = terminal or final_action
    if final_action == "land":
        add(MAV_CMD_NAV_LAND, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, None, last[0], last[1], 0])
    elif final_action == "rtl":
        add(MAV_CMD_NAV_RETURN_TO_LAUNCH, MAV_FRAME_MISSION, [0, 0, 0, 0, 0, 0, 0])
    return MissionPlan(home=home, items=items, geofence=geofence or GeofenceConfig())
