"""Mission plans and AeroDaaS navigation: :func:`plan_to_flight` (a plan -> the ordered absolute waypoints, terminal
action and geofence a drone flies; :func:`plan_to_navigation` for the waypoints alone) and
:func:`navigation_to_plan` (the other way, for export)."""
from __future__ import annotations

from collections import Counter
from itertools import islice
import math

from pathlib import Path
from typing import Any, Iterable, Literal

from pydantic import ValidationError

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.navigation.geofence import Geofence, GeofenceConfig
from aerodaas.model.types import AeroNavigation, GeoPoint, NavigationType, SchedulingType, VelocityCommand, Waypoint
from aerodaas.missionfile._common import MissionFileError, _fail, _first_error
from aerodaas.missionfile.commands import (_AMSL_FRAMES, _FLIGHT_COMMANDS, _RELATIVE_FRAMES, _TERRAIN_FRAMES, MAV_CMD_DO_CHANGE_SPEED,
                       MAV_CMD_NAV_LAND, MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LOITER_UNLIM,
                       MAV_CMD_NAV_RETURN_TO_LAUNCH, MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT,
                       MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_MISSION, PAYLOAD_COMMANDS, command_name, frame_name)
from aerodaas.missionfile.expand import expand_items
from aerodaas.missionfile.items import MissionItem
from aerodaas.missionfile.plans import FlightPlan, MissionPlan


def _latlon_missing(lat: float | None, lon: float | None) -> bool:
    return lat is None or lon is None or (lat == 0.0 and lon == 0.0)


def ground_distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance in metres (haversine, mean Earth radius 6,371,008.8 m: IUGG)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2
    return 2.0 * 6_371_008.8 * math.asin(min(1.0, math.sqrt(a)))


def _check_bounds(src: str, tag: str, lat: float, lon: float, z: float, home: GeoPoint | None,
                  max_altitude: float | None, max_distance: float | None) -> None:
    """Raise MissionFileError (naming ``src`` and ``tag``) when ``z`` (metres above home) is above ``max_altitude``
    or (``lat``, ``lon``) (degrees) is farther than ``max_distance`` metres from ``home``; None skips a check."""
    if max_altitude is not None and z > max_altitude:
        raise _fail(src, tag, f"altitude {z:g} m above home is above max_altitude {max_altitude:g} m")
    if max_distance is not None and home is not None:
        d = ground_distance_m(home.lat, home.lon, lat, lon)
        if d > max_distance:
            raise _fail(src, tag, f"({lat:.7f}, {lon:.7f}) is {d:.0f} m from home, beyond max_distance "
                                  f"{max_distance:g} m")


def plan_to_flight(plan: MissionPlan, home: GeoPoint | None = None, *, skip_commands: Iterable[int] = (),
                   check_geofence: bool = True, min_altitude: float | None = 0.0, max_altitude: float | None = None,
                   max_distance: float | None = None) -> FlightPlan:
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
    was meant relative) raises too; ``None`` disables that check. So does a waypoint or rally point higher than
    ``max_altitude`` metres above home, or (with a home) farther than ``max_distance`` metres from it horizontally
    (great-circle distance, mean Earth radius); ``None`` (default) disables those checks. With ``check_geofence`` every waypoint
    and leg (from home, and back to home for RTL) must satisfy the plan's geofence."""
    src = plan.source or "<plan>"
    skip = frozenset(int(c) for c in skip_commands)
    clash = skip & _FLIGHT_COMMANDS
    if clash:
        raise ValueError(f"skip_commands may not contain commands plan_to_flight flies: "
                         f"{', '.join(command_name(c) for c in sorted(clash))}")
    home = home if home is not None else plan.home
    items = expand_items(plan)
    fb = _FlightBuilder(src, home, skip, min_altitude, max_altitude, max_distance)
    for k, item in enumerate(items):
        fb.item(item, islice(items, k + 1, None))  # lazily: a slice per item copies the rest (quadratic)

    for k, (lat, lon, alt) in enumerate(plan.rally_points):  # the autopilot's RTL may fly to them
        _check_bounds(src, f"rally point {k + 1}", lat, lon, alt, home, max_altitude, max_distance)
    waypoints = fb.waypoints
    dup = sorted(i for i, n in Counter(w.id for w in waypoints).items() if n > 1)  # linear (ids.count was quadratic)
    if dup:
        raise _fail(src, "items", f"duplicate sequence numbers give duplicate waypoint ids {dup}")
    if check_geofence and not plan.geofence.is_empty and waypoints:
        _check_flight_geofence(src, plan.geofence, home, waypoints, fb.final)
    name = Path(plan.source).stem if plan.source else "mission"
    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.ORDERED, name=name)
    return FlightPlan(navigation=nav, final_action=fb.final or "hover", geofence=plan.geofence, home=home,
                      skipped=fb.skipped)


