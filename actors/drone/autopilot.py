"""What a drone does when the autopilot, not AeroDaaS, flies: an autopilot's own mission (ArduPilot AUTO, PX4
AUTO.MISSION) uploaded and followed by its MISSION_CURRENT / MISSION_ITEM_REACHED reports, the autopilot's own
failsafes (RTL, LAND, BRAKE: ``mavlink.on_failsafe``), a regained link, and the return to launch around exclusion
zones. An object of its drone (:attr:`~aerodaas.actors.drone.component.DroneComponent.autopilot_flight`), given the drone's
collaborators and the flight state it shares with the drone (:mod:`aerodaas.actors.drone.flight`); it knows nothing
else of the drone."""
from __future__ import annotations

import math

from aerodaas.actors.drone.flight import FlightContext, FlightState
from aerodaas.navigation.fsm import MissionState as S
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.navigation.rtl import plan_return


class AutopilotFlight:
    """The autopilot's own mission, failsafes, link regain and the return to launch (see the module). ``ctx``: the
    drone's collaborators; ``flight``: the flight state shared with the drone (this object writes the waypoint being
    flown, the visited waypoints, the outcome, the failsafe, the return path ...); ``flies_mission``: the pre-planned
    waypoints fly as a mission uploaded to the vehicle (:attr:`flies_mission`: :meth:`start_mission`, then
    :meth:`follow_mission` each control step, fed the autopilot's reports by :meth:`mission_report`)."""

    def __init__(self, ctx: FlightContext, flight: FlightState, flies_mission: bool) -> None:
        self.ctx, self.flight = ctx, flight
        #: fly the pre-planned waypoints as a mission uploaded to the vehicle (the backend says whether)
        self.flies_mission = bool(flies_mission)
        self._items: dict[int, tuple[str, Waypoint | None]] = {}  # MissionItem seq (from 1) -> (kind, waypoint)
        self._reports: list[dict] = []  # mission_current / mission_item_reached from the backend, not yet applied
        self._current = 0
        self._reached: dict[int, tuple] = {}  # item -> where the vehicle was when the autopilot reported it
        self._done: set[int] = set()

    def mission_report(self, ev: dict) -> None:
        """A ``mission_current`` or ``mission_item_reached`` event of the backend (its ``item``: the MissionItem
        sequence number), applied at the next :meth:`follow_mission`."""
        self._reports.append(dict(ev))

    def start_mission(self) -> None:
        """Upload the queued waypoints in flying order (NAV_TAKEOFF to ``takeoff_altitude`` metres, NAV_WAYPOINT
        each with its hover time, NAV_LAND at the last one or NAV_RETURN_TO_LAUNCH for a final rtl action), arm, and
        start the mission (MAV_CMD_MISSION_START). Raises the backend's CommandRefused / BackendError."""
        c = self.ctx
        b = c.backend
        items = c.queue.queued()
        nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, items, SchedulingType.ORDERED, name="autopilot mission")
        sent = b.mission.upload(nav, takeoff_altitude=c.gate.check_takeoff(c.cfg.takeoff_altitude),
                                final_action="land")
        wps = iter([w for w in items if isinstance(w, Waypoint)])
        for it in sent:
            kind = it.nav_kind
            self._items[it.seq] = (kind, next(wps) if kind == "waypoint" else None)
        c.event("autopilot_mission_uploaded", items=len(sent),
                waypoints=[w.id for _, w in self._items.values() if w is not None])
        b.actions.arm()
        c.progress.check_vehicle_home()
        c.fsm.transition(S.ARMED, b.t)
        b.mission.start()
        c.fsm.transition(S.TAKING_OFF, b.t)
        c.event("takeoff", altitude=c.cfg.takeoff_altitude, by="autopilot mission")

    def follow_mission(self, t: float, pos: tuple) -> bool:
        """Map the autopilot's mission reports onto the stat-stream and the waypoint bookkeeping at vehicle time
        ``t`` (s), the vehicle at ``pos`` (ENU metres): MISSION_CURRENT on a waypoint -> NAVIGATING (``navigate``),
        MISSION_ITEM_REACHED -> WAYPOINT_HOLD (``waypoint_reached``; the autopilot holds for the item's hover time),
        MISSION_CURRENT moving past a waypoint -> visited (``waypoint_done``; also for items whose reports were lost
        with the link), on NAV_LAND -> LANDING, on NAV_RETURN_TO_LAUNCH -> RETURNING (the autopilot's RTL). Sends
        nothing to the vehicle. Returns False (the mission ends through LANDING)."""
        c, f = self.ctx, self.flight
        res = c.next_order(t, pos)  # records the plan; the queue itself is only popped as items complete
        f.preplanned_left = res.preplanned_left
        reports, self._reports = self._reports, []
        for ev in reports:
            n = ev.get("item")
            if n not in self._items:
                continue  # ArduPilot's home (sequence 0)
            kind, wp = self._items[n]
            if ev["event"] == "mission_item_reached":
                if kind == "takeoff" and c.fsm.state == S.TAKING_OFF:
                    c.fsm.transition(S.HOVERING, t)
                elif kind == "waypoint":
                    self._waypoint_reached(n, t, pos)
                continue
            if n <= self._current:
                continue
            for k in range(max(self._current, 1), n):
                self._item_done(k, t, pos)
            self._current = n
            self._item_current(n, kind, wp, t)
        f.preplanned_left = c.queue.pending(distance_driven_only=True)
        return False

    def _item_current(self, n: int, kind: str, wp: Waypoint | None, t: float) -> None:
        """MISSION_CURRENT reached item ``n``: a waypoint -> NAVIGATING, NAV_LAND -> LANDING, NAV_RETURN_TO_LAUNCH
        -> RETURNING (the autopilot's RTL)."""
        c, f = self.ctx, self.flight
        if kind == "waypoint":
            target = wp.to_local(c.cfg.home)
            f.active_wp = wp.id
            self._to(S.NAVIGATING, t)
            c.event("navigate", waypoint=wp.id, target=list(target), by="autopilot mission", item=n)
            c.nav_command(t, {"kind": "waypoint", "waypoint": wp.model_dump(), "local": list(target),
                              "priority": None, "autopilot_item": n})
        elif kind == "land":
            f.active_wp = None
            self._to(S.LANDING, t)
            c.event("landing", reason="mission complete", by="autopilot mission")
        elif kind == "rtl":
            f.active_wp = None
            f.backend_rtl = True
            self._to(S.RETURNING, t)
            c.event("returning", home=[0.0, 0.0], by="autopilot mission")

    def _to(self, state: S, t: float) -> None:
        """Transition to ``state``, through HOVERING when the state machine needs it (TAKING_OFF -> NAVIGATING)."""
        fsm = self.ctx.fsm
        if fsm.state != state and not fsm.can(state) and fsm.can(S.HOVERING):
            fsm.transition(S.HOVERING, t)
        fsm.transition(state, t)

    def _waypoint_reached(self, n: int, t: float, pos: tuple) -> None:
        if n in self._reached:
            return
        c = self.ctx
        self._reached[n] = pos
        wp = self._items[n][1]
        if c.fsm.state in (S.NAVIGATING, S.HOVERING, S.TAKING_OFF):
            self._to(S.WAYPOINT_HOLD, t)
        c.event("waypoint_reached", waypoint=wp.id, error_m=math.dist(pos, wp.to_local(c.cfg.home)),
                by="autopilot mission", item=n)

    def _item_done(self, n: int, t: float, pos: tuple) -> None:
        c, f = self.ctx, self.flight
        kind, wp = self._items.get(n, ("other", None))
        if kind == "takeoff" and c.fsm.state == S.TAKING_OFF:
            c.fsm.transition(S.HOVERING, t)
        if kind != "waypoint" or n in self._done:
            return
        self._waypoint_reached(n, t, pos)  # its MISSION_ITEM_REACHED may have been lost (link loss)
        self._done.add(n)
        target = wp.to_local(c.cfg.home)
        at = self._reached[n]
        c.plan_log.complete(c.queue, wp.id, t)
        f.waypoint_done(wp, {"id": wp.id, "t": t, "position": list(at), "target": list(target),
                             "error_m": math.dist(at, target)})
        c.event("waypoint_done", waypoint=wp.id)
        f.active_wp = None

    def on_failsafe(self, t: float, st: S, fs: dict) -> bool:
        """The autopilot entered a failsafe mode by itself (backend event ``autopilot_failsafe``, ``fs``) at vehicle
        time ``t`` (s) in mission state ``st``: the mission pauses and the outcome records it; then
        ``mavlink.on_failsafe`` says what follows: ``end`` (the autopilot's RTL/LAND flies on to the ground; after
        BRAKE, land here), ``hold`` (PAUSED until an operator resumes) or ``resume`` (the current waypoint is
        re-issued, which switches back to GUIDED/OFFBOARD). Returns True when the mission is over."""
        c, f = self.ctx, self.flight
        v, fsm = c.backend, c.fsm
        action = v.failsafe_action
        mode = fs.get("mode", "")
        if self.flies_mission and f.preplanned_left == 0 and mode in ("RTL", "LAND"):
            return False  # the uploaded mission's own last item (NAV_RETURN_TO_LAUNCH / NAV_LAND)
        f.failsafe = {"mode": mode, "previous": fs.get("previous"), "t": t, "text": fs.get("text", ""),
                      "action": action, "state": st.value}
        c.event("failsafe", mode=mode, action=action, state=st.value, text=fs.get("text", ""))
        if st in (S.LANDING, S.LANDED, S.RETURNING):
            return False  # already on the way down: nothing of ours to pause

        f.reissue = False
        f.active_wp, f.hold_until, f.hold = None, None, None
        if action == "resume":
            if st == S.LINK_LOST:
                return self.link_regained(t)
            if st == S.WAYPOINT_HOLD:
                fsm.transition(S.NAVIGATING, t)
            return False
        getattr(v.guidance, "release", lambda: None)()
        if action == "hold":
            if st != S.PAUSED and fsm.can(S.PAUSED):
                f.paused_from = {S.LINK_LOST: f.link_lost_from}.get(st, st)
                fsm.transition(S.PAUSED, t)
                c.event("paused", reason=f"autopilot failsafe {mode}")
            return False
        f.outcome = "failsafe"
        if mode in ("RTL", "SMART_RTL", "AUTO_RTL"):
            f.backend_rtl = True
            fsm.transition(S.RETURNING, t)
            c.event("returning", by="autopilot failsafe", mode=mode)
        else:
            if mode not in ("LAND",):
                v.guidance.land()  # BRAKE (a fence action) holds in the air: end the flight here
            fsm.transition(S.LANDING, t)
            c.event("landing", reason=f"autopilot failsafe {mode}")
        return False

    def link_regained(self, t: float) -> bool:
        """The link is back at vehicle time ``t`` (s): resume what was going on (re-issuing the active waypoint), or
        note the landing. Returns True when the mission is over (landed while the link was lost)."""
        c, f = self.ctx, self.flight
        v, prev = c.backend, f.link_lost_from or S.HOVERING
        c.event("link_regained", resuming=prev.value)
        if not v.state().in_air:
            c.fsm.transition(S.LANDED, t)
            c.event("landed", reason="landed while the link was lost")
            if f.outcome is None:
                f.outcome = "incomplete" if f.preplanned_left or c.plan_log.cleared_preplanned else "success"
            return True
        resume = {S.WAYPOINT_HOLD: S.NAVIGATING}.get(prev, prev)
        if resume in (S.ARMED, S.PREFLIGHT):
            resume = S.TAKING_OFF
        c.fsm.transition(resume, t)
        f.active_wp, f.hold_until = None, None  # re-issue the current waypoint on the next step
        return False

    def return_to_launch(self, t: float, pos: tuple) -> None:
        """RTL at vehicle time ``t`` (s) from ``pos`` (ENU metres): the autopilot's own mode when it has one and the
        straight leg home is the planned path; else fly home along the planned path at the current altitude (at
        least the take-off altitude, metres) leg by leg (the drone's RETURNING handler), then land; with no safe
        path home, land in place (outcome ``rtl_failed``)."""
        c, f = self.ctx, self.flight
        f.active_wp, f.hold_until = None, None
        if c.fsm.state == S.TRACKING:
            c.event("tracking_ended")

        alt = min(max(pos[2], c.cfg.takeoff_altitude), c.gate.max_alt)
        try:
            vel = tuple(float(x) for x in c.backend.state().velocity)
        except Exception:  # noqa: BLE001 - a backend without a velocity estimate: planned from rest
            vel = (0.0, 0.0, 0.0)
        path, why = plan_return(c.gate, pos, vel, alt)
        if path is None:  # no safe path home: land in place (a failsafe never crosses an exclusion zone)
            f.rtl_path = None
            c.backend.guidance.land()
            c.fsm.transition(S.LANDING, t)
            away = math.hypot(pos[0], pos[1])
            # landing away from home is not the return asked for: never a success (it was, 43 m from home)
            f.outcome = f.outcome or "rtl_failed"
            c.event("rtl_impossible", reason=why, distance_from_home_m=round(away, 1))
            c.event("landing", reason=f"return to launch impossible: {why}; landing in place {away:.0f} m from "
                                      f"home")
            return
        # the autopilot's own RTL flies straight home: only when the straight leg is the planned path
        straight = len(path) == 2
        f.backend_rtl = bool(straight and c.backend.guidance.return_to_launch())
        f.rtl_path = [(x, y, alt) for x, y in path[1:]]
        if not f.backend_rtl:
            c.backend.guidance.goto(f.rtl_path[0], c.gate.max_speed)
        c.fsm.transition(S.RETURNING, t)
        c.event("returning", home=[0.0, 0.0], by="autopilot" if f.backend_rtl else "aerodaas",
                path=[list(p) for p in f.rtl_path])
