"""The mission protocol (mavlink.io mission microservice): upload, download, clear and start, in the INT form."""
from __future__ import annotations

import queue
import time
from typing import Any, Callable, Literal


from aerodaas.model.geo import geodetic_to_enu
from aerodaas.missionfile import MissionItem, MissionPlan, expand_items, navigation_to_plan
from aerodaas.model.types import ActionCommand, AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.backends.base import BackendError, CommandRefused
from aerodaas.backends.mavlink._common import M, _enum_name, _f32, _GLOBAL_FRAMES


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
        self._send_mission(wire)
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

    def _send_mission(self, wire: list[tuple]) -> None:
        """The upload transfer of the ``wire`` items (MISSION_COUNT, each item as the autopilot requests it, until
        its MISSION_ACK). Raises CommandRefused for a refusing MISSION_ACK."""
        n = len(wire)

        def send_item(seq: int, as_int: bool) -> None:
            # always MISSION_ITEM_INT, also to a MISSION_REQUEST (ArduPilot: "GCS should send MISSION_ITEM_INT";
            # the float MISSION_ITEM loses ~0.4 m of latitude/longitude in float32)
            frame, cmd, auto, p1, p2, p3, p4, xi, yi, z = wire[seq]
            self._send(lambda mav: mav.mission_item_int_send(self._sysid, self._compid, seq, frame, cmd, 0, auto,
                                                             p1, p2, p3, p4, xi, yi, z, 0))

        def resend(last: Any) -> None:
            if last is None:
                self._send(lambda mav: mav.mission_count_send(self._sysid, self._compid, n, 0))
            else:
                send_item(*last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if t in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and getattr(msg, "mission_type", 0) == 0:
                if 0 <= msg.seq < n:
                    state["last"] = (msg.seq, t == "MISSION_REQUEST_INT")
                    state["max"] = max(state["max"], msg.seq)
                    send_item(*state["last"])
                return False
            if t == "MISSION_ACK" and getattr(msg, "mission_type", 0) == 0:
                if msg.type == M.MAV_MISSION_INVALID_SEQUENCE and state["max"] < n - 1:
                    # ArduPilot answers an item that is not the one it asks for now (our answer to a request it
                    # had already repeated) with this ACK and goes on with the transfer (MissionItemProtocol::
                    # handle_mission_item); the next MISSION_REQUEST follows
                    self._event("mission_item_out_of_sequence", last_requested=state["max"])
                    return False
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission upload", _enum_name("MAV_MISSION_RESULT", msg.type),
                                         self._status_text_since(state["start"]))
                return state["max"] == n - 1 or n == 0
            return False

        self._transaction("mission upload", lambda: resend(None), resend, on_msg)

    def _transaction(self, name: str, begin: Callable[[], None], resend: Callable[[Any], None],
                     on_msg: Callable[[Any, dict], bool]) -> dict:
        """Run one mission-protocol exchange: ``begin()``, then feed every mission message to ``on_msg`` until it
        returns True; after ``command_timeout_s`` without progress ``resend(state["last"])`` up to
        ``command_retries`` times (only a message that advances the exchange, i.e. changes ``state``, resets the
        count, so a vehicle answering with something we do not use cannot keep it going for ever)."""
        while True:
            try:
                self._mission_q.get_nowait()
            except queue.Empty:
                break
        state: dict[str, Any] = {"last": None, "max": -1, "start": time.monotonic()}
        self._mission_active = True
        try:
            begin()
            retries = 0
            deadline = time.monotonic() + self.cfg.command_timeout_s
            while True:
                remaining = deadline - time.monotonic()
                msg = None
                if remaining > 0:
                    try:
                        msg = self._mission_q.get(timeout=remaining)
                    except queue.Empty:
                        pass
                if msg is None:
                    self._check_link(name)
                    retries += 1
                    if retries > self.cfg.command_retries:
                        raise BackendError(f"robot {self.robot_id!r}: {name}: no usable answer after {retries} "
                                           f"tries of {self.cfg.command_timeout_s:g} s")
                    resend(state["last"])
                    deadline = time.monotonic() + self.cfg.command_timeout_s
                    continue
                before = (state["last"], state["max"], state.get("count"))
                if on_msg(msg, state):
                    return state
                if (state["last"], state["max"], state.get("count")) != before:
                    retries = 0
                    deadline = time.monotonic() + self.cfg.command_timeout_s
        finally:
            self._mission_active = False

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

    def _download_messages(self, mission_type: int, what: str) -> dict[int, Any]:
        """The mission protocol's download of the items of ``mission_type`` (0 mission, 1 fence, 2 rally; MAVLink
        common.xml MAV_MISSION_TYPE): MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT per item (answered
        with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM), then our MISSION_ACK; messages of another
        mission type are ignored. Returns sequence number -> item message. Raises CommandRefused (a MISSION_ACK
        with an error, named ``what``), BackendError / LinkLost."""
        got: dict[int, Any] = {}

        def begin() -> None:
            self._send(lambda mav: mav.mission_request_list_send(self._sysid, self._compid, mission_type))

        def request(seq: int) -> None:
            self._send(lambda mav: mav.mission_request_int_send(self._sysid, self._compid, seq, mission_type))

        def resend(last: Any) -> None:
            begin() if last is None else request(last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if getattr(msg, "mission_type", 0) != mission_type:
                return False
            if t == "MISSION_COUNT" and "count" not in state:
                state["count"] = msg.count
                if msg.count == 0:
                    return True
                state["last"] = 0
                request(0)
            elif t in ("MISSION_ITEM_INT", "MISSION_ITEM") and "count" in state and msg.seq == state["last"]:
                got[msg.seq] = msg
                if msg.seq + 1 >= state["count"]:
                    return True
                state["last"] = msg.seq + 1
                request(msg.seq + 1)
            elif t == "MISSION_ACK" and msg.type != M.MAV_MISSION_ACCEPTED:
                raise CommandRefused(self.robot_id, what, _enum_name("MAV_MISSION_RESULT", msg.type),
                                     self._status_text_since(state["start"]))
            return False

        self._transaction(what, begin, resend, on_msg)
        self._send(lambda mav: mav.mission_ack_send(self._sysid, self._compid, M.MAV_MISSION_ACCEPTED, mission_type))
        return got

    def download_mission(self) -> MissionPlan:
        """Download the autopilot's mission (MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT for each
        item, answered with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM, whose float latitude/longitude
        degrees are rounded to the same 1e-7 degree grid; MISSION_ACK). Returns a
        :class:`~aerodaas.missionfile.MissionPlan` with ``home`` = the vehicle's home and ``items`` numbered from 1
        (ArduPilot's home item at sequence 0 is left out); turn it into waypoints with
        :func:`~aerodaas.missionfile.plan_to_flight`. Raises BackendError / LinkLost, CommandRefused (MISSION_ACK
        with an error)."""
        self._check_link("mission download")
        got = self._download_messages(0, "mission download")
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
        self._check_link("mission clear")

        def on_msg(msg: Any, state: dict) -> bool:
            if msg.get_type() == "MISSION_ACK":
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission clear", _enum_name("MAV_MISSION_RESULT", msg.type))
                return True
            return False

        clear = lambda *_: self._send(lambda mav: mav.mission_clear_all_send(self._sysid, self._compid, 0))  # noqa: E731
        self._transaction("mission clear", clear, clear, on_msg)

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
        """The mission protocol's state: its message queue, the transfer under way, the uploaded mission's wire items."""
        self._mission_q: queue.Queue = queue.Queue()
        self._mission_active = False
        self._mission_wire: dict[int, tuple[float, float, float, int]] = {}  # wire seq -> (lat, lon, z, frame)
        #: wire seqs of our uploaded mission's autocontinue items, and its length (the next item after a reached one)
        self._mission_next: tuple[frozenset[int], int] = (frozenset(), 0)
        self._current_inferred_from = -1  # the reached item whose successor we took as current (telemetry.py)
