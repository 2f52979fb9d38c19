"""The mission protocol (mavlink.io mission microservice): upload, download, clear and start, in the INT form, and the
mission's progress (MISSION_CURRENT, MISSION_ITEM_REACHED, arrival at a waypoint). A concern object of
:class:`~aerodaas.backends.mavlink.MavlinkBackend`."""
from __future__ import annotations

import math
import threading
from typing import Any, Callable, Literal

from aerodaas.model.geo import geodetic_to_enu
from aerodaas.backends.base import BackendError, LinkLost
from aerodaas.missionfile import MissionItem, MissionPlan, expand_items, navigation_to_plan
from aerodaas.missionfile.upload import mission_differences
from aerodaas.model.types import ActionCommand, AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.backends.mavlink._common import M, _f32, _GLOBAL_FRAMES
from aerodaas.backends.mavlink.action import VehicleAction
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.offboard import OffboardControl
from aerodaas.backends.mavlink.params import SpeedLimits
from aerodaas.backends.mavlink.signing import SignedOnly
from aerodaas.backends.mavlink.telemetry import VehicleTelemetry
from aerodaas.backends.mavlink.transfer import MissionTransfer


#: MAV_FRAME_GLOBAL_RELATIVE_ALT and its _INT twin: altitudes above home
_RELATIVE_FRAMES = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
#: horizontal metres from a mission waypoint at which the vehicle counts as arrived (its hold begins): ArduPilot at
#: most this, PX4 the item's own acceptance radius (see AutopilotMission._remember_waypoints); without one, this
_ARRIVAL_RADIUS_M = 0.5


def reports_the_running_mission(mission_state: int, mode: str) -> bool:
    """Whether a MISSION_CURRENT describes a mission the autopilot is running: its ``mission_state`` (MAVLink
    common ``MISSION_STATE``, a MAVLink 2 extension) is ``MISSION_STATE_ACTIVE``; from an autopilot that does not
    report it (``MISSION_STATE_UNKNOWN``, 0), the vehicle's ``mode`` is AUTO (ArduPilot) or MISSION (PX4
    AUTO.MISSION). Sources: mavlink.io mission protocol, "Mission state"; PX4 reports ACTIVE only while its
    navigator flies the mission (AUTO_MISSION, and the take-off and landing states it enters from it), NO_MISSION
    while the stored mission is not valid, PAUSED in other modes (``MavlinkMissionManager::update_mission_state``,
    src/modules/mavlink/mavlink_mission.cpp); ArduPilot ACTIVE while its mission runs, NOT_STARTED when stopped,
    which leaving AUTO does (``GCS_MAVLINK::mission_state``, libraries/GCS_MAVLink/GCS_Common.cpp;
    ``ModeAuto::exit``). Before that state, a MISSION_CURRENT may be a mission stored earlier: a PX4 rebooted with
    its last mission reports that one's last item after a new upload, until MISSION_START."""
    if mission_state:
        return mission_state == M.MISSION_STATE_ACTIVE
    return mode in ("AUTO", "MISSION")


def _float_degrees(v: float) -> float:
    """Degrees as a MISSION_ITEM carries them (float32), on the 1e-7 degree grid of MISSION_ITEM_INT."""
    return round(_f32(v) * 1e7) / 1e7


