"""How a drone flies its own waypoint queue (what AeroDaaS, not the autopilot, flies): each order the queue gives
passes the safety gate, then a waypoint is flown as a leg (NAVIGATING, its progress watched), reached (WAYPOINT_HOLD)
and held for its ``hover_duration`` (:class:`WaypointHold`), a velocity command is tracked (TRACKING), a land or rtl
action ends the flight; with nothing queued the drone hovers, and lands once its mission is done or it idled
``idle_land_s``. A mixin of :class:`~aerodaas.actors.drone.DroneComponent` (its ``_on_airborne`` state handler calls
:meth:`QueueFlight._fly_queue`), whose state (``fsm``, ``backend``, ``gate``, ``cfg``, ``queue``, ``plan_log``,
events) it shares; split from that module so that each stays one concept."""
from __future__ import annotations

import math
from dataclasses import dataclass

from aerodaas.model.types import ActionCommand, VelocityCommand, Waypoint
from aerodaas.navigation.fsm import MissionState as S
from aerodaas.navigation.safety import SafetyViolation
from aerodaas.navigation.waypoint_queue import Order


@dataclass
class WaypointHold:
    """The hold under way at a reached waypoint, in vehicle seconds, metres and m/s: when it began (``start``),
    the last control tick (``last``), the time spent within the acceptance radius (``within_s``, the only time that
    counts towards ``hover_duration``), and the largest distance to the waypoint and horizontal speed seen."""

    start: float
    last: float
    max_error_m: float
    max_speed: float
    within_s: float = 0.0

    def update(self, t: float, distance_m: float, speed_mps: float, within: bool) -> None:
        """One control tick at vehicle time ``t``: the previous tick's interval counts if it ended ``within``."""
        if within:
            self.within_s += t - self.last
        self.last = t
        self.max_error_m = max(self.max_error_m, distance_m)
        self.max_speed = max(self.max_speed, speed_mps)