class _FlightBuilder:
    """:func:`plan_to_flight`'s walk over the mission items, one at a time (:meth:`item`), with what it collects:
    the waypoints, the skipped items, the final action and the item that ended the mission, the speed in force
    (m/s; None: the default) and the previous waypoint's latitude, longitude and altitude above home (m). Errors
    are :class:`MissionFileError` naming the file ``src`` and the item."""

    def __init__(self, src: str, home: GeoPoint | None, skip: frozenset[int], min_altitude: float | None,
                 max_altitude: float | None, max_distance: float | None) -> None:
        self.src, self.home, self.skip = src, home, skip
        self.min_altitude, self.max_altitude, self.max_distance = min_altitude, max_altitude, max_distance
        self.waypoints: list[Waypoint] = []
        self.skipped: list[str] = []
        self.final: str | None = None
        self.terminal: MissionItem | None = None
        self.speed: float | None = None
        self.last: tuple[float, float, float] | None = None

    def item(self, item: MissionItem, rest: Iterable[MissionItem]) -> None:
        """Take one item (``rest``: the items after it, read only when needed)."""
        tag, cmd = item.describe(), item.command
        if cmd in self.skip:
            self.skipped.append(f"{tag} skipped")
            return
        if self.terminal is not None:
            raise _fail(self.src, tag, f"comes after the terminal {self.terminal.describe()} and would never run")
        if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LOITER_UNLIM):
            self._position_item(item, tag, rest)
        elif cmd == MAV_CMD_NAV_LAND:
            self._land(item, tag)
        elif cmd == MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self.final, self.terminal = "rtl", item
        elif cmd == MAV_CMD_DO_CHANGE_SPEED:
            self._change_speed(item, tag)
        else:
            hint = " (pass skip_commands=PAYLOAD_COMMANDS to skip camera/gimbal commands)" \
                if cmd in PAYLOAD_COMMANDS else ""
            raise _fail(self.src, tag, f"{command_name(cmd)} is not supported by AeroDaaS navigation{hint}")

    def _altitude(self, item: MissionItem, tag: str) -> float:
        """The item's altitude above home (m), from a relative or an AMSL frame."""
        src, z = self.src, item.params[6]
        if item.frame in _TERRAIN_FRAMES:
            raise _fail(src, tag, f"{frame_name(item.frame)} altitudes are above terrain; AeroDaaS has no "
                                  "terrain model")
        if item.frame not in _AMSL_FRAMES and item.frame not in _RELATIVE_FRAMES:
            raise _fail(src, tag, f"{frame_name(item.frame)} carries no global position")
        if z is None:
            raise _fail(src, tag, "altitude (z) is not set")
        if item.frame in _RELATIVE_FRAMES:
            return z
        if self.home is None:
            raise _fail(src, tag, f"{frame_name(item.frame)} altitude {z:g} m is above mean sea level; converting "
                                  "it to altitude above home needs the home position (plan has none; pass home=)")
        return z - self.home.alt

    def _add_waypoint(self, item: MissionItem, tag: str, lat: float, lon: float, z: float, hover: float = 0.0,
                      radius: float | None = None, wp_id: str | None = None) -> None:
        home, min_altitude = self.home, self.min_altitude
        if min_altitude is not None and z < min_altitude:
            raise _fail(self.src, tag, f"altitude {z:g} m above home is below min_altitude {min_altitude:g} m "
                                       f"({frame_name(item.frame)}, z={item.params[6]!r}"
                                       f"{f', home altitude {home.alt:g} m AMSL' if home is not None else ''})")
        _check_bounds(self.src, tag, lat, lon, z, home, self.max_altitude, self.max_distance)
        kwargs: dict[str, Any] = {}
        if radius is not None and radius > 0:
            kwargs["acceptance_radius"] = radius
        try:
            self.waypoints.append(Waypoint(id=wp_id or f"item{item.seq}", x=lat, y=lon, z=z, hover_duration=hover,
                                           waypoint_type="absolute", speed=self.speed, **kwargs))
        except ValidationError as e:
            raise _fail(self.src, tag, _first_error(e)) from None
        self.last = (lat, lon, z)

    def _position_item(self, item: MissionItem, tag: str, rest: Iterable[MissionItem]) -> None:
        """NAV_WAYPOINT, NAV_TAKEOFF, NAV_LOITER_TIME, NAV_LOITER_UNLIM: a waypoint."""
        src, cmd, p = self.src, item.command, item.params
        lat, lon = p[4], p[5]
        if _latlon_missing(lat, lon):
            if cmd == MAV_CMD_NAV_WAYPOINT:
                raise _fail(src, tag, f"latitude/longitude not set (x={lat!r}, y={lon!r})")
            if cmd != MAV_CMD_NAV_TAKEOFF and self.last is not None:
                lat, lon = self.last[0], self.last[1]  # loiter at the current position
            elif self.home is not None:
                lat, lon = self.home.lat, self.home.lon
            else:
                raise _fail(src, tag, "has no latitude/longitude, so it acts at the vehicle's current (home) "
                                      "position, which is unknown (plan has no home; pass home=)")
        z = self._altitude(item, tag)
        hover, radius = 0.0, None
        if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME):
            hover = p[0] or 0.0
            if hover < 0:
                raise _fail(src, tag, f"param1 (hold/loiter time) must be >= 0 s, got {hover!r}")
        if cmd == MAV_CMD_NAV_WAYPOINT:
            radius = p[1]
        if cmd == MAV_CMD_NAV_LOITER_UNLIM:
            after = next((it for it in rest if it.command not in self.skip), None)
            if after is not None:
                raise _fail(src, tag, f"loiters forever, so the following {after.describe()} would never run")
            self.final = "hover"
        self._add_waypoint(item, tag, lat, lon, z, hover, radius)

    def _land(self, item: MissionItem, tag: str) -> None:
        """NAV_LAND: the final action, after a transit waypoint at the previous altitude if it lands elsewhere."""
        lat, lon = item.params[4], item.params[5]
        last, home = self.last, self.home
        if item.frame != MAV_FRAME_MISSION and not _latlon_missing(lat, lon):
            here = last[:2] if last is not None else (home.lat, home.lon) if home is not None else None
            if here is None or abs(lat - here[0]) > 1e-7 or abs(lon - here[1]) > 1e-7:
                if last is None:
                    raise _fail(self.src, tag, f"lands at ({lat}, {lon}) before any waypoint gave an altitude to "
                                               "fly there at; add a takeoff or waypoint first")
                self._add_waypoint(item, tag, lat, lon, last[2], wp_id=f"item{item.seq}_approach")
        self.final, self.terminal = "land", item

    def _change_speed(self, item: MissionItem, tag: str) -> None:
        """DO_CHANGE_SPEED: the speed of the following waypoints."""
        kind, value = item.params[0], item.params[1]
        if kind not in (0.0, 1.0, None):
            raise _fail(self.src, tag, f"param1 speed type {kind!r} (climb/descent speed) is not supported; only "
                                       "0 (airspeed) and 1 (ground speed)")
        if value is None or value == -1:
            pass
        elif value == -2:
            self.speed = None
        elif value > 0:
            self.speed = value
        else:
            raise _fail(self.src, tag, f"param2 speed must be > 0 m/s, -1 (no change) or -2 (default), "
                                       f"got {value!r}")


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
