"""What a drone does when the autopilot, not AeroDaaS, flies: an autopilot's own mission (ArduPilot AUTO, PX4
AUTO.MISSION) uploaded and followed by its MISSION_CURRENT / MISSION_ITEM_REACHED reports, the autopilot's own
failsafes (RTL, LAND, BRAKE: ``mavlink.on_failsafe``), a regained link, and the return to launch around exclusion
zones. A mixin of :class:`~aerodaas.actors.drone.DroneComponent`, whose state (``fsm``, ``backend``, ``gate``,
``cfg``, ``queue``, ``plan_log``, events) it shares; split from that module so that each stays one concept."""
from __future__ import annotations

import math

from aerodaas.navigation.fsm import MissionState as S
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint


class AutopilotFlight:
    """Mixin: the autopilot's own mission, failsafes, link regain and the return to launch (see the module)."""

    def _init_autopilot(self) -> None:
        """Whether the pre-planned waypoints fly as the autopilot's own mission, and that mission's bookkeeping."""
        #: fly the pre-planned waypoints as a mission uploaded to the vehicle (the backend says whether)
        self.autopilot_mission = bool(self.backend.flies_uploaded_mission)
        self._ap_items: dict[int, tuple[str, Waypoint | None]] = {}  # MissionItem seq (from 1) -> (kind, waypoint)
        self._ap_events: list[dict] = []  # mission_current / mission_item_reached from the backend, not yet applied
        self._ap_current = 0
        self._ap_reached: dict[int, tuple] = {}  # item -> where the vehicle was when the autopilot reported it
        self._ap_done: set[int] = set()

    def _start_autopilot_mission(self) -> None:
        """Upload the queued waypoints in flying order (NAV_TAKEOFF to ``takeoff_altitude``, NAV_WAYPOINT each with
        its hover time, NAV_LAND at the last one or NAV_RETURN_TO_LAUNCH for a final rtl action), arm, and start
        the mission (MAV_CMD_MISSION_START). Raises the backend's CommandRefused / BackendError."""
        b = self.backend
        items = self.queue.queued()
        nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, items, SchedulingType.ORDERED, name="autopilot mission")
        sent = b.upload_mission(nav, takeoff_altitude=self.gate.check_takeoff(self.cfg.takeoff_altitude),
                                final_action="land")
        wps = iter([w for w in items if isinstance(w, Waypoint)])
        for it in sent:
            kind = it.nav_kind
            self._ap_items[it.seq] = (kind, next(wps) if kind == "waypoint" else None)
        self._event("autopilot_mission_uploaded", items=len(sent),
                    waypoints=[w.id for _, w in self._ap_items.values() if w is not None])
        b.arm()
        self.progress.check_vehicle_home()
        self.fsm.transition(S.ARMED, b.t)
        b.start_mission()
        self.fsm.transition(S.TAKING_OFF, b.t)
        self._event("takeoff", altitude=self.cfg.takeoff_altitude, by="autopilot mission")

    def _follow_autopilot_mission(self, t: float, pos: tuple) -> bool:
        """Map the autopilot's mission reports onto the stat-stream and the waypoint bookkeeping: MISSION_CURRENT
        on a waypoint -> NAVIGATING (``navigate``), MISSION_ITEM_REACHED -> WAYPOINT_HOLD (``waypoint_reached``;
        the autopilot holds for the item's hover time), MISSION_CURRENT moving past a waypoint -> visited
        (``waypoint_done``; also for items whose reports were lost with the link), on NAV_LAND -> LANDING, on
        NAV_RETURN_TO_LAUNCH -> RETURNING (the autopilot's RTL). Sends nothing to the vehicle."""
        res = self.next_order(t, pos)  # records the plan; the queue itself is only popped as items complete
        self.flight.preplanned_left = res.preplanned_left
        events, self._ap_events = self._ap_events, []
        for ev in events:
            n = ev.get("item")
            if n not in self._ap_items:
                continue  # ArduPilot's home (sequence 0)
            kind, wp = self._ap_items[n]
            if ev["event"] == "mission_item_reached":
                if kind == "takeoff" and self.fsm.state == S.TAKING_OFF:
                    self.fsm.transition(S.HOVERING, t)
                elif kind == "waypoint":
                    self._ap_waypoint_reached(n, t, pos)
                continue
            if n <= self._ap_current:
                continue
            for k in range(max(self._ap_current, 1), n):
                self._ap_item_done(k, t, pos)
            self._ap_current = n
            if kind == "waypoint":
                target = wp.to_local(self.cfg.home)
                self.flight.active_wp = wp.id
                self._to(S.NAVIGATING, t)
                self._event("navigate", waypoint=wp.id, target=list(target), by="autopilot mission", item=n)
                self._nav_command(t, {"kind": "waypoint", "waypoint": wp.model_dump(), "local": list(target),
                                      "priority": None, "autopilot_item": n})
            elif kind == "land":
                self.flight.active_wp = None
                self._to(S.LANDING, t)
                self._event("landing", reason="mission complete", by="autopilot mission")
            elif kind == "rtl":
                self.flight.active_wp = None
                self.flight.backend_rtl = True
                self._to(S.RETURNING, t)
                self._event("returning", home=[0.0, 0.0], by="autopilot mission")
        self.flight.preplanned_left = self.queue.pending(distance_driven_only=True)
        return False

    def _ap_waypoint_reached(self, n: int, t: float, pos: tuple) -> None:
        if n in self._ap_reached:
            return
        self._ap_reached[n] = pos
        wp = self._ap_items[n][1]
        if self.fsm.state in (S.NAVIGATING, S.HOVERING, S.TAKING_OFF):
            self._to(S.WAYPOINT_HOLD, t)
        self._event("waypoint_reached", waypoint=wp.id, error_m=math.dist(pos, wp.to_local(self.cfg.home)),
                    by="autopilot mission", item=n)

    def _ap_item_done(self, n: int, t: float, pos: tuple) -> None:
        kind, wp = self._ap_items.get(n, ("other", None))
        if kind == "takeoff" and self.fsm.state == S.TAKING_OFF:
            self.fsm.transition(S.HOVERING, t)
        if kind != "waypoint" or n in self._ap_done:
            return
        self._ap_waypoint_reached(n, t, pos)  # its MISSION_ITEM_REACHED may have been lost (link loss)
        self._ap_done.add(n)
        target = wp.to_local(self.cfg.home)
        at = self._ap_reached[n]
        self.plan_log.complete(self.queue, wp.id, t)
        self.flight.visited.append({"id": wp.id, "t": t, "position": list(at), "target": list(target),
                             "error_m": math.dist(at, target)})
        self._event("waypoint_done", waypoint=wp.id)
        self.flight.active_wp = None

    def _on_autopilot_failsafe(self, t: float, st: S) -> bool:
        """The autopilot entered a failsafe mode by itself (backend event ``autopilot_failsafe``): the mission
        pauses and the outcome records it; then ``mavlink.on_failsafe`` says what follows: ``end`` (the autopilot's
        RTL/LAND flies on to the ground; after BRAKE, land here), ``hold`` (PAUSED until an operator resumes) or
        ``resume`` (the current waypoint is re-issued, which switches back to GUIDED/OFFBOARD)."""
        fs, self._failsafe_pending = self._failsafe_pending, None
        v, fsm = self.backend, self.fsm
        action = self.backend.failsafe_action
        mode = fs.get("mode", "")
        if self.autopilot_mission and self.flight.preplanned_left == 0 and mode in ("RTL", "LAND"):
            return False  # the uploaded mission's own last item (NAV_RETURN_TO_LAUNCH / NAV_LAND)
        self.flight.failsafe = {"mode": mode, "previous": fs.get("previous"), "t": t, "text": fs.get("text", ""),
                         "action": action, "state": st.value}
        self._event("failsafe", mode=mode, action=action, state=st.value, text=fs.get("text", ""))
        if st in (S.LANDING, S.LANDED, S.RETURNING):
            return False  # already on the way down: nothing of ours to pause

        self.flight.reissue = False
        self.flight.active_wp, self.flight.hold_until, self.flight.hold = None, None, None
        if action == "resume":
            if st == S.LINK_LOST:
                return self._link_regained(t)
            if st == S.WAYPOINT_HOLD:
                fsm.transition(S.NAVIGATING, t)
            return False
        getattr(v, "release", lambda: None)()
        if action == "hold":
            if st != S.PAUSED and fsm.can(S.PAUSED):
                self.flight.paused_from = {S.LINK_LOST: self.flight.link_lost_from}.get(st, st)
                fsm.transition(S.PAUSED, t)
                self._event("paused", reason=f"autopilot failsafe {mode}")
            return False
        self.flight.outcome = "failsafe"
        if mode in ("RTL", "SMART_RTL", "AUTO_RTL"):
            self.flight.backend_rtl = True
            fsm.transition(S.RETURNING, t)
            self._event("returning", by="autopilot failsafe", mode=mode)
        else:
            if mode not in ("LAND",):
                v.land()  # BRAKE (a fence action) holds in the air: end the flight here
            fsm.transition(S.LANDING, t)
            self._event("landing", reason=f"autopilot failsafe {mode}")
        return False

    def _link_regained(self, t: float) -> bool:
        """The link is back: resume what was going on (re-issuing the active waypoint), or note the landing."""
        v, prev = self.backend, self.flight.link_lost_from or S.HOVERING
        self._event("link_regained", resuming=prev.value)
        if not v.in_air:
            self.fsm.transition(S.LANDED, t)
            self._event("landed", reason="landed while the link was lost")
            if self.flight.outcome is None:
                self.flight.outcome = "incomplete" if self.flight.preplanned_left or self.plan_log.cleared_preplanned else "success"
            return True
        resume = {S.WAYPOINT_HOLD: S.NAVIGATING}.get(prev, prev)
        if resume in (S.ARMED, S.PREFLIGHT):
            resume = S.TAKING_OFF
        self.fsm.transition(resume, t)
        self.flight.active_wp, self.flight.hold_until = None, None  # re-issue the current waypoint on the next step
        return False

    def _return_to_launch(self, t: float, pos: tuple) -> None:
        """RTL: the autopilot's own mode when it has one; else fly home at the current altitude (at least the
        take-off altitude), then land (see _control)."""
        self.flight.active_wp, self.flight.hold_until = None, None
        if self.fsm.state == S.TRACKING:
            self._event("tracking_ended")
        from aerodaas.navigation.rtl import plan_return

        alt = min(max(pos[2], self.cfg.takeoff_altitude), self.gate.max_alt)
        try:
            vel = tuple(float(c) for c in self.backend.velocity)
        except Exception:  # noqa: BLE001 - a backend without a velocity estimate: planned from rest
            vel = (0.0, 0.0, 0.0)
        path, why = plan_return(self.gate, pos, vel, alt)
        if path is None:  # no safe path home: land in place (a failsafe never crosses an exclusion zone)
            self.flight.rtl_path = None
            self.backend.land()
            self.fsm.transition(S.LANDING, t)
            away = math.hypot(pos[0], pos[1])
            # landing away from home is not the return asked for: never a success (it was, 43 m from home)
            self.flight.outcome = self.flight.outcome or "rtl_failed"
            self._event("rtl_impossible", reason=why, distance_from_home_m=round(away, 1))
            self._event("landing", reason=f"return to launch impossible: {why}; landing in place {away:.0f} m from "
                                          f"home")
            return
        # the autopilot's own RTL flies straight home: only when the straight leg is the planned path
        straight = len(path) == 2
        self.flight.backend_rtl = bool(straight and self.backend.return_to_launch())
        self.flight.rtl_path = [(x, y, alt) for x, y in path[1:]]
        if not self.flight.backend_rtl:
            self.backend.goto(self.flight.rtl_path[0], self.gate.max_speed)
        self.fsm.transition(S.RETURNING, t)
        self._event("returning", home=[0.0, 0.0], by="autopilot" if self.flight.backend_rtl else "aerodaas",
                    path=[list(p) for p in self.flight.rtl_path])

