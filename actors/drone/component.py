"""DroneComponent: one robot — its vehicle backend, flight logic (mission state machine, waypoint acceptance,
hover timers, failsafes), navigation executor, and its odometry and stat-stream sensors (their data is the
vehicle state itself).

It lives in the edge actor (:mod:`aerodaas.actors.data.plane`): the actor's clock thread calls :meth:`step` and
:meth:`control_tick`. A control step checks what holds in every state (link, autopilot failsafe), then runs the
handler of the current mission state (``_on_landing``, ``_on_returning``, ``_on_paused``, ...), from a table with
one handler per state of :data:`~aerodaas.navigation.fsm.TRANSITIONS` (:func:`~aerodaas.navigation.fsm.handler_table`). The drone owns its waypoint queue (:attr:`DroneComponent.queue`, a
:class:`~aerodaas.navigation.waypoint_queue.WaypointQueue` holding the pre-planned navigation it was given) and its
navigation inbox (:attr:`DroneComponent.inbox`, :class:`~aerodaas.actors.drone.inbox.DroneInbox`), which checks new
navigation, asks the trajectory scheduler plug-in to plan it into the queue, and hands it to
:meth:`DroneComponent.apply_navigation` so that it is applied at once. Every command passes the robot's
:class:`~aerodaas.navigation.safety.SafetyGate` right before it reaches the backend (the one choke point). The
backend is whatever ``robots[].backend`` names: the embedded simulator, a MAVLink autopilot, a Tello, or a replayed log (not navigable: the state machine then follows the log).

With ``mavlink.use_autopilot_mission`` the pre-planned waypoints are uploaded to the autopilot before arming and
flown as its own mission (ArduPilot AUTO, PX4 AUTO.MISSION); the state machine then follows the autopilot's
MISSION_CURRENT / MISSION_ITEM_REACHED reports instead of sending targets (the runtime refused, before any actor
started, every navigation that such a mission cannot express).

The drone composes its flight logic from objects that know nothing else of it: :attr:`DroneComponent.queue_flight`
(flying its own queue, :mod:`~aerodaas.actors.drone.queue_flight`) and :attr:`DroneComponent.autopilot_flight` (the
autopilot's own mission, failsafes, link regain, return to launch, :mod:`~aerodaas.actors.drone.autopilot`), both
given its collaborators and the flight state it shares with them (:attr:`DroneComponent.flight`, a
:class:`~aerodaas.actors.drone.flight.FlightState`).
"""
from __future__ import annotations

import math
import threading
import traceback
from typing import Any

from aerodaas.backends import BackendError, VehicleState, make_backend
from aerodaas.config import RobotConfig
from aerodaas.navigation.fsm import MissionFSM, MissionState as S, handler_table
from aerodaas.protocol.messages import StatMsg
from aerodaas.navigation.safety import SafetyGate
from aerodaas.navigation.waypoint_queue import Order
from aerodaas.schedulers.base import TrajectoryScheduler

from aerodaas.actors.drone.autopilot import AutopilotFlight
from aerodaas.actors.drone.deadline import PhaseDeadlines
from aerodaas.actors.drone.inbox import DroneInbox, DronePort
from aerodaas.actors.drone.mission_plan import MissionPlanLog
from aerodaas.actors.drone.end import SETTLE_WALL_S, RunEnd
from aerodaas.actors.drone.gimbal import DroneGimbal
from aerodaas.actors.drone.odometry import OdometryPublisher
from aerodaas.actors.drone.progress import NavigationProgress
from aerodaas.actors.drone.flight import FlightContext, FlightState
from aerodaas.actors.drone.queue_flight import QueueFlight

_ACTIVE = (S.HOVERING, S.NAVIGATING, S.WAYPOINT_HOLD, S.TRACKING)