class AutopilotMission:
    """The vehicle's own mission: built from waypoints (or given as items), uploaded, downloaded, cleared and
    started over the mission protocol, and its progress reported as events.

    It is given its collaborators: ``link`` (the link check, the autopilot, its mode and armed flag; it registers
    :meth:`on_mission_current` and :meth:`on_mission_item_reached` with it), ``telemetry`` (home, position, in the
    air, altitude reference; it feeds :meth:`on_position`), ``speed_limits`` (the horizontal speed limit),
    ``commands`` (the command protocol: mode change, MAV_CMD_MISSION_START), ``transfers`` (the mission protocol's
    exchanges), ``offboard`` (our target stream stops when the mission starts, and the vehicle is ours to bring
    down), ``actions`` (fixes the altitude reference where the vehicle stands and keeps it for the next
    arming: an uploaded mission's altitudes refer to it), ``signed`` (:class:`SignedOnly`:
    ``mavlink.require_signing`` for the start), ``event`` (records a backend event) and ``lock`` (the
    backend's lock, which guards the progress state; the I/O thread holds it while it feeds the handlers).

    State: the uploaded mission's NAV_WAYPOINTs by wire sequence number, its autocontinue items and length, the
    current item, and the items whose arrival we reported and those the autopilot reported reached. The
    autopilot's reports become progress once a MISSION_CURRENT says a mission runs
    (:func:`reports_the_running_mission`), and after an upload of ours only once we started it (:meth:`start`): a
    report about a stored or finished mission never marks the new mission's items reached. Where this backend
    uploaded nothing, a mission a ground station uploaded and started reports its progress all the same; after an
    upload of ours, only our start counts."""

    def __init__(self, robot_id: str, *, link: MavlinkLink, telemetry: VehicleTelemetry, speed_limits: SpeedLimits,
                 commands: CommandProtocol, transfers: MissionTransfer, actions: VehicleAction,
                 offboard: OffboardControl, signed: SignedOnly, event: Callable[..., None],
                 lock: threading.RLock) -> None:
        self.robot_id, self._signed = robot_id, signed
        self._link, self._telemetry, self._speed_limits = link, telemetry, speed_limits
        self._commands, self._transfers, self._actions, self._offboard = commands, transfers, actions, offboard
        self._event, self._lock = event, lock
        self._waypoints: dict[int, tuple[float, float, float]] = {}  # wire seq -> (east, north, arrival radius m)
        #: wire seqs of our uploaded mission's autocontinue items, and its length (the next item after a reached one)
        self._next: tuple[frozenset[int], int] = (frozenset(), 0)
        self._current_inferred_from = -1  # the reached item whose successor we took as current
        self._seq = -1  # the current item (wire seq)
        self._arrived: set[int] = set()  # mission wire seqs whose arrival we reported
        self._reached_fw: set[int] = set()  # mission wire seqs the autopilot reported reached
        self._uploaded = False  # we uploaded a mission: only our start() makes the reports its progress
        self._started = False  # start() was called since the last upload
        self._live = False  # ... and a MISSION_CURRENT said the mission runs: the reports are its progress
        self._plan_id = 0  # the id the vehicle gave our uploaded mission (MISSION_ACK.opaque_id); 0: none given
        link.handle("MISSION_CURRENT", self.on_mission_current)
        link.handle("MISSION_ITEM_REACHED", self.on_mission_item_reached)
        telemetry.notify_positions(self)

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
                items = navigation_to_plan(nav, self._telemetry.home, final_action,
                                           takeoff_altitude=takeoff_altitude).items
        for it in items:
            if it.is_complex:
                raise ValueError(f"upload_mission: {it.describe()} must be expanded first (pass the MissionPlan)")
        return items, nav is not None

    def upload(self, mission: Any, *, takeoff_altitude: float | None = None,
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

        The accepted mission is then read back (:meth:`download`) and compared with what was sent
        (:func:`~aerodaas.missionfile.upload.mission_differences`, what each autopilot stores): a vehicle that
        holds another flight (count, command, position, altitude, hold time, speed) gets the mission once more
        (event ``mission_replaced``), since PX4 can replace a mission it has just accepted
        (``src/modules/mavlink/mavlink_mission.cpp``, ``MavlinkMissionManager::check_active_mission``: a mission
        state published on its ``mission`` topic with another mission id, such as the navigator's own copy,
        replaces the count just stored). A value ArduPilot stores at its own precision (an altitude in whole
        centimetres, a hold time in whole seconds) is the same flight. Event ``mission_uploaded``: ``count`` and
        ``fields_not_kept`` (each field the vehicle stores differently without changing the flight, said as text
        with why: not kept, or kept at the autopilot's precision), ``mission_id`` (the plan id the vehicle gave the
        mission, :mod:`~aerodaas.missionfile.plan_ids`; 0: none given), which :meth:`start` checks.

        Returns the items as sent (``seq`` from 1; latitude/longitude rounded to 1e-7 degrees, params to float32),
        which :meth:`download` returns unchanged. Raises BackendError when the read-back of the second upload
        still differs in the flight (named, "not started"; the vehicle's mission is then cleared, and the error
        says whether that succeeded), CommandRefused (MAV_MISSION_RESULT name) when the
        autopilot rejects an item, BackendError after ``command_retries`` timeouts, LinkLost, TypeError/ValueError
        for bad input (nothing is sent then)."""
        items, built = self._mission_items(mission, takeoff_altitude, final_action)
        absolute = built and self._link.autopilot == "px4"
        if absolute and (self._telemetry.altitude_reference is None or not self._link.armed):
            # the take-off point, where the vehicle stands now; arm() keeps it: the mission's altitudes refer to it
            self._actions.pin_altitude_reference()
        wire, sent_items = self._wire_items(items, built, absolute)
        self._link.check_link("mission upload")
        for attempt in (1, 2):
            with self._lock:  # closed before the transfer: the vehicle may announce the new mission with its ACK
                self._uploaded, self._started, self._live, self._seq = True, False, False, -1
                self._plan_id = 0
            given = self._transfers.upload_mission(wire)
            with self._lock:
                self._plan_id = given
            stored, floats = self._download_items()
            # as this autopilot stores a mission (ArduPilot: altitudes in whole centimetres, hold times in whole
            # seconds); positions read back as float32 degrees (MISSION_ITEM) within float32 precision
            differences = mission_differences(sent_items, stored, autopilot=self._link.autopilot,
                                              float_positions=floats)
            flight = [d for d in differences if d.flight]
            if not flight:
                break
            if attempt == 1:
                self._event("mission_replaced", count=len(sent_items), stored=len(stored),
                            differences=[str(d) for d in flight[:5]])
        else:
            # never leave a mission other than the one sent where AUTO / MISSION would fly it
            cleared = self._clear_after_mismatch()
            raise BackendError("the mission read back differs from the one sent: "
                               + "; ".join(str(d) for d in flight[:5]) + "; not started"
                               + ("; the vehicle's mission cleared" if cleared else
                                  "; clearing the vehicle's mission failed: it still holds the one read back"))
        self._remember_waypoints(wire)
        self._event("mission_uploaded", count=len(sent_items), mission_id=given,
                    fields_not_kept=[d.explained() for d in differences])
        return sent_items

    def _clear_after_mismatch(self) -> bool:
        """MISSION_CLEAR_ALL after a read-back that still differs; True when the vehicle acknowledged it."""
        try:
            self.clear()
        except BackendError:  # CommandRefused and LinkLost are BackendErrors: the caller reports the mismatch
            return False
        return True

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
                frame, z = M.MAV_FRAME_GLOBAL, _f32(self._telemetry.altitude_reference + z)
            if it.command == M.MAV_CMD_DO_CHANGE_SPEED and built:
                # our own waypoints' speeds: never above the robot's limit (less any estimator margin measured in
                # flight), never -2 ("default": DENIED by ArduCopter): the limit instead. Given items (a mission
                # file) go up as written (``aerodaas mission upload --max-speed`` caps them itself, and says so)
                limit = self._speed_limits.xy_speed_cap()
                p[1] = _f32(limit if p[1] is None or (p[1] <= 0 and p[1] != -1) else min(p[1], limit))
            wire.append((frame, it.command, 1 if it.autocontinue else 0,
                         *[float("nan") if v is None else v for v in p], xi, yi, z))
            sent_items.append(MissionItem(seq=k + 1, command=it.command, frame=frame, params=[*p, xs, ys, z],
                                          autocontinue=it.autocontinue))
        if self._link.autopilot == "ardupilot":
            h = self._telemetry.home
            wire.insert(0, (0, M.MAV_CMD_NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, 0.0, int(round(h.lat * 1e7)),
                            int(round(h.lon * 1e7)), float(h.alt)))
        return wire, sent_items

    def _remember_waypoints(self, wire: list[tuple]) -> None:
        """Keep each uploaded NAV_WAYPOINT's horizontal position (ENU metres from :attr:`home`) and acceptance
        radius by wire sequence number, for the arrival report (:meth:`_check_arrival`)."""
        wps = {}
        first = 1 if self._link.autopilot == "ardupilot" else 0
        # PX4 starts an item's hold when its own reached check passes: horizontal distance within the item's
        # acceptance radius (navigator mission_block.cpp is_mission_item_reached, Navigator::get_acceptance_radius),
        # so its arrival radius is that one; stock PX4 SIH then holds 0.6-0.7 m from the waypoint at times and never
        # came within 0.5 m at one corner of a CI run (no arrival, so the hold had no start). ArduCopter's at most
        # _ARRIVAL_RADIUS_M
        px4 = self._link.autopilot == "px4"
        for seq, (frame, cmd, _auto, _p1, p2, _p3, _p4, xi, yi, _z) in enumerate(wire):
            if seq >= first and cmd == M.MAV_CMD_NAV_WAYPOINT and frame in _GLOBAL_FRAMES:
                e, n, _ = geodetic_to_enu(xi / 1e7, yi / 1e7, self._telemetry.home.alt, self._telemetry.home)
                radius = float(p2) if p2 is not None and p2 == p2 and p2 > 0 else _ARRIVAL_RADIUS_M
                wps[seq] = (float(e), float(n), radius if px4 else min(radius, _ARRIVAL_RADIUS_M))
        with self._lock:
            self._waypoints = wps
            self._next = (frozenset(k for k, w in enumerate(wire) if w[2]), len(wire))
            self._current_inferred_from = -1
            self._arrived.clear()
            self._reached_fw.clear()

    def download(self) -> MissionPlan:
        """Download the autopilot's mission (MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT for each
        item, answered with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM, whose float latitude/longitude
        degrees are rounded to the same 1e-7 degree grid; MISSION_ACK). Returns a
        :class:`~aerodaas.missionfile.MissionPlan` with ``home`` = the vehicle's home and ``items`` numbered from 1
        (ArduPilot's home item at sequence 0 is left out); turn it into waypoints with
        :func:`~aerodaas.missionfile.plan_to_flight`. Raises BackendError / LinkLost, CommandRefused (MISSION_ACK
        with an error)."""
        return MissionPlan(home=self._telemetry.home, items=self._download_items()[0])

    def _download_items(self) -> tuple[list[MissionItem], bool]:
        """The mission's items (see :meth:`download`) and whether any position came as float32 degrees
        (MISSION_ITEM: about 1e-6 degree apart near 50 degrees, not the 1e-7 grid)."""
        self._link.check_link("mission download")
        got = self._transfers.download_messages(0, "mission download")
        items = []
        floats = False
        first = 1 if self._link.autopilot == "ardupilot" else 0
        for seq in sorted(got):
            if seq < first:
                continue
            m = got[seq]
            if m.frame in _GLOBAL_FRAMES and m.get_type() == "MISSION_ITEM":  # float degrees (float32 on the wire)
                x, y = _float_degrees(m.x), _float_degrees(m.y)
                floats = True
            elif m.frame in _GLOBAL_FRAMES:
                x, y = m.x / 1e7, m.y / 1e7
            else:
                x, y = float(m.x), float(m.y)
            items.append(MissionItem(seq=seq + 1 - first, command=m.command, frame=m.frame,
                                     params=[_f32(m.param1), _f32(m.param2), _f32(m.param3), _f32(m.param4), x, y,
                                             _f32(m.z)], autocontinue=bool(m.autocontinue)))
        return items, floats

    def clear(self) -> None:
        """MISSION_CLEAR_ALL; waits for MISSION_ACK. Raises CommandRefused / BackendError / LinkLost."""
        with self._lock:
            self._plan_id = 0
        self._transfers.clear_mission()

    def start(self) -> None:
        """Fly the uploaded mission: in the air switch to AUTO (ArduPilot) / MISSION (PX4); on the ground (armed)
        MAV_CMD_MISSION_START, which starts it from the first item (ArduPilot needs a NAV_TAKEOFF first; PX4
        takes off by itself). Our target stream stops first, and the vehicle is ours to bring down
        (:attr:`OffboardControl.in_control`). Progress arrives as ``mission_current`` / ``mission_item_reached``
        events. Raises CredentialsRefused on an unsigned link when ``mavlink.require_signing``
        (:class:`SignedOnly`); BackendError when the vehicle holds another mission than the one uploaded
        (:meth:`_check_plan_id`; no command is sent); as :meth:`CommandProtocol.command_long` /
        :meth:`CommandProtocol.set_mode`."""
        self._signed.require("start_mission")
        self._check_plan_id()
        with self._lock:  # a resume (start again without a new upload) keeps the progress it has
            self._started = True
        self._offboard.stop()
        self._offboard.take_control()
        if self._telemetry.in_air:
            self._commands.set_mode("MISSION" if self._link.autopilot == "px4" else "AUTO")
        else:
            self._commands.command_long("mission start", M.MAV_CMD_MISSION_START, 0, 0)

    def pause(self) -> None:
        """Hold the autopilot's mission where the vehicle is: its hold mode (ArduPilot LOITER, PX4 AUTO.LOITER), also
        while it takes off, before its landed state says airborne (a hold that only stops our targets on the ground
        would let the mission fly on); :meth:`start` resumes it from its current item. Raises as
        :meth:`CommandProtocol.set_mode`."""
        self._offboard.stop()
        self._commands.set_mode("LOITER")

    def _check_plan_id(self) -> None:
        """Where the vehicle gave our uploaded mission a plan id (PX4: MISSION_ACK.opaque_id), it must still hold
        that mission before the start: PX4 can replace a mission it accepted and we read back (a mission state its
        navigator publishes with another id, ``MavlinkMissionManager::check_active_mission``; another ground
        station's upload), and MISSION_START / AUTO.MISSION would fly that one. The vehicle is asked, twice
        (:meth:`MissionTransfer.held_plan_id`), not its periodic MISSION_CURRENT believed: PX4 streams that at 1 Hz
        per link and announces a new mission at once only on the link that uploaded it, so a report handled now may
        have left the vehicle before another station's upload; and the mission protocol carries no request id, so
        an answer to an earlier request arriving late could pass for the answer (asked twice, it is at most one of
        the two, and both must name our mission). Another station's upload still under way when asked is not seen:
        the vehicle changes the id once it accepts that upload. Also for a resume (a start again without an
        upload). Raises BackendError naming both ids, or saying that the vehicle did not answer; LinkLost."""
        with self._lock:
            ours = self._plan_id
        if not ours:
            return
        held = []
        for _ in range(2):
            try:
                held.append(self._transfers.held_plan_id("start_mission: mission id check"))
            except LinkLost:
                raise
            except BackendError as e:
                raise BackendError(f"{e}: cannot confirm that the vehicle holds the mission uploaded (mission id "
                                   f"{ours}); not started") from e
        other = next((h for h in held if h != ours), None)
        if other is not None:
            raise BackendError(f"robot {self.robot_id!r}: start_mission: the vehicle reports mission id {other}, not "
                               f"{ours}, the id it gave the mission uploaded: another mission replaced it; not "
                               f"started (upload the mission again)")

    # ------------------------------------------------------------------ progress (the I/O thread, under the lock)
    def on_position(self) -> None:
        """A new position sample (telemetry.py): an uploaded waypoint may be reached. Caller holds the backend's
        lock."""
        if self._waypoints:
            self._check_arrival()

    def on_mission_current(self, msg: Any) -> None:
        """MISSION_CURRENT: the autopilot's current item, from the first one that says the started mission runs
        (see the class). Caller holds the backend's lock (the I/O thread)."""
        if not self._live:
            ours = self._started or not self._uploaded
            if not (ours and reports_the_running_mission(getattr(msg, "mission_state", 0) or 0, self._link.mode)):
                return
            self._live = True
        if msg.seq == self._current_inferred_from:
            return  # sent before the MISSION_ITEM_REACHED we already advanced on (see on_mission_item_reached)
        self._current_inferred_from = -1
        self._set_mission_current(msg.seq)

    def _set_mission_current(self, seq: int, **why: Any) -> None:
        """Make wire item ``seq`` the current one (a ``mission_current`` event when it changes). Caller holds
        the backend's lock."""
        if seq != self._seq:
            if seq < self._seq:  # the mission restarted (or jumped back): its items may be reached again
                self._arrived = {s for s in self._arrived if s < seq}
                self._reached_fw = {s for s in self._reached_fw if s < seq}
            self._seq = seq
            self._event("mission_current", seq=seq, item=self._item_number(seq), **why)
        self._check_arrival()

    def _check_arrival(self) -> None:
        """In AUTO / AUTO.MISSION, the current item is an uploaded NAV_WAYPOINT and the vehicle is within its
        arrival radius (horizontal metres): report ``mission_item_reached`` now, when its hold begins. Both
        autopilots send MISSION_ITEM_REACHED only *after* the hold time (ArduCopter ``ModeAuto::verify_nav_wp``
        after ``loiter_time``; PX4 navigator after the item's hold, repeated ~10 times at 1 Hz), so without this the
        stat-stream's WAYPOINT_HOLD would begin when the hover ends. Caller holds the backend's lock."""
        seq = self._seq
        wp = self._waypoints.get(seq)
        if wp is None or seq in self._arrived or seq in self._reached_fw or self._link.mode not in ("AUTO", "MISSION"):
            return
        pos = self._telemetry.position
        if math.hypot(pos[0] - wp[0], pos[1] - wp[1]) <= wp[2]:
            self._arrived.add(seq)
            self._event("mission_item_reached", seq=seq, item=self._item_number(seq), by="arrival")

    def _item_number(self, wire_seq: int) -> int:
        """The :class:`MissionItem` ``seq`` (from 1, as :meth:`upload` returns) of a wire sequence number:
        ArduPilot's wire numbering already starts at 1 (home is 0), PX4's at 0."""
        return wire_seq if self._link.autopilot == "ardupilot" else wire_seq + 1

    def on_mission_item_reached(self, msg: Any) -> None:
        """The autopilot's MISSION_ITEM_REACHED (after the item's hold): reported once per item and mission run
        (PX4 repeats it). For an item whose arrival :meth:`_check_arrival` already reported it becomes
        ``mission_item_hold_done``, else ``mission_item_reached`` (take-off, or an item we do not track). Ignored
        before the started mission runs (see the class)."""
        if not self._live or msg.seq in self._reached_fw:
            return
        self._reached_fw.add(msg.seq)
        name = "mission_item_hold_done" if msg.seq in self._arrived else "mission_item_reached"
        self._event(name, seq=msg.seq, item=self._item_number(msg.seq), by="autopilot")
        # The current item of our own mission moves on with it: both autopilots advance to the next item in the
        # step that reports the reached one (PX4: navigator Mission advances on the same mission_result that the
        # MAVLink mission manager sends as MISSION_ITEM_REACHED, then MISSION_CURRENT, in one
        # MavlinkMissionManager::send(), src/modules/mavlink/mavlink_mission.cpp; ArduPilot: AP_Mission::update
        # advances once verify_command reports the NAV item complete). A MISSION_CURRENT lost on the link is
        # repeated only at 1 Hz (PX4's slow-rate resend; our stream request), which delayed the next hold's start
        # and this hold's end by up to 1 s of vehicle time.
        auto, count = self._next
        if msg.seq == self._seq and msg.seq in auto and msg.seq + 1 < count:
            self._current_inferred_from = msg.seq
            self._set_mission_current(msg.seq + 1, by="reached")
