"""The mission protocol (mavlink.io mission microservice): upload, download, clear and start, in the INT form."""
from __future__ import annotations

from typing import Any, Literal


from aerodaas.model.geo import geodetic_to_enu
from aerodaas.missionfile import MissionItem, MissionPlan, expand_items, navigation_to_plan
from aerodaas.model.types import ActionCommand, AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.backends.mavlink._common import M, _f32, _GLOBAL_FRAMES
from aerodaas.backends.mavlink.transfer import MissionTransfer


#: MAV_FRAME_GLOBAL_RELATIVE_ALT and its _INT twin: altitudes above home
_RELATIVE_FRAMES = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
#: horizontal metres from a mission waypoint at which the vehicle counts as arrived (its hold begins), at most
_ARRIVAL_RADIUS_M = 0.5


class MissionMixin:
    """Part of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see its docstring for the shared state)."""

    # ------------------------------------------------------------------ missions
    def _mission_items(self, mission: Any, takeoff_altitude: float | None,
                       final_action: str) -> tuple[list[MissionItem], bool]:
        """The items to upload, and whether we built them from waypoints (True) rather than being given items."""
        nav = None
        if isinstance(mission, MissionPlan):
            items = expand_items(mission)
        else:
            if isinstance(mission, AeroNavigation):
                nav = mission
            else:
                seq = list(mission)
                if seq and all(isinstance(i, MissionItem) for i in seq):
                    items = seq
                    nav = None
                elif all(isinstance(i, (Waypoint, ActionCommand)) for i in seq):
                    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, seq, SchedulingType.ORDERED)
                else:
                    bad = next(i for i in seq if not isinstance(i, (Waypoint, ActionCommand, MissionItem)))
                    raise TypeError(f"upload_mission: items must all be Waypoint/ActionCommand or all MissionItem, "
                                    f"got {type(bad).__name__}")
            if nav is not None:
                items = navigation_to_plan(nav, self.home, final_action, takeoff_altitude=takeoff_altitude).items
        for it in items:
            if it.is_complex:
                raise ValueError(f"upload_mission: {it.describe()} must be expanded first (pass the MissionPlan)")
        return items, nav is not None

    def upload_mission(self, mission: Any, *, takeoff_altitude: float | None = None,
                       final_action: Literal["land", "rtl", "hover"] = "hover") -> list[MissionItem]:
        """Upload a mission with the MISSION_ITEM_INT protocol (MISSION_COUNT, answering each MISSION_REQUEST_INT
        / MISSION_REQUEST, until MISSION_ACK).

        ``mission``: a list of :class:`~aerodaas.model.types.Waypoint` (ENU relative to :attr:`home`, or absolute) and
        optionally a final land/rtl :class:`~aerodaas.model.types.ActionCommand`, an :class:`AeroNavigation`, a
        :class:`~aerodaas.missionfile.MissionPlan` (e.g. an imported ``.plan``; ComplexItems expanded) or a list
        of :class:`~aerodaas.missionfile.MissionItem`. Waypoints become MAV_CMD_NAV_WAYPOINT items
        (``navigation_to_plan``: ``takeoff_altitude`` m prepends a NAV_TAKEOFF, ``final_action`` appends
        NAV_LAND / NAV_RETURN_TO_LAUNCH). ArduPilot gets its home placeholder at sequence 0. On PX4 the items built
        from waypoints carry absolute altitudes (MAV_FRAME_GLOBAL: the take-off point's AMSL altitude, fixed here
        while the vehicle stands on it, + the height), since PX4 keeps re-estimating the home altitude that
        MAV_FRAME_GLOBAL_RELATIVE_ALT refers to for minutes after take-off (``COM_HOME_EN``; commander
        ``HomePosition``); given mission items (a file) keep their frames and their speeds (DO_CHANGE_SPEED); the
        speeds of items built from waypoints are capped at the robot's limit.

        Returns the items as sent (``seq`` from 1; latitude/longitude rounded to 1e-7 degrees, params to float32),
        which :meth:`download_mission` returns unchanged. Raises CommandRefused (MAV_MISSION_RESULT name) when the
        autopilot rejects an item, BackendError after ``command_retries`` timeouts, LinkLost, TypeError/ValueError
        for bad input (nothing is sent then)."""
        items, built = self._mission_items(mission, takeoff_altitude, final_action)
        absolute = built and self.autopilot == "px4"
        if absolute and (self._alt_ref is None or not self._armed):
            self._fix_altitude_reference()  # the take-off point, where the vehicle stands now
            self._alt_ref_pinned = True  # arm() keeps it: the mission's altitudes are relative to it
        wire, sent_items = self._wire_items(items, built, absolute)
        self._check_link("mission upload")
        self.transfers.upload_mission(wire)
        self._remember_waypoints(wire)
        self._event("mission_uploaded", count=len(sent_items))
        return sent_items

    def _wire_items(self, items: list[MissionItem], built: bool,
                    absolute: bool) -> tuple[list[tuple], list[MissionItem]]:
        """The MISSION_ITEM_INT fields of ``items`` (frame, command, autocontinue, param1-4, x, y, z; ArduPilot's
        home placeholder first) and the items as sent (see :meth:`upload_mission`: ``built`` from waypoints, their
        speeds capped; ``absolute``: home-relative altitudes sent as AMSL above the take-off point)."""
        wire: list[tuple] = []
        sent_items: list[MissionItem] = []
        for k, it in enumerate(items):
            p = [_f32(v) for v in it.params[:4]]
            x, y = it.params[4], it.params[5]
            if it.frame in _GLOBAL_FRAMES:
                xi, yi = int(round((x or 0.0) * 1e7)), int(round((y or 0.0) * 1e7))
                xs, ys = xi / 1e7, yi / 1e7
            else:
                xi, yi = int(round(x or 0.0)), int(round(y or 0.0))
                xs, ys = float(xi), float(yi)
            z = _f32(it.params[6] if it.params[6] is not None else 0.0)
            frame = it.frame
            if absolute and frame in _RELATIVE_FRAMES:
                # PX4 resolves home-relative altitudes with a home it keeps re-estimating for minutes after
                # take-off (COM_HOME_EN): our own waypoints go up as AMSL altitudes above the take-off point
                frame, z = M.MAV_FRAME_GLOBAL, _f32(self._alt_ref + z)
            if it.command == M.MAV_CMD_DO_CHANGE_SPEED and built:
                # our own waypoints' speeds: never above the robot's limit (less any estimator margin measured in
                # flight), never -2 ("default": DENIED by ArduCopter): the limit instead. Given items (a mission
                # file) go up as written (``aerodaas mission upload --max-speed`` caps them itself, and says so)
                limit = self.xy_speed_cap()
                p[1] = _f32(limit if p[1] is None or (p[1] <= 0 and p[1] != -1) else min(p[1], limit))
            wire.append((frame, it.command, 1 if it.autocontinue else 0,
                         *[float("nan") if v is None else v for v in p], xi, yi, z))
            sent_items.append(MissionItem(seq=k + 1, command=it.command, frame=frame, params=[*p, xs, ys, z],
                                          autocontinue=it.autocontinue))
        if self.autopilot == "ardupilot":
            h = self.home
            wire.insert(0, (0, M.MAV_CMD_NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, 0.0, int(round(h.lat * 1e7)),
                            int(round(h.lon * 1e7)), float(h.alt)))
        return wire, sent_items

    def _remember_waypoints(self, wire: list[tuple]) -> None:
        """Keep each uploaded NAV_WAYPOINT's horizontal position (ENU metres from :attr:`home`) and acceptance
        radius by wire sequence number, for the arrival report (telemetry.py ``_check_arrival``)."""
        wps = {}
        first = 1 if self.autopilot == "ardupilot" else 0
        for seq, (frame, cmd, _auto, _p1, p2, _p3, _p4, xi, yi, _z) in enumerate(wire):
            if seq >= first and cmd == M.MAV_CMD_NAV_WAYPOINT and frame in _GLOBAL_FRAMES:
                e, n, _ = geodetic_to_enu(xi / 1e7, yi / 1e7, self.home.alt, self.home)
                radius = p2 if p2 is not None and p2 == p2 and p2 > 0 else _ARRIVAL_RADIUS_M
                wps[seq] = (float(e), float(n), min(float(radius), _ARRIVAL_RADIUS_M))
        with self._lock:
            self._mission_wire = wps
            self._mission_next = (frozenset(k for k, w in enumerate(wire) if w[2]), len(wire))
            self._current_inferred_from = -1
            self._arrived.clear()
            self._reached_fw.clear()

    def download_mission(self) -> MissionPlan:
        """Download the autopilot's mission (MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT for each
        item, answered with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM, whose float latitude/longitude
        degrees are rounded to the same 1e-7 degree grid; MISSION_ACK). Returns a
        :class:`~aerodaas.missionfile.MissionPlan` with ``home`` = the vehicle's home and ``items`` numbered from 1
        (ArduPilot's home item at sequence 0 is left out); turn it into waypoints with
        :func:`~aerodaas.missionfile.plan_to_flight`. Raises BackendError / LinkLost, CommandRefused (MISSION_ACK
        with an error)."""
        self._check_link("mission download")
        got = self.transfers.download_messages(0, "mission download")
        items = []
        first = 1 if self.autopilot == "ardupilot" else 0
        for seq in sorted(got):
            if seq < first:
                continue
            m = got[seq]
            if m.frame in _GLOBAL_FRAMES and m.get_type() == "MISSION_ITEM":  # float degrees (float32 on the wire)
                x, y = round(m.x * 1e7) / 1e7, round(m.y * 1e7) / 1e7
            elif m.frame in _GLOBAL_FRAMES:
                x, y = m.x / 1e7, m.y / 1e7
            else:
                x, y = float(m.x), float(m.y)
            items.append(MissionItem(seq=seq + 1 - first, command=m.command, frame=m.frame,
                                     params=[_f32(m.param1), _f32(m.param2), _f32(m.param3), _f32(m.param4), x, y,
                                             _f32(m.z)], autocontinue=bool(m.autocontinue)))
        return MissionPlan(home=self.home, items=items)

    def clear_mission(self) -> None:
        """MISSION_CLEAR_ALL; waits for MISSION_ACK. Raises CommandRefused / BackendError / LinkLost."""
        self.transfers.clear_mission()

    def start_mission(self) -> None:
        """Fly the uploaded mission: in the air switch to AUTO (ArduPilot) / MISSION (PX4); on the ground (armed)
        MAV_CMD_MISSION_START, which starts it from the first item (ArduPilot needs a NAV_TAKEOFF first; PX4
        takes off by itself). Progress arrives as ``mission_current`` / ``mission_item_reached`` events."""
        self._require_navigable("start_mission")
        self._stop_setpoints()
        self._in_control = True
        if self.in_air:
            self.set_mode("MISSION" if self.autopilot == "px4" else "AUTO")
        else:
            self.command_long("mission start", M.MAV_CMD_MISSION_START, 0, 0)

    def _init_mission(self) -> None:
        """The mission's state: its transfers (:class:`MissionTransfer`), the uploaded mission's wire items."""
        #: the mission protocol's transfers (transfer.py), talking to the link through what it is given
        self.transfers = MissionTransfer(self.robot_id, self.cfg, send=self._send, check_link=self._check_link,
                                         target=lambda: (self._sysid, self._compid),
                                         status_text_since=self._status_text_since, event=self._event,
                                         wire_version=lambda: getattr(self._conn.mav, "WIRE_PROTOCOL_VERSION", "2.0"))
        self._mission_wire: dict[int, tuple[float, float, float, int]] = {}  # wire seq -> (lat, lon, z, frame)
        #: wire seqs of our uploaded mission's autocontinue items, and its length (the next item after a reached one)
        self._mission_next: tuple[frozenset[int], int] = (frozenset(), 0)
        self._current_inferred_from = -1  # the reached item whose successor we took as current (telemetry.py)
