"""SchedulerComponent: a robot's navigation inbox, inside the robot's drone actor. Navigation from analytics (its
``priority`` port) and from users (the HITL API) is checked by the robot's safety gate and bounds, planned by the
trajectory scheduler plug-in (INavigate) and committed into the drone's own waypoint queue. One way: it never calls
the drone; the drone's port (:class:`aerodaas.actors.drone.inbox.DroneInbox`) applies what it took at once."""
from __future__ import annotations

import threading
import time
from typing import Any


from aerodaas.config import RobotConfig
from aerodaas.protocol.messages import Message, Port
from aerodaas.model.types import AeroNavigation, Waypoint
from aerodaas.navigation.safety import SafetyGate, SafetyViolation
from aerodaas.navigation.waypoint_queue import Order, WaypointQueue

from aerodaas.actors.data.plane import Component, DataPlane, percentiles as _percentiles
from aerodaas.actors.drone.mission_plan import MissionPlanLog

__all__ = ["Order", "SchedulerComponent"]


class SchedulerComponent(Component):
    """One robot's navigation inbox: what may enter the drone's waypoint queue, and how it is planned.

    ``scheduler``: the robot's trajectory scheduler plug-in (the paper's INavigate), asked to plan every addition;
    ``queue``: the :class:`~aerodaas.navigation.waypoint_queue.WaypointQueue` it commits into (the drone's own;
    default: the scheduler's :attr:`~aerodaas.schedulers.base.TrajectoryScheduler.queue`, for an inbox on its own).
    Analytics streams deliver navigation messages on a ``priority`` :class:`~aerodaas.protocol.messages.Port`
    (optionally ``replace``), taken by :meth:`take`; users add navigation through :meth:`add_navigation` (the HITL
    API). Everything added is checked by the robot's :class:`~aerodaas.navigation.safety.SafetyGate` and bounds
    first (all items or none). ``log``: the :class:`~aerodaas.actors.drone.mission_plan.MissionPlanLog` shared with the
    drone (plan record, discards; default: one of its own). This class never calls the drone, and the drone never
    calls it: the drone pops its own queue; on its own (with :meth:`tick` standing in for the drone) this inbox
    leaves new navigation to the next tick, while the drone's port (:class:`~aerodaas.actors.drone.inbox.DroneInbox`)
    has the drone apply it at once. The per-frame latency (frame ready -> command applied to the vehicle) is
    recorded by :meth:`record_latency`; the waypoint plan on ``/<robot>/mission/plan`` at start and whenever the
    queued waypoints change."""

    kind = "scheduler"

    def __init__(self, plane: DataPlane, cid: str, robot_id: str, scheduler: Any, recorder: Any, epoch_ns: int,
                 robot_cfg: dict | None = None, queue: WaypointQueue | None = None,
                 log: MissionPlanLog | None = None) -> None:
        super().__init__(plane, cid, buffer=4)
        self.robot_id = robot_id
        self.s = scheduler
        self.queue = queue if queue is not None else scheduler.queue
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.position = tuple(scheduler.start)
        self.now = 0.0
        self.latency: list[dict] = []
        cfg = RobotConfig.model_validate(robot_cfg) if robot_cfg else RobotConfig(id=robot_id)
        self.home = cfg.home
        self.gate = SafetyGate(cfg.safety, cfg.limits, cfg.home, control_period_s=1.0 / cfg.control_rate_hz)
        self.max_per_request = cfg.max_waypoints_per_request
        self.max_queued = cfg.max_queued_items
        self._plan_lock = threading.Lock()  # one planner at a time; never the lock the control tick takes
        self.refused: list[dict] = []
        #: the plan record, discards and cleared pre-planned waypoints (shared with the drone that owns the queue)
        self.log = log if log is not None else MissionPlanLog(robot_id, cfg.home, recorder, epoch_ns)
        self._injected: dict[int, Any] = {}  # id(item) -> item, for the items added through the HITL API
        self._replaced: set[Port] = set()

    @property
    def discarded(self) -> list[dict]:
        """Items dropped from the queue without being visited (:attr:`MissionPlanLog.discarded`)."""
        return self.log.discarded

    @property
    def cleared_preplanned(self) -> list[str]:
        """Ids of pre-planned waypoints cleared through the HITL API (the mission is then never a success)."""
        return self.log.cleared_preplanned

    def where(self) -> tuple[float, tuple]:
        """``(now, position)``: the simulated time (s) and the drone's position (ENU metres) that navigation is
        checked and planned from: those of the last :meth:`tick` (the drone's port reads its drone's)."""
        return self.now, self.position

    def tick(self, now: float, position: tuple) -> Order:
        """A control tick at simulated time ``now`` (s) and ``position`` (ENU metres), for an inbox used without
        a drone: what to fly now (see :class:`~aerodaas.navigation.waypoint_queue.Order`)."""
        self.now, self.position = now, tuple(position)
        if not self.log.recorded:
            self._record_plan()
        return self.queue.order_at(now)

    def complete(self, item_id: str) -> bool:
        """The head waypoint ``item_id`` was reached (see :meth:`MissionPlanLog.complete`)."""
        return self.log.complete(self.queue, item_id, self.where()[0])

    def discard(self, item_id: str, reason: str) -> bool:
        """Drop the head item ``item_id`` without counting it as visited (see :meth:`MissionPlanLog.discard`)."""
        return self.log.discard(self.queue, item_id, reason, self.where()[0])

    def _event(self, event: str, **kw: Any) -> None:
        if self.recorder is not None:
            now = self.where()[0]
            self.recorder.json(f"/{self.robot_id}/events", self.epoch_ns + int(now * 1e9),
                               {"robot": self.robot_id, "t": now, "event": event, **kw}, "aerodaas.MissionEvent")

    def handle(self, port: Port, msg: Message) -> None:
        """A navigation message on a ``priority`` port: :meth:`take` it; the drone applies it at its next control
        tick (its own port, :class:`~aerodaas.actors.drone.inbox.DroneInbox`, applies it at once)."""
        if self.take(port, msg):
            self.record_latency(msg, applied=False)
        return None

    def take(self, port: Port, msg: Message) -> bool:
        """Take the navigation carried by ``msg`` (from analytics, for this robot) into the queue at the port's
        priority: bounds and safety gate first, a ``replace`` port's first navigation aborts the queued missions
        (``mission_aborted``), then planned and committed. Returns True when it was queued; False when it is not
        this robot's navigation or was refused (recorded in :attr:`refused` and a ``navigation_refused`` event: the
        run goes on)."""
        prio = port.priority if port.name == "priority" else None
        nav = msg.data
        if not isinstance(nav, AeroNavigation) or msg.robot != self.robot_id:
            return False  # a shared analytics navigates each robot through that robot's own inbox
        replace = port.replace and port not in self._replaced
        now, position = self.where()
        try:
            self._check_bounds(nav, ignore_queue=replace)
            nav = self.gate.check_navigation(nav, position)
            if replace:
                self._replaced.add(port)  # pattern 5: the first navigation from this source aborts the queued missions
                self.queue.remove_queued(lambda _item: True)
                self.log.discarded.append({"id": "*", "t": now, "reason": f"mission aborted by {port.wire()}"})
                self._event("mission_aborted", by=port.wire())
            self._plan_and_add(nav, None, prio)
        except (SafetyViolation, ValueError) as e:  # an analytics asked for something unsafe: refuse it, keep running
            self.refused.append({"t": msg.sim_t, "source": "analytics", "error": str(e)})
            self._event("navigation_refused", source="analytics", error=str(e))
            return False
        if any(isinstance(w, Waypoint) for w in nav.waypoints) or port.replace:
            self._record_plan()
        return True

    def record_latency(self, msg: Message, applied: bool) -> None:
        """Record the per-frame latency of navigation ``msg`` taken into the queue (``applied``: whether the drone
        applied it to the vehicle at once) on ``/<robot>/latency``, when its frame carries a capture time; times
        in milliseconds (``e2e_ms``, ``inference_ms``, ``post_ms``, ``overhead_ms`` and the actor hop's)."""
        tr = msg.trace
        if "capture_wall" in tr:
            e2e = (time.time() - tr["capture_wall"]) * 1e3
            rec = {"robot": self.robot_id, "t": msg.sim_t, "e2e_ms": e2e, "applied": applied,
                   "inference_ms": tr.get("inference_ms", 0.0), "post_ms": tr.get("post_ms", 0.0),
                   "overhead_ms": max(0.0, e2e - tr.get("inference_ms", 0.0) - tr.get("post_ms", 0.0))}
            for k in ("put_ms", "call_ms", "get_ms", "reply_ms", "dispatch_ms"):  # the actor hop, when the frame
                # made one; the capture's wait for a pool thread after the clock's tick
                if k in tr:
                    rec[k] = tr[k]
            self.latency.append(rec)
            if self.recorder is not None:
                self.recorder.json(f"/{self.robot_id}/latency", self.epoch_ns + int(rec["t"] * 1e9), rec,
                                   "aerodaas.FrameLatency")

    def add_navigation(self, nav: Any, index: int | None = None, priority: int | None = None) -> dict:
        """Add navigation (user or application side) to the queue at ``priority`` (``index``: insert at that index
        of the mission of that priority). Raises SafetyViolation / IndexError / TypeError / ValueError (bounds) and
        then changes nothing; returns ``{"queued": snapshot, "position": ENU metres, "t": s}`` on success."""
        nav_, prio = self.s.unwrap_navigation(nav, priority)
        self._check_bounds(nav_)
        now, position = self.where()
        nav_ = self.gate.check_navigation(nav_, position)
        self._plan_and_add(nav_, index, prio)
        if nav_.name == "hitl":  # added through the HITL API: what ``clear`` with scope "injected" removes
            self._injected.update({id(w): w for w in nav_.waypoints})
        self._record_plan()
        return {"queued": self.queue.snapshot(), "position": list(position), "t": now}

    def _check_bounds(self, nav: AeroNavigation, ignore_queue: bool = False) -> None:
        """Bounded work: at most ``max_waypoints_per_request`` items per request and ``max_queued_items`` queued in
        all (robot config). Raises ValueError naming the limit; nothing is planned or queued."""
        n = len(nav.waypoints)
        if n > self.max_per_request:
            raise ValueError(f"waypoints: {n} items in one request, more than max_waypoints_per_request "
                             f"({self.max_per_request}) of robot {self.robot_id!r}")
        queued = 0 if ignore_queue else self.queue.pending()
        if queued + n > self.max_queued:
            raise ValueError(f"waypoints: {queued} items queued + {n} new exceed max_queued_items "
                             f"({self.max_queued}) of robot {self.robot_id!r}")

    def _plan_and_add(self, nav: AeroNavigation, index: int | None, prio: int) -> None:
        """Add ``nav`` (already through the gate) at ``prio``: planned on a copy of the queue, outside the lock the
        drone's control tick takes (a long re-plan never holds the tick), then every leg of the resulting tour of
        that mission, from the drone's position, is checked against the geofence (SafetyViolation naming the leg:
        nothing is queued, never a silent drop in flight), and the plan is committed under the lock, keeping what
        happened meanwhile (waypoints reached or discarded, navigation added by others)."""
        with self._plan_lock:
            position = self.where()[1]
            plan = self.s.plan_addition(self.queue, nav, index, prio, position)  # the planning, on a copy
            self._check_tour(plan.mission.items if plan.mission is not None else [], position)
            self.queue.commit(plan)

    def _check_tour(self, items: list, position: tuple) -> None:
        """Every leg of a planned tour (from ``position`` through its waypoints, ENU metres) against the geofence."""
        fence = self.gate.fence
        if fence.is_empty:
            return
        prev, prev_id = (float(position[0]), float(position[1])), "the drone's position"
        for w in items:
            if not isinstance(w, Waypoint):
                continue
            x, y, _ = w.to_local(self.home)
            why = fence.check_segment(prev, (x, y))
            if why is not None:
                self.gate.rejected += 1
                raise SafetyViolation(w.id, "leg", [prev_id, w.id], f"the planned tour's leg from {prev_id} to "
                                      f"{w.id!r} is refused by the geofence: {why}")
            prev, prev_id = (x, y), repr(w.id)

    def clear_navigation(self, priority: int | None = None, scope: str = "all", by: str = "app") -> dict:
        """Abort queued navigation (a cleared mission never resumes): every mission (``scope="all"``) or only the
        navigation added through the HITL API (``scope="injected"``: items of navigation named ``hitl``), at ``priority``
        when given. Cleared pre-planned waypoints are recorded as a ``navigation_cleared`` event; cleared by the
        HITL API (``by="hitl"``) they make the mission ``incomplete`` (:attr:`cleared_preplanned`), never a
        success. Returns ``{"cleared": [waypoint ids], "preplanned": [ids of pre-planned ones]}``. Raises
        ValueError for an unknown scope."""
        if scope not in ("all", "injected"):
            raise ValueError(f"clear: scope {scope!r} is not 'injected' or 'all'")
        injected = self._injected
        gone = self.queue.remove_queued(lambda i: scope == "all" or id(i) in injected, priority)
        ids = [i.id for i in gone if isinstance(i, Waypoint)]
        pre = [i.id for i in gone if isinstance(i, Waypoint) and id(i) not in self._injected]
        for i in gone:
            self._injected.pop(id(i), None)
        if pre and by == "hitl":
            self.log.cleared_preplanned.extend(pre)
        if ids:
            self._event("navigation_cleared", scope=scope, by=by, waypoints=ids[:100], preplanned=pre[:100])
        self._record_plan()
        return {"cleared": ids, "preplanned": pre}

    def snapshot(self) -> list[dict]:
        """The queue as JSON-ready dicts in flying order (:meth:`WaypointQueue.snapshot`)."""
        return self.queue.snapshot()

    def _record_plan(self) -> None:
        """Record the queued waypoints when they changed since the last record (:meth:`MissionPlanLog.record_plan`)."""
        self.log.record_plan(self.queue, self.where()[0])

    def stats(self) -> dict:
        """Completed waypoint ids, refusals, discards, the mailbox's counts and latency percentiles (ms)."""
        out: dict[str, Any] = {"completed": list(self.queue.completed), "frames_with_latency": len(self.latency),
                               "refused": self.refused[-20:], "refused_count": len(self.refused),
                               "discarded": self.log.discarded, **self.mailbox_stats()}
        if self.latency:
            for key in ("e2e_ms", "overhead_ms", "inference_ms"):
                out[key] = _percentiles([r[key] for r in self.latency])
            out["latency_records"] = list(self.latency)
        return out