class QueueFlight:
    """Mixin: flying the drone's own queue (see the module)."""

    def _fly_queue(self, t: float, pos: tuple) -> None:
        """Fly the queue's order for now: a new waypoint or velocity command passes the safety gate first (the
        choke point: nothing outside the safety limits reaches the backend), then goes to its own step."""
        res = self.next_order(t, pos)
        item = res.item
        self.preplanned_left = res.preplanned_left
        if item is not None:
            self.idle_since = None
            self.flew_something = True
        if isinstance(item, (Waypoint, VelocityCommand)) and not (isinstance(item, Waypoint) and self.active_wp == item.id):
            try:  # a velocity command is checked for the time it has left (its fence horizon shrinks as it runs)
                left = item.left_at(t) if isinstance(item, VelocityCommand) else item
                item = self.gate.check_item(left, pos, tuple(float(c) for c in self.backend.velocity))
            except SafetyViolation as e:
                self._reject(t, item, e)
                return
        if isinstance(item, ActionCommand):
            self._fly_action(t, pos, item, res)
        elif isinstance(item, VelocityCommand):
            self._fly_velocity(t, item, res)
        elif isinstance(item, Waypoint):
            target = item.to_local(self.cfg.home)
            if self.active_wp != item.id:
                self._start_leg(t, pos, item, target, res)
            else:
                self._fly_leg(t, pos, item, target)
        else:
            self._nothing_queued(t, res)

    def _fly_action(self, t: float, pos: tuple, item: ActionCommand, res: Order) -> None:
        """A land or rtl action: executed (dropped from the queue), then LANDING or the return to launch."""
        self._event("action", action=item.action, reason=item.reason, priority=res.priority)
        if self.fsm.state == S.TRACKING:
            self._event("tracking_ended")
        self.plan_log.discard(self.queue, item.id, "executed", t)
        self.preplanned_left = self.queue.pending(distance_driven_only=True)
        if item.action == "land":
            self.backend.land()
            self.fsm.transition(S.LANDING, t)
            self._event("landing", reason=item.reason or "land command")
        else:
            self._return_to_launch(t, pos)

    def _fly_velocity(self, t: float, item: VelocityCommand, res: Order) -> None:
        """A velocity command (an analytics following something): TRACKING, the velocity to the backend."""
        if self.fsm.state != S.TRACKING:
            self.fsm.transition(S.TRACKING, t)
            self._event("tracking_started", priority=res.priority, mission=res.mission, preempted=self.active_wp)
        self.backend.set_velocity((item.vx, item.vy, item.vz), item.yaw_rate)
        self.active_wp, self.hold_until = None, None

    def _start_leg(self, t: float, pos: tuple, item: Waypoint, target: tuple, res: Order) -> None:
        """A new waypoint: NAVIGATING towards its ENU ``target``, its progress watched, the command recorded."""
        if self.fsm.state == S.TRACKING:
            self._event("tracking_ended")
        self.active_wp, self.hold_until, self._hold = item.id, None, None
        self.backend.goto(target, item.speed)
        self.fsm.transition(S.NAVIGATING, t)
        self.progress.start(t, math.dist(pos, target), item.speed)
        self._event("navigate", waypoint=item.id, target=list(target), priority=res.priority, mission=res.mission)
        if self.recorder is not None:
            self.recorder.json(f"/{self.cfg.id}/nav/command", self._t_ns(t),
                               {"kind": "waypoint", "waypoint": item.model_dump(), "local": list(target),
                                "priority": res.priority}, "aerodaas.NavCommand")

    def _fly_leg(self, t: float, pos: tuple, item: Waypoint, target: tuple) -> None:
        """The waypoint being flown: given up without progress; reached (within its acceptance radius and, to hold
        there, settled below ``hold.settle_speed``): WAYPOINT_HOLD; held for its ``hover_duration``: done."""
        v = self.backend
        dist = math.dist(pos, target)
        speed = math.hypot(*tuple(float(c) for c in v.velocity)[:2])
        within = dist <= item.acceptance_radius
        if self.fsm.state == S.NAVIGATING:
            if self.progress.check(t, item, target, dist, within):
                # given up for lack of progress: dropped from the queue; the next tick flies what is queued next
                self.plan_log.discard(self.queue, item.id, "not_reached", t)
                self.active_wp, self.hold_until, self._hold = None, None, None
                return
            if not (within and (item.hover_duration <= 0 or speed <= self.cfg.hold.settle_speed)):
                return
            self.fsm.transition(S.WAYPOINT_HOLD, t)
            v.goto(target)  # keep station on the exact waypoint
            self.hold_until = t + item.hover_duration
            self._hold = WaypointHold(start=t, last=t, max_error_m=dist, max_speed=speed)
            self._event("waypoint_reached", waypoint=item.id, error_m=dist, speed=round(speed, 3))
        elif self.fsm.state == S.WAYPOINT_HOLD and self._hold is not None:
            self._hold.update(t, dist, speed, within)
        if self.fsm.state == S.WAYPOINT_HOLD and self._hold is not None:
            self._end_hold(t, pos, item, target, dist)

    def _end_hold(self, t: float, pos: tuple, item: Waypoint, target: tuple, dist: float) -> None:
        """The hold's end: done once held long enough within the radius; failed (dropped, never a success) once
        ``hold.max_time_factor`` × ``hover_duration`` + ``hold.grace_s`` passed without that."""
        h, hc = self._hold, self.cfg.hold
        if h.within_s + 1e-9 >= item.hover_duration:
            self.plan_log.complete(self.queue, item.id, t)
            self.visited.append({"id": item.id, "t": t, "position": list(pos), "target": list(target),
                                 "error_m": dist})
            self._event("waypoint_done", waypoint=item.id, held_s=round(h.within_s, 3),
                        max_error_m=round(h.max_error_m, 3))
        elif t - h.start > hc.max_time_factor * item.hover_duration + hc.grace_s:
            rec = {"waypoint": item.id, "held_s": round(h.within_s, 3), "needed_s": item.hover_duration,
                   "elapsed_s": round(t - h.start, 3), "max_error_m": round(h.max_error_m, 3),
                   "max_speed": round(h.max_speed, 3), "acceptance_radius": item.acceptance_radius}
            self.hold_failed.append(rec)
            self._event("hold_failed", **rec)
            self.plan_log.discard(self.queue, item.id, "hold_failed", t)
        else:
            return
        self.active_wp, self.hold_until, self._hold = None, None, None

    def _nothing_queued(self, t: float, res: Order) -> None:
        """Nothing to fly: land once the pre-planned mission is done or after ``idle_land_s`` idle; else hover."""
        v, st = self.backend, self.fsm.state
        if st == S.TRACKING:
            self._event("tracking_ended")
        if self.idle_since is None:
            self.idle_since = t
        done_plan = self.preplanned_total > 0 and res.preplanned_left == 0 and len(self.visited) > 0
        had_mission = self.flew_something or self.preplanned_total > 0
        idle_too_long = had_mission and t - self.idle_since >= self.cfg.idle_land_s
        if done_plan or idle_too_long:
            v.land()
            self.fsm.transition(S.LANDING, t)
            self._event("landing", reason="mission complete" if done_plan else
                        f"nothing to do for {self.cfg.idle_land_s:g} s")
            return
        if st != S.HOVERING:
            self.fsm.transition(S.HOVERING, t)
            v.hold()
