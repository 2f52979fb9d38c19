"""A mission file sent to a vehicle as written: the frame of a command without a position set to
``MAV_FRAME_MISSION`` (:func:`mission_frames`), the speeds an explicit limit caps (:func:`cap_speeds`), each change
said, and what the vehicle stored compared with what was sent (:func:`mission_differences`).

``aerodaas mission upload`` (:mod:`aerodaas.commands.mission`) uses all three. What is compared is what the
autopilots document storing: the command; the parameters the flight depends on (:data:`FLIGHT_PARAMS`); for a
command with a position (:data:`~aerodaas.missionfile.commands.POSITION_COMMANDS`) its latitude, longitude,
altitude and frame. Autopilots keep less than a mission item can say. ArduPilot
(``libraries/AP_Mission/AP_Mission.cpp``) keeps a location and its frame only for the commands of
``AP_Mission::stored_in_location``; ``mission_cmd_to_mavlink_int`` returns every other command with frame 0 and
x/y/z 0 (a Mission Planner file's DO_CHANGE_SPEED or RTL in frame 3 reads back in frame 0), and of a
``MAV_CMD_NAV_WAYPOINT`` ArduCopter keeps only the hold time (``mavlink_int_to_mission_cmd``: ``cmd.p1 =
packet.param1``; acceptance radius, pass radius and yaw read back as 0). PX4 (``src/modules/mavlink/
mavlink_mission.cpp``, ``MavlinkMissionManager::parse_mavlink_mission_item`` / ``format_mavlink_mission_item``,
the navigator's dataman mission storage) keeps a position command's frame, position, hold time, acceptance radius
and yaw, takes a command without a position only in ``MAV_FRAME_MISSION`` and returns its seven params as sent.
Fields a vehicle does not keep are reported, not hidden; a changed command, position, altitude, frame of a
position, hold time or speed is a different flight. ArduPilot stores an altitude in whole centimetres and ArduCopter
a hold time in whole seconds (``cmd.content.location.alt = packet.z * 100.0f``, ``cmd.p1 = packet.param1``, both
integers): told which autopilot stored the mission, a value kept at that precision is reported, not a different
flight.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Sequence

from aerodaas.missionfile._common import _fail
from aerodaas.missionfile.commands import (MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_LAND, MAV_CMD_NAV_LOITER_TIME,
                                           MAV_CMD_NAV_LOITER_UNLIM, MAV_CMD_NAV_RETURN_TO_LAUNCH,
                                           MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT, MAV_FRAME_MISSION,
                                           POSITION_COMMANDS, _RELATIVE_FRAMES, frame_name)
from aerodaas.missionfile.items import MissionItem, float32

__all__ = ["ItemDifference", "mission_differences", "ardupilot_stored_altitude", "ardupilot_stored_seconds",
           "FLIGHT_PARAMS", "FrameChange", "mission_frames", "SpeedChange",
           "cap_speeds", "check_relative_altitudes"]

#: a frame and its ``_INT`` twin (common.xml: the same meaning, x/y as integers on the wire)
_FRAME_ALIAS = {5: 0, 6: 3, 11: 10}
_FIELDS = ("param1", "param2", "param3", "param4", "x", "y", "z")

#: For each command AeroDaaS flies from a file, the params (0-based: 0 is param1) that change the flight and that
#: both autopilots store as sent: a waypoint's and a loiter's hold time (param1: ArduCopter ``cmd.p1``, PX4
#: ``time_inside``), DO_CHANGE_SPEED's speed type and speed (param1, param2: ArduPilot ``speed_type``/``target_ms``,
#: PX4 the params as sent). Take-off, land, return to launch and unlimited loiter have none a copter flies by
#: (pitch, abort altitude, yaw: ArduCopter keeps none of them). Any other command: all four.
FLIGHT_PARAMS: dict[int, frozenset[int]] = {
    MAV_CMD_NAV_WAYPOINT: frozenset({0}), MAV_CMD_NAV_LOITER_TIME: frozenset({0}),
    MAV_CMD_DO_CHANGE_SPEED: frozenset({0, 1}), MAV_CMD_NAV_TAKEOFF: frozenset(), MAV_CMD_NAV_LAND: frozenset(),
    MAV_CMD_NAV_RETURN_TO_LAUNCH: frozenset(), MAV_CMD_NAV_LOITER_UNLIM: frozenset(),
}
_ALL_PARAMS = frozenset({0, 1, 2, 3})


class ItemDifference(NamedTuple):
    """One field the vehicle stored differently: ``index`` (1-based position in the mission), ``item`` (the sent
    item's description), ``field`` (``command``, ``frame``, ``param1``..``param4``, ``latitude``, ``longitude``,
    ``altitude``, ``x``/``y``/``z`` of a command without a position, or ``count``), the ``sent`` and ``stored``
    values (None: unset/NaN) and whether it changes the flight (``flight``: command, the frame, position or
    altitude of a command with a position, a param of :data:`FLIGHT_PARAMS`, the number of items)."""

    index: int
    item: str
    field: str
    sent: float | int | None
    stored: float | int | None
    flight: bool
    #: the autopilot's documented storage of the field when the stored value is the sent one at that precision
    #: (e.g. "ArduPilot keeps an altitude in whole centimetres"); None: a field the vehicle does not keep, or a
    #: different value
    precision: str | None = None

    def __str__(self) -> str:
        def show(v):
            return "unset" if v is None else f"{v:g}" if isinstance(v, float) else str(v)

        return f"{self.item}: {self.field} {show(self.sent)} sent, {show(self.stored)} stored"

    def explained(self) -> str:
        """The difference with why the vehicle holds it: its :attr:`precision`, else "a field it does not keep"
        (for a difference that does not change the flight)."""
        return f"{self} ({self.precision or 'a field it does not keep'})"


def _same(a: float | None, b: float | None, abs_tol: float, rel_tol: float = 0.0) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return math.isclose(a, b, rel_tol=rel_tol, abs_tol=abs_tol)


#: the commands whose param1 ArduCopter keeps as a whole number of seconds (``AP_Mission::mavlink_int_to_mission_cmd``:
#: ``cmd.p1 = packet.param1``, a uint16: NAV_WAYPOINT's hold time, NAV_LOITER_TIME's loiter time)
_ARDUPILOT_WHOLE_SECONDS = frozenset({MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME})


def ardupilot_stored_altitude(z_m: float) -> float:
    """The altitude (m) ArduPilot stores for ``z_m`` sent with a position: whole centimetres, truncated toward zero
    (``AP_Mission::mavlink_int_to_mission_cmd``: ``cmd.content.location.alt = packet.z * 100.0f``, an int32, in
    float32 arithmetic), read back as ``alt * 0.01f`` (``mission_cmd_to_mavlink_int``). Source:
    ``libraries/AP_Mission/AP_Mission.cpp``."""
    return math.trunc(float32(float32(z_m) * 100.0)) / 100.0


def ardupilot_stored_seconds(p: float) -> float:
    """The hold or loiter time (s) ArduCopter stores for ``p`` sent as param1 of NAV_WAYPOINT or NAV_LOITER_TIME:
    whole seconds, truncated (a uint16, ``cmd.p1 = packet.param1``; ``libraries/AP_Mission/AP_Mission.cpp``). A value
    outside 0..65535 is returned unchanged (the conversion is undefined there: compared as sent)."""
    return float(math.trunc(p)) if 0.0 <= p < 65536.0 else p


def _float32_degrees_tolerance(v: float) -> float:
    """How far a latitude/longitude (degrees) carried as float32 (MISSION_ITEM) may read back from the one sent on
    the 1e-7 degree grid: two float32 steps at ``v`` (the vehicle's own conversion of its int32 to float, e.g.
    ArduPilot's ``lat * 1.0e-7f`` in float32, rounds twice) and the grid's half step."""
    return 2.0 * math.ulp(abs(v)) * 2.0 ** 29 + 0.6e-7  # a float32 step: the double's ulp times 2**(52 - 23)


def mission_differences(sent: Sequence[MissionItem], stored: Sequence[MissionItem], *, autopilot: str | None = None,
                        float_positions: bool = False) -> list[ItemDifference]:
    """What the vehicle's mission (``stored``: a download, ArduPilot's home item left out) holds differently from
    ``sent`` (the items as uploaded: latitude/longitude on the 1e-7 degree grid, params as float32). Compared per
    item: the command; params (float32 tolerance; a 0 stored for an unset param is a difference), a difference
    changing the flight for the params of :data:`FLIGHT_PARAMS`; for a command of
    :data:`~aerodaas.missionfile.commands.POSITION_COMMANDS` the frame (a frame equals its ``_INT`` twin),
    latitude/longitude (within 0.6e-7 degree; ``float_positions``: read back as float32 degrees, MISSION_ITEM,
    within two float32 steps more) and altitude (1 mm). A command without a position has no frame and no position
    to keep (ArduPilot returns frame 0, x/y/z 0): its frame is not compared, its x/y/z only as fields it does not
    keep. A different number of items is one ``count`` difference (the items are then compared as far as both go).

    ``autopilot`` ``"ardupilot"``: a value stored at ArduPilot's own precision is a difference that does not change
    the flight, with its :attr:`ItemDifference.precision` said: an altitude in whole centimetres
    (:func:`ardupilot_stored_altitude`), a waypoint's hold time and a loiter time in whole seconds
    (:func:`ardupilot_stored_seconds`); any other value there is still a different flight."""
    out: list[ItemDifference] = []
    ardupilot = autopilot == "ardupilot"
    if len(sent) != len(stored):
        out.append(ItemDifference(0, "mission", "count", len(sent), len(stored), True))
    for k, (a, b) in enumerate(zip(sent, stored), start=1):
        tag = a.describe().replace(f"item {a.seq} ", f"item {k} ")
        if a.command != b.command:
            out.append(ItemDifference(k, tag, "command", a.command, b.command, True))
            continue
        positional = a.command in POSITION_COMMANDS
        if positional and _FRAME_ALIAS.get(a.frame, a.frame) != _FRAME_ALIAS.get(b.frame, b.frame):
            out.append(ItemDifference(k, tag, "frame", a.frame, b.frame, True))
        flight_params = FLIGHT_PARAMS.get(a.command, _ALL_PARAMS)
        for i, name in enumerate(_FIELDS):
            pa, pb = a.params[i], b.params[i]
            if i in (4, 5) and positional:
                tol = _float32_degrees_tolerance(pa) if float_positions and pa is not None else 0.6e-7
                if not _same(pa, pb, tol):
                    out.append(ItemDifference(k, tag, "latitude" if i == 4 else "longitude", pa, pb, True))
            elif i == 6 and positional:
                if _same(pa, pb, 1e-3, rel_tol=1e-6):
                    continue
                if ardupilot and pa is not None and _same(ardupilot_stored_altitude(pa), pb, 1e-3, rel_tol=1e-6):
                    out.append(ItemDifference(k, tag, "altitude", pa, pb, False,
                                              "ArduPilot keeps an altitude in whole centimetres"))
                else:
                    out.append(ItemDifference(k, tag, "altitude", pa, pb, True))
            elif not _same(pa, pb, 1e-6, rel_tol=1e-6):  # float32 on the wire
                if (ardupilot and i == 0 and a.command in _ARDUPILOT_WHOLE_SECONDS and pa is not None
                        and _same(ardupilot_stored_seconds(pa), pb, 1e-6)):
                    out.append(ItemDifference(k, tag, name, pa, pb, False,
                                              "ArduCopter keeps this time in whole seconds"))
                else:
                    out.append(ItemDifference(k, tag, name, pa, pb, i in flight_params))
    return out


class FrameChange(NamedTuple):
    """What :func:`mission_frames` did to one item: ``index`` (1-based), ``item`` (description), the frame ``was``
    (as written) and ``now`` (sent)."""

    index: int
    item: str
    was: int
    now: int

    def __str__(self) -> str:
        return (f"{self.item}: frame {frame_name(self.was)} sent as {frame_name(self.now)} (the command has no "
                f"position; PX4 refuses it in a global frame, ArduPilot stores no frame for it)")


def mission_frames(items: Sequence[MissionItem]) -> tuple[list[MissionItem], list[FrameChange]]:
    """``items`` with every command without a position (not in
    :data:`~aerodaas.missionfile.commands.POSITION_COMMANDS`: DO_CHANGE_SPEED, NAV_RETURN_TO_LAUNCH ...) in
    ``MAV_FRAME_MISSION`` (2), as QGroundControl sends them. Mission Planner writes such items in the frame of
    the mission (``QGC WPL 110`` rows in frame 3); PX4 answers those with ``MAV_MISSION_UNSUPPORTED``
    (``MavlinkMissionManager::parse_mavlink_mission_item`` takes them only in ``MAV_FRAME_MISSION``) and
    ArduPilot keeps no frame for them (``AP_Mission::stored_in_location``). Their params, x, y and z are kept.
    Returns the items and one :class:`FrameChange` per item changed."""
    out: list[MissionItem] = []
    changes: list[FrameChange] = []
    for k, it in enumerate(items, start=1):
        if it.command not in POSITION_COMMANDS and it.frame != MAV_FRAME_MISSION:
            changes.append(FrameChange(k, it.describe().replace(f"item {it.seq} ", f"item {k} "), it.frame,
                                       MAV_FRAME_MISSION))
            it = it.model_copy(update={"frame": MAV_FRAME_MISSION})
        out.append(it)
    return out, changes


class SpeedChange(NamedTuple):
    """What :func:`cap_speeds` did to one item: ``index`` (1-based position in the items it returned), ``item``
    (description), ``was`` (m/s as written; None: an item inserted) and ``now`` (m/s sent), ``why``."""

    index: int
    item: str
    was: float | None
    now: float
    why: str

    def __str__(self) -> str:
        if self.was is None:
            return f"{self.item} inserted: DO_CHANGE_SPEED {self.now:g} m/s ({self.why})"
        if self.was == -2:
            return f"{self.item}: DO_CHANGE_SPEED -2 (the vehicle's default) set to {self.now:g} m/s ({self.why})"
        return f"{self.item}: DO_CHANGE_SPEED {self.was:g} m/s capped to {self.now:g} m/s ({self.why})"


def cap_speeds(items: Sequence[MissionItem], max_speed: float,
               cruise_speed: float | None) -> tuple[list[MissionItem], list[SpeedChange]]:
    """``items`` with every ``MAV_CMD_DO_CHANGE_SPEED`` (178) above ``max_speed`` m/s lowered to it, and one
    ``DO_CHANGE_SPEED`` ground speed ``max_speed`` inserted (after a leading ``NAV_TAKEOFF``) when the flight would
    otherwise start at the vehicle's own cruise speed ``cruise_speed`` m/s above the cap (None: unknown, inserted
    too); a ``-2`` ("the vehicle's default") becomes the cap when that default is above it. Returns the items,
    renumbered from 1, and one :class:`SpeedChange` per item changed or inserted. ``param2`` -1 ("no change") and
    speeds within the cap are kept as written."""
    out: list[MissionItem] = []
    changes: list[SpeedChange] = []
    why = f"--max-speed {max_speed:g} m/s"
    default_too_fast = cruise_speed is None or cruise_speed > max_speed + 1e-6
    insert_at = 1 if items and items[0].command == MAV_CMD_NAV_TAKEOFF else 0
    speed_set_before_flight = any(it.command == MAV_CMD_DO_CHANGE_SPEED for it in items[:insert_at + 1])
    for k, it in enumerate(items):
        if k == insert_at and default_too_fast and not speed_set_before_flight:
            out.append(MissionItem(seq=0, command=MAV_CMD_DO_CHANGE_SPEED, frame=MAV_FRAME_MISSION,
                                   params=[1.0, max_speed, -1.0, 0.0, 0.0, 0.0, 0.0]))
            cruise = "unknown" if cruise_speed is None else f"{cruise_speed:g} m/s"
            changes.append(SpeedChange(len(out), f"before item {k + 1}", None, max_speed,
                                       f"{why}; the vehicle's own cruise speed is {cruise}"))
        new = it
        if it.command == MAV_CMD_DO_CHANGE_SPEED and it.params[1] is not None:
            v = it.params[1]
            if v > max_speed + 1e-6 or (v == -2 and default_too_fast):
                new = it.model_copy(update={"params": [it.params[0], max_speed, *it.params[2:]]})
                changes.append(SpeedChange(len(out) + 1, it.describe(), v, max_speed, why))
        out.append(new)
    return [m.model_copy(update={"seq": k}) for k, m in enumerate(out, start=1)], changes


def check_relative_altitudes(plan, max_altitude: float) -> None:
    """The altitude bound that needs no home, checked before connecting to the vehicle: items in a home-relative
    frame (``MAV_FRAME_GLOBAL_RELATIVE_ALT`` 3 / ``_INT`` 6) and rally points (home-relative in a ``.plan``) higher
    than ``max_altitude`` metres raise :class:`~aerodaas.missionfile.MissionFileError` naming the file and the item,
    as :func:`~aerodaas.missionfile.plan_to_flight` does. AMSL items and every distance are checked once the vehicle's
    home is known."""
    src = plan.source or "<plan>"
    for it in plan.expanded_items():
        z = it.params[6]
        if it.frame in _RELATIVE_FRAMES and z is not None and z > max_altitude:
            raise _fail(src, it.describe(), f"altitude {z:g} m above home is above max_altitude {max_altitude:g} m")
    for k, (lat, lon, alt) in enumerate(plan.rally_points):
        if alt > max_altitude:
            raise _fail(src, f"rally point {k + 1} ({lat:.7f}, {lon:.7f})",
                        f"altitude {alt:g} m above home is above max_altitude {max_altitude:g} m")