class DroneComponent:
    """See the module docstring. ``scheduler`` is the robot's trajectory scheduler plug-in (a
    :class:`~aerodaas.schedulers.base.TrajectoryScheduler`; None: the base one, nothing pre-planned): its queued
    navigation is copied into this drone's own :attr:`queue`, and it plans what the :attr:`inbox` (component id
    ``inbox_cid``, default ``<robot>/scheduler``) takes; ``plane`` publishes sensor messages to subscribers;
    ``recorder`` is the run's RecorderService or None."""

    kind = "drone"

    def __init__(self, cid: str, robot_cfg: dict, plane: Any, scheduler: Any, recorder: Any, epoch_ns: int,
                 preplanned_total: int, odom_cids: list[str], stat_cids: list[str], backend: Any = None,
                 inbox_cid: str | None = None, gimbal_commands: list | None = None) -> None:
        self.cid = cid
        self.cfg = RobotConfig.model_validate(robot_cfg)
        self.plane = plane
        self.backend = backend if backend is not None else make_backend(self.cfg)
        self.gate = SafetyGate(self.cfg.safety, self.cfg.limits, self.cfg.home,
                               control_period_s=1.0 / self.cfg.control_rate_hz)
        planner = scheduler if scheduler is not None else TrajectoryScheduler()
        #: this drone's waypoint queue: the pre-planned navigation it was given, then whatever its inbox takes
        self.queue = planner.queue.copy()
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.odom_cids, self.stat_cids = odom_cids, stat_cids
        #: the plan record and the items dropped from the queue (shared with the inbox)
        self.plan_log = MissionPlanLog(self.cfg.id, self.cfg.home, recorder, epoch_ns)
        #: simulated time (s) and position (ENU metres) at the last control step: where navigation is planned from
        self.last_tick: tuple[float, tuple] = (0.0, tuple(planner.start))
        #: the drone's navigation port (``<robot>/scheduler``): analytics and the HITL API add navigation there
        self.inbox = DroneInbox(plane, inbox_cid or f"{self.cfg.id}/scheduler", self.cfg.id, planner, recorder,
                                epoch_ns, robot_cfg, self.queue, self.plan_log,
                                DronePort(last_tick=lambda: self.last_tick, apply=self.apply_navigation))
        self.lock = threading.RLock()
        self.fsm = MissionFSM(self._on_transition)
        self.cameras: list[dict] = []  # {"comp", "fps", "next_t"} — filled by the actor's assembly
        self.plugin_sensors: list = []  # PluginSensorComponent (aerodaas.actors.sensors.plugin_sensor), filled likewise
        self.events: list[dict] = []
        self.takeoff_altitude = self.cfg.takeoff_altitude  # as the safety gate passed it (start())
        self._failsafe_pending: dict | None = None  # an autopilot_failsafe event not yet acted on
        #: whether the vehicle flies where the gate thinks: its home after arming, its progress on each leg
        self.progress = NavigationProgress(self.backend, self.cfg.id, self.cfg.progress, self.gate, self._event)
        #: the flight state shared with the flight objects: waypoint flown and held, visited, outcome, ...
        self.flight = FlightState(preplanned_total=preplanned_total, preplanned_left=preplanned_total)
        self.flight.mark_preplanned(self.queue)
        ctx = FlightContext(self.cfg, self.backend, self.gate, self.fsm, self.queue, self.plan_log, self.progress,
                            self._event, self.next_order, self._nav_command)
        #: fly the pre-planned waypoints as a mission uploaded to the vehicle (the backend says whether)
        self.autopilot_mission = bool(self.backend.flies_uploaded_mission)
        #: the autopilot's own mission, its failsafes, link regain, the return to launch
        #: (:class:`~aerodaas.actors.drone.autopilot.AutopilotFlight`)
        self.autopilot_flight = AutopilotFlight(ctx, self.flight, self.autopilot_mission)
        #: flying the drone's own queue (:class:`~aerodaas.actors.drone.queue_flight.QueueFlight`)
        self.queue_flight = QueueFlight(ctx, self.flight, self.autopilot_flight.return_to_launch)
        #: the deadlines of take-off, landing and the return (:class:`~aerodaas.actors.drone.deadline.PhaseDeadlines`)
        self.deadlines = PhaseDeadlines(ctx, self.flight)
        self._pause_req = threading.Event()
        self._resume_req = threading.Event()
        self._end_req: str | None = None
        self.error: str | None = None
        self.done = False
        self.ticks = 0
        self.missed_ticks = 0
        self.nudges = 0  # navigation applied outside the control tick (:meth:`apply_navigation`)
        #: the drone's odometry sensor (recorded and published from the vehicle's state or its own samples)
        self.odometry = OdometryPublisher(self.backend, self.cfg.id, recorder, plane, odom_cids,
                                          OdometryPublisher.rate_of(self.cfg), self._t_ns)
        #: the camera gimbal: commands through the safety gate, attitude recorded on /<robot>/gimbal
        self.gimbal = DroneGimbal(self.backend, self.cfg.id, self.cfg.gimbal, self.gate, recorder, self._t_ns,
                                  self._event, OdometryPublisher.rate_of(self.cfg), gimbal_commands)
        #: the end of the run: a real vehicle brought down and recorded until its end state (:attr:`ended`)
        self.end = RunEnd(self.backend, self.cfg.id, self.fsm, self._event, self.odometry)
        self.tick_period = 1.0 / self.cfg.control_rate_hz
        self.next_tick = 0.0
        #: the control step's handler of each mission state (:meth:`_control`), checked against the state table
        self._handlers = handler_table({
            S.LINK_LOST: self._on_link_lost, S.LANDING: self._on_landing, S.EMERGENCY: self._on_emergency,
            S.RETURNING: self._on_returning, S.PAUSED: self._on_paused, S.TAKING_OFF: self._on_taking_off,
            **{st: self._on_airborne for st in (*_ACTIVE, S.IDLE, S.PREFLIGHT, S.ARMED, S.LANDED)}})

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float | None = None) -> None:
        """Open the backend's link (a no-op for the simulator), waiting up to ``timeout_s`` seconds (default: the
        backend's own setting, e.g. ``mavlink.connect_timeout_s``). Raises BackendError naming the robot."""
        try:
            if timeout_s is None:
                self.backend.connect()
            else:
                self.backend.connect(timeout_s)
        except BackendError:
            raise
        except Exception as e:
            raise BackendError(f"robot {self.cfg.id!r}: backend {self.cfg.backend!r} could not connect: "
                               f"{type(e).__name__}: {e}") from e

    def start(self) -> None:
        """PREFLIGHT -> ARMED -> TAKING_OFF (navigable backends; -> HOVERING for a backend that needs no take-off), or
        PREFLIGHT only (a replayed log)."""
        b, t = self.backend, self.backend.t
        self.fsm.transition(S.PREFLIGHT, t)
        if not b.navigable:
            self._event("observing", backend=self.cfg.backend)
            return
        self.gimbal.start()  # what the application pointed the gimbal at before the mission started
        if self.autopilot_mission:
            self.autopilot_flight.start_mission()
            return
        if not b.needs_takeoff:  # a ground vehicle: armed, it is ready to drive (no take-off phase to bound)
            b.actions.arm()
            self.progress.check_vehicle_home()
            self.fsm.transition(S.ARMED, b.t)
            self.fsm.transition(S.HOVERING, b.t)
            self._event("takeoff_skipped", reason=f"backend {self.cfg.backend!r} needs no take-off")
            return
        alt = self.gate.check_takeoff(self.cfg.takeoff_altitude)  # the take-off target passes the gate too
        self.takeoff_altitude = alt
        b.actions.arm()
        self.progress.check_vehicle_home()
        self.fsm.transition(S.ARMED, b.t)
        b.actions.takeoff(alt)
        self.fsm.transition(S.TAKING_OFF, b.t)
        self._event("takeoff", altitude=alt)

    def close(self) -> None:
        """Close the backend, a real vehicle still armed brought down first and recorded until the disarm
        (:meth:`RunEnd.close <aerodaas.actors.drone.end.RunEnd.close>`)."""
        self.end.close()

    def settled(self, wait_s: float = SETTLE_WALL_S) -> bool:
        """After the mission ended: whether the recorded odometry shows the vehicle's end state, or ``wait_s`` wall
        seconds passed (:meth:`RunEnd.settled <aerodaas.actors.drone.end.RunEnd.settled>`)."""
        return self.end.settled(wait_s)

    def finish(self) -> None:
        """The run is over for this drone: last odometry and the mission result. The drone is no longer stepped:
        what its vehicle sends meanwhile is not recorded, except from the newest sample on while :meth:`close` brings
        it down."""
        self.publish_odometry()
        self.odometry.mission_ended()
        for ps in self.plugin_sensors:  # their failures not yet in an event: one summary each
            ps.finish(self.backend.t)
        if self.recorder is not None:
            self.recorder.json("/mission/result", self._t_ns(self.backend.t),
                               {"robot": self.cfg.id, "outcome": self.outcome, "visited": len(self.visited),
                                "preplanned_total": self.flight.preplanned_total,
                                "preplanned_reached": self.flight.preplanned_reached, "t": self.backend.t,
                                "error": self.error}, "aerodaas.MissionResult")

    # ------------------------------------------------------------------ recording helpers
    def _t_ns(self, t: float) -> int:
        return self.epoch_ns + int(t * 1e9)

    def _event(self, kind: str, **kw: Any) -> None:
        ev = {"robot": self.cfg.id, "t": self.backend.t, "event": kind, **kw}
        self.events.append(ev)
        if self.recorder is not None:
            self.recorder.json(f"/{self.cfg.id}/events", self._t_ns(self.backend.t), ev, "aerodaas.MissionEvent")

    def _nav_command(self, t: float, command: dict) -> None:
        """Record navigation command ``command`` (``aerodaas.NavCommand`` fields) on ``/<robot>/nav/command`` at
        vehicle time ``t`` (s); nothing without a recorder."""
        if self.recorder is not None:
            self.recorder.json(f"/{self.cfg.id}/nav/command", self._t_ns(t), command, "aerodaas.NavCommand")

    def record_event(self, kind: str, **fields: Any) -> None:
        """Record mission event ``kind`` with ``fields`` (JSON-serialisable) at the vehicle's time: kept in
        :attr:`events` (the robot's report) and written to ``/<robot>/events`` (``aerodaas.MissionEvent``). For
        the actor around the drone: a recording failure, a timeout, a resume after a restart."""
        self._event(kind, **fields)

    def _on_transition(self, old: S, new: S, t: float) -> None:
        msg = {"robot": self.cfg.id, "state": new.value, "previous": old.value, "t": t}
        if self.recorder is not None:
            self.recorder.json("/mission/state", self._t_ns(t), msg, "aerodaas.MissionState")
        for cid in self.stat_cids:
            self.plane.publish(cid, [StatMsg(robot=self.cfg.id, sim_t=t, data=msg)], None, inline=False)

    # ------------------------------------------------------------------ control API (any thread)
    def pause_mission(self) -> bool:
        self._pause_req.set()
        return True

    def resume_mission(self) -> bool:
        self._resume_req.set()
        return True

    def end_mission(self, reason: str = "aborted") -> bool:
        self._end_req = reason
        return True

    def point_gimbal(self, cmd: Any) -> None:
        """Carry out gimbal command ``cmd`` (:data:`aerodaas.protocol.gimbal.GimbalCommand`) now: the safety gate
        checks it against the robot's ``gimbal`` limits, then the backend sends it (:class:`DroneGimbal`). Raises
        GimbalError (nothing sent) or the backend's error when the vehicle refuses."""
        with self.lock:
            self.gimbal.command(cmd)

    def gimbal_attitude(self) -> dict | None:
        """The gimbal's latest attitude (``aerodaas.GimbalAttitude`` fields: vehicle time ``t``, ``q``, degrees),
        None before the first report or without a gimbal."""
        return self.gimbal.attitude()

    @property
    def visited(self) -> list[dict]:
        """The waypoints done, in order: id, vehicle time ``t`` (s), ``position`` and ``target`` (ENU metres),
        ``error_m`` (:attr:`FlightState.visited <aerodaas.actors.drone.flight.FlightState.visited>`)."""
        return self.flight.visited

    @property
    def outcome(self) -> str | None:
        """How this drone's mission ended (``success``, ``incomplete``, ``failsafe``, ``timeout`` ...); None while it
        runs (:attr:`FlightState.outcome <aerodaas.actors.drone.flight.FlightState.outcome>`)."""
        return self.flight.outcome

    @outcome.setter
    def outcome(self, outcome: str | None) -> None:
        self.flight.outcome = outcome

    @property
    def end_requested(self) -> str | None:
        """The reason given to :meth:`end_mission` (the robot's outcome once the next control tick ends it);
        None while no end was requested."""
        return self._end_req

    def status(self) -> dict:
        """The live state for the driver's progress line (``clock_held_s``: this actor's clock's waits, wall s)."""
        b, now = self.backend, self.backend.state()
        cam_drop, rec = sum(c["comp"].dropped_at_camera for c in self.cameras), self.recorder
        return {"robot": self.cfg.id, "t": now.t, "state": self.fsm.state.value,
                "clock_held_s": 0.0 if rec is None else round(rec.hold.spent_s(), 3),
                "position": [float(v) for v in now.position], "battery_pct": None if now.battery_pct is None else float(now.battery_pct),
                "visited": len(self.visited), "preplanned_total": self.flight.preplanned_total,
                "preplanned_reached": self.flight.preplanned_reached, "cameras": len(self.cameras),
                "frames": sum(c["comp"].ticks for c in self.cameras), "frames_dropped_at_camera": cam_drop,
                "frames_shed_late": sum(c["comp"].shed_late for c in self.cameras),
                "frames_not_made": sum(c["comp"].frames_not_made for c in self.cameras),
                "outcome": self.outcome, "missed_ticks": self.missed_ticks, "ticks": self.ticks,
                "link_ok": bool(now.link_ok), "backend": self.cfg.backend, "navigable": b.navigable}

    def report(self) -> dict:
        f = self.flight
        return {**self.status(), "visited_waypoints": f.visited, "events": self.events, "error": self.error,
                "rejected": f.rejected, "hold_failed": f.hold_failed, "not_reached": self.progress.not_reached,
                "ended": self.end.ended, "failsafe": f.failsafe, "safety": self.gate.stats(),
                "state_history": [(t, s.value) for t, s in self.fsm.history]}

    # ------------------------------------------------------------------ odometry (the drone's odometry object)
    def publish_odometry(self, tok: Any = None, *, paced: bool = False) -> None:
        """Record and publish odometry now (:meth:`OdometryPublisher.publish`)."""
        self.odometry.publish(tok, paced=paced)

    @property
    def last_odom(self) -> dict | None:
        """The latest odometry sample published (None before the first)."""
        return self.odometry.last

    @property
    def next_odom(self) -> float:
        """The vehicle time (s) of the odometry's next slot (checkpointed with the drone)."""
        return self.odometry.next_t

    @next_odom.setter
    def next_odom(self, t: float) -> None:
        self.odometry.next_t = t

    # ------------------------------------------------------------------ the clock thread
    def step(self, dt: float, tok: Any = None) -> None:
        """Advance the backend (simulator: ``dt`` seconds; others: process what arrived) and publish odometry
        when due (in lock-step, as part of the cascade ``tok``). Backend events are recorded."""
        with self.lock:
            self.backend.step(dt)
            for ev in self.backend.drain_events():
                if self.autopilot_mission and ev.get("event") in ("mission_current", "mission_item_reached"):
                    self.autopilot_flight.mission_report(ev)
                elif ev.get("event") == "link_regained":
                    self.flight.reissue = True  # the vehicle may have left guided/offboard meanwhile (PX4's failsafe)
                elif ev.get("event") == "autopilot_failsafe":
                    self._failsafe_pending = dict(ev)
                elif ev.get("event") == "command_withheld":
                    self.flight.reissue = True  # sent again on the next tick, unless the autopilot's failsafe comes first
                self._event(ev.pop("event", "backend_event"), **ev)
        self.odometry.on_step(tok)
        self.gimbal.on_step()
        if not self.done:  # plug-in sensors sample the vehicle state at their own rate while the mission runs
            for ps in self.plugin_sensors:  # (a drone settling after its mission: odometry only)
                ps.maybe_sample(self.backend, tok)

    def control_tick(self) -> bool:
        """One control tick (at ``control_rate_hz``); returns True when this drone's mission is over."""
        self.ticks += 1
        with self.lock:
            try:
                if self._end_req is not None:
                    self.flight.outcome = self._end_req
                    self._event("end_requested", reason=self._end_req)
                    self.done = True
                elif self._control():
                    self.done = True
            except BackendError as e:  # the vehicle refused or the link failed: record it, keep the run alive
                self._event("backend_error", error=str(e))
                self.error = str(e)
            except Exception as e:
                self.error = f"{type(e).__name__}: {e}"
                self.flight.outcome = "failed"
                self._event("error", message=self.error, traceback=traceback.format_exc())
                self.done = True
        return self.done

    def apply_navigation(self) -> bool:
        """New navigation was queued by the inbox: apply it now (a control step outside the tick; idempotent).
        Returns True when the drone was in a state that flies navigation (so the command reached the backend, or
        was refused)."""
        if self.done:
            return False
        with self.lock:
            if self.fsm.state not in _ACTIVE:
                return False
            self.nudges += 1
            try:
                self._control()
            except BackendError as e:
                self._event("backend_error", error=str(e))
            return True

    # ------------------------------------------------------------------ flight logic
    def next_order(self, t: float, pos: tuple) -> Order:
        """What to fly at simulated time ``t`` (s) from ``pos`` (ENU metres), from this drone's own queue; the first
        call records the plan. Caller holds ``self.lock``."""
        self.last_tick = (t, pos)
        if not self.plan_log.recorded:
            self.plan_log.record_plan(self.queue, t)
        return self.queue.order_at(t)

    def _control(self) -> bool:
        """One control step: what holds in every mission state (a replayed log is only observed; the link dropped;
        an autopilot failsafe; a short link drop to recover from), then the handler of the current mission state
        (:attr:`_handlers`, one per state of the state machine's table). Returns True when the mission is over.
        Caller holds ``self.lock``."""
        v, st, now = self.backend, self.fsm.state, self.backend.state()
        t = now.t
        if not v.navigable:
            return self._observe(t, st, now)
        if not now.link_ok:
            if st not in (S.LINK_LOST, S.LANDED):
                self.flight.link_lost_from = st
                self.fsm.transition(S.LINK_LOST, t)
                self._event("link_lost", previous=st.value)
            return False
        if self._failsafe_pending is not None:
            fs, self._failsafe_pending = self._failsafe_pending, None
            return self.autopilot_flight.on_failsafe(t, st, fs)
        if self.flight.reissue and st != S.LINK_LOST:
            self._on_link_blip(t, st)
        pos = tuple(float(c) for c in now.position)
        stalled = self.deadlines.check(t, self.fsm.state, pos)  # take-off, landing, return: each has a deadline
        if stalled is not None:
            return stalled
        return self._handlers[self.fsm.state](t, pos)

    def _on_link_blip(self, t: float, st: S) -> None:
        """A link drop shorter than a control tick: the state machine never saw it, but the vehicle may have left
        guided/offboard meanwhile, so the active waypoint is sent again."""
        self.flight.reissue = False
        if st in (S.NAVIGATING, S.WAYPOINT_HOLD) and not self.autopilot_mission:
            self._event("link_blip", resuming=st.value)
            if st == S.WAYPOINT_HOLD:
                self.fsm.transition(S.NAVIGATING, t)
            self.flight.active_wp, self.flight.hold_until = None, None

    # ------------------------------------------------------------------ one handler per mission state
    # Each takes the vehicle time ``t`` (s) and position ``pos`` (ENU metres) and returns True when the mission is
    # over. IDLE, PREFLIGHT, ARMED and LANDED get no control ticks (start() leaves ARMED in the same call; LANDED
    # ends the mission): they share the airborne handler, as they always did.
    def _on_link_lost(self, t: float, pos: tuple) -> bool:
        self.flight.reissue = False
        return self.autopilot_flight.link_regained(t)

    def _on_landing(self, t: float, pos: tuple) -> bool:
        """On the ground: LANDED, disarm, and the outcome (success only if everything planned was flown)."""
        v = self.backend
        if v.state().in_air:
            return False
        self.fsm.transition(S.LANDED, t)
        try:
            v.actions.disarm()
        except BackendError as e:
            self._event("backend_error", error=str(e))
        self._event("landed")
        if self.flight.outcome is None:
            self.flight.outcome = "success" if self._all_flown() else "incomplete"
        return True

    def _all_flown(self) -> bool:
        """Every pre-planned waypoint flown: none refused in flight (not flown), none whose hold failed (not held),
        none given up (not reached), and none cleared through the HITL API."""
        f = self.flight
        refused = any(r.get("item") == "waypoint" for r in f.rejected)
        return (f.preplanned_left == 0 and not refused and not f.hold_failed and not self.progress.not_reached
                and not self.plan_log.cleared_preplanned)

    def _on_emergency(self, t: float, pos: tuple) -> bool:
        self.backend.guidance.land()
        self.fsm.transition(S.LANDING, t)
        return False

    def _on_returning(self, t: float, pos: tuple) -> bool:
        """Fly the return path leg by leg (or let the autopilot's RTL fly it), then land at home."""
        if self._battery_critical(t):
            return False
        v = self.backend
        if self.flight.backend_rtl:
            if not v.state().in_air:
                self.fsm.transition(S.LANDING, t)
            return False
        path = self.flight.rtl_path
        if path and len(path) > 1 and math.hypot(pos[0] - path[0][0], pos[1] - path[0][1]) <= 0.5:
            path.pop(0)  # the next leg of the path around the exclusion zones
            v.guidance.goto(path[0], self.gate.max_speed)
            self._event("rtl_leg", target=list(path[0]), legs_left=len(path))
        elif math.hypot(pos[0], pos[1]) <= 0.5:
            v.guidance.land()
            self.fsm.transition(S.LANDING, t)
            self._event("landing", reason="return to launch")
        return False

    def _on_paused(self, t: float, pos: tuple) -> bool:
        """Hover until resumeMission(), then go back to what was paused; a landing meanwhile ends the flight."""
        if self._failsafe_or_pause(t, pos):
            return False
        v, now = self.backend, self.backend.state()
        if not now.in_air and not now.armed and self.flew_something_or_took_off():
            # landed while paused (the autopilot's failsafe RTL/LAND under on_failsafe: hold): the flight is over
            self.fsm.transition(S.LANDING, t)
            self.flight.outcome = self.flight.outcome or ("failsafe" if self.flight.failsafe else "incomplete")
            self._event("landing", reason="landed while paused")
            return False
        if not self._resume_req.is_set():
            return False
        self._resume_req.clear()
        back = self.flight.paused_from or S.HOVERING
        if self.autopilot_mission:  # AUTO / MISSION from its current item; refused (another mission): stays PAUSED
            v.mission.start()
        self.fsm.transition(back if back != S.WAYPOINT_HOLD else S.NAVIGATING, t)
        self._event("resumed")
        if back == S.TAKING_OFF and not self.autopilot_mission:
            v.actions.takeoff(self.takeoff_altitude)
        self.flight.active_wp = None
        self.flight.hold_until = None
        return False

    def _on_taking_off(self, t: float, pos: tuple) -> bool:
        """HOVERING once at the take-off altitude (10 cm)."""
        if self._failsafe_or_pause(t, pos):
            return False
        if self.autopilot_mission:
            return self.autopilot_flight.follow_mission(t, pos)
        v = self.backend
        if abs(v.state().position[2] - self.takeoff_altitude) < 0.1:
            self.fsm.transition(S.HOVERING, t)
            v.guidance.hold()
        return False

    def _on_airborne(self, t: float, pos: tuple) -> bool:
        """HOVERING, NAVIGATING, WAYPOINT_HOLD, TRACKING: fly what the queue says (or follow the autopilot's own
        mission)."""
        if self._failsafe_or_pause(t, pos):
            return False
        if self.autopilot_mission:
            return self.autopilot_flight.follow_mission(t, pos)
        self.queue_flight.fly(t, pos)
        return False

    # ------------------------------------------------------------------ failsafes and pause
    def _battery_critical(self, t: float) -> bool:
        """Below ``safety.critical_battery_pct`` in the air: EMERGENCY (outcome failed). True when it acted."""
        now = self.backend.state()
        if not (now.battery_pct < self.cfg.safety.critical_battery_pct and now.in_air):
            return False
        self._event("battery_critical", battery_pct=now.battery_pct)
        self.flight.outcome = "failed"
        self.fsm.transition(S.EMERGENCY, t)
        return True

    def _failsafe_or_pause(self, t: float, pos: tuple) -> bool:
        """The battery failsafes (critical: EMERGENCY; below ``safety.low_battery_rtl_pct``: return to launch) and
        a pauseMission() request (PAUSED, hovering). True when one of them took this control step."""
        v, safety = self.backend, self.cfg.safety
        if self._battery_critical(t):
            return True
        now = v.state()
        if now.battery_pct < safety.low_battery_rtl_pct and now.in_air:
            self._event("failsafe_rtl", battery_pct=now.battery_pct, threshold_pct=safety.low_battery_rtl_pct)
            self.flight.outcome = "failsafe_rtl"
            self.autopilot_flight.return_to_launch(t, pos)
            return True
        if not self._pause_req.is_set():
            return False
        self._pause_req.clear()
        st = self.fsm.state
        if st != S.PAUSED and self.fsm.can(S.PAUSED):
            self.flight.paused_from = st
            (v.mission.pause if self.autopilot_mission else v.guidance.hold)()  # the autopilot's own mission: held
            self.fsm.transition(S.PAUSED, t)
            self._event("paused")
        return True

    # ------------------------------------------------------------------ the flight so far, a replayed log
    def flew_something_or_took_off(self) -> bool:
        """The vehicle has been in the air in this run (a landed, disarmed vehicle then means the flight ended)."""
        return any(s in (S.TAKING_OFF, S.HOVERING, S.NAVIGATING) for _, s in self.fsm.history)

    def _observe(self, t: float, st: S, v: VehicleState) -> bool:
        """Not navigable (a replayed log): the stat-stream follows the vehicle's own state ``v``; ends with the log."""
        fsm = self.fsm
        finished = bool(getattr(self.backend, "finished", False))
        speed = math.hypot(float(v.velocity[0]), float(v.velocity[1]))
        if st in (S.IDLE, S.LANDED) and v.armed:  # armed again for another flight
            if st == S.LANDED:
                fsm.transition(S.IDLE, t)
            fsm.transition(S.PREFLIGHT, t)
            fsm.transition(S.ARMED, t)
        elif st == S.PREFLIGHT and v.armed:
            fsm.transition(S.ARMED, t)
        elif st == S.ARMED and not v.armed:  # disarmed without flying
            fsm.transition(S.IDLE, t)
        elif st in (S.TAKING_OFF, S.HOVERING, S.NAVIGATING) and not v.armed:  # disarm ends the flight
            fsm.transition(S.LANDING, t)
            fsm.transition(S.LANDED, t)
        elif st == S.ARMED and v.in_air:
            fsm.transition(S.TAKING_OFF, t)
        elif st == S.TAKING_OFF and v.in_air and v.velocity[2] < 0.3:
            fsm.transition(S.HOVERING, t)
        elif st in (S.HOVERING, S.NAVIGATING):
            if not v.in_air or v.velocity[2] < -0.5 and v.position[2] < 5.0:
                fsm.transition(S.LANDING, t)
            elif st == S.HOVERING and speed > 0.5:
                fsm.transition(S.NAVIGATING, t)
            elif st == S.NAVIGATING and speed < 0.2:
                fsm.transition(S.HOVERING, t)
        elif st == S.LANDING and (not v.in_air or not v.armed):
            fsm.transition(S.LANDED, t)
        if finished:  # the backend recorded its own replay_finished event
            if self.flight.outcome is None:
                self.flight.outcome = "success"
            return True
        return False
