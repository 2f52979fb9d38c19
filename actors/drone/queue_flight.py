"""How a drone flies its own waypoint queue (what AeroDaaS, not the autopilot, flies): each order the queue gives
passes the safety gate, then a waypoint is flown as a leg (NAVIGATING, its progress watched), reached (WAYPOINT_HOLD)
and held for its ``hover_duration`` (:class:`~aerodaas.actors.drone.flight.WaypointHold`), a velocity command is
tracked (TRACKING), a land or rtl action ends the flight, a command outside the safety limits is refused; with
nothing queued the drone hovers, and lands once its mission is done or it idled ``idle_land_s``. An object of its
drone (:attr:`~aerodaas.actors.drone.component.DroneComponent.queue_flight`; the drone's airborne state handler calls
:meth:`QueueFlight.fly`), given the drone's collaborators and the flight state it shares with the drone
(:mod:`aerodaas.actors.drone.flight`); it knows nothing else of the drone."""
from __future__ import annotations

import math
from typing import Any, Callable

from aerodaas.actors.drone.flight import FlightContext, FlightState, WaypointHold
from aerodaas.model.types import ActionCommand, VelocityCommand, Waypoint
from aerodaas.navigation.fsm import MissionState as S
from aerodaas.navigation.safety import SafetyViolation
from aerodaas.navigation.waypoint_queue import Order

__all__ = ["QueueFlight"]


class QueueFlight:
    """Flies the drone's own queue (see the module): :meth:`fly` once per control step in HOVERING, NAVIGATING,
    WAYPOINT_HOLD or TRACKING. ``ctx``: the drone's collaborators; ``flight``: the flight state shared with the
    drone (this object writes the waypoint being flown, its hold, the visited / rejected / not-held waypoints, the
    idle time and what is left of the pre-planned mission); ``return_to_launch(t, pos)``: starts the return to
    launch at vehicle time ``t`` (s) from ``pos`` (ENU metres), for an rtl action."""

    def __init__(self, ctx: FlightContext, flight: FlightState,
                 return_to_launch: Callable[[float, tuple], None]) -> None:
        self.ctx, self.flight, self.return_to_launch = ctx, flight, return_to_launch

    def fly(self, t: float, pos: tuple) -> None:
        """Fly the queue's order for vehicle time ``t`` (s) from ``pos`` (ENU metres): a new waypoint or velocity
        command passes the safety gate first (the choke point: nothing outside the safety limits reaches the
        backend), then goes to its own step."""
        c, f = self.ctx, self.flight
        res = c.next_order(t, pos)
        item = res.item
        f.preplanned_left = res.preplanned_left
        if item is not None:
            f.idle_since = None
            f.flew_something = True
        if isinstance(item, (Waypoint, VelocityCommand)) and not (isinstance(item, Waypoint) and f.active_wp == item.id):
            try:  # a velocity command is checked for the time it has left (its fence horizon shrinks as it runs)
                left = item.left_at(t) if isinstance(item, VelocityCommand) else item
                item = c.gate.check_item(left, pos, tuple(float(v) for v in c.backend.state().velocity))
            except SafetyViolation as e:
                self.reject(t, item, e)
                return
        if isinstance(item, ActionCommand):
            self._fly_action(t, pos, item, res)
        elif isinstance(item, VelocityCommand):
            self._fly_velocity(t, item, res)
        elif isinstance(item, Waypoint):
            target = item.to_local(c.cfg.home)
            if f.active_wp != item.id:
                self._start_leg(t, pos, item, target, res)
            else:
                self._fly_leg(t, pos, item, target)
        else:
            self._nothing_queued(t, res)

    def reject(self, t: float, item: Any, err: SafetyViolation) -> None:
        """A command outside the safety limits at vehicle time ``t`` (s): never sent to the backend; dropped from
        the queue, recorded in :attr:`FlightState.rejected <aerodaas.actors.drone.flight.FlightState.rejected>` and
        as a ``command_rejected`` event; the vehicle holds where it is."""
        c, f = self.ctx, self.flight
        rec = {"id": getattr(item, "id", "?"), "t": t, "field": err.field, "value": err.value, "reason": err.reason,
               "item": "waypoint" if isinstance(item, Waypoint) else type(item).__name__}
        f.rejected.append(rec)
        c.event("command_rejected", **rec)
        c.plan_log.discard(c.queue, rec["id"], f"rejected: {err.reason}", t)
        if c.fsm.state == S.TRACKING:
            c.event("tracking_ended")
        if c.fsm.state in (S.TRACKING, S.NAVIGATING, S.WAYPOINT_HOLD):
            c.fsm.transition(S.HOVERING, t)
        c.backend.guidance.hold()
        f.active_wp, f.hold_until = None, None

    def _fly_action(self, t: float, pos: tuple, item: ActionCommand, res: Order) -> None:
        """A land or rtl action: executed (dropped from the queue), then LANDING or the return to launch."""
        c = self.ctx
        c.event("action", action=item.action, reason=item.reason, priority=res.priority)
        if c.fsm.state == S.TRACKING:
            c.event("tracking_ended")
        c.plan_log.discard(c.queue, item.id, "executed", t)
        self.flight.preplanned_left = c.queue.pending(distance_driven_only=True)
        if item.action == "land":
            c.backend.guidance.land()
            c.fsm.transition(S.LANDING, t)
            c.event("landing", reason=item.reason or "land command")
        else:
            self.return_to_launch(t, pos)

    def _fly_velocity(self, t: float, item: VelocityCommand, res: Order) -> None:
        """A velocity command (an analytics following something): TRACKING, the velocity to the backend."""
        c, f = self.ctx, self.flight
        if c.fsm.state != S.TRACKING:
            c.fsm.transition(S.TRACKING, t)
            c.event("tracking_started", priority=res.priority, mission=res.mission, preempted=f.active_wp)
        c.backend.guidance.set_velocity((item.vx, item.vy, item.vz), item.yaw_rate)
        f.active_wp, f.hold_until = None, None

    def _start_leg(self, t: float, pos: tuple, item: Waypoint, target: tuple, res: Order) -> None:
        """A new waypoint: NAVIGATING towards its ENU ``target``, its progress watched, the command recorded."""
        c, f = self.ctx, self.flight
        if c.fsm.state == S.TRACKING:
            c.event("tracking_ended")
        f.active_wp, f.hold_until, f.hold = item.id, None, None
        c.backend.guidance.goto(target, item.speed)
        c.fsm.transition(S.NAVIGATING, t)
        c.progress.start(t, math.dist(pos, target), item.speed)
        c.event("navigate", waypoint=item.id, target=list(target), priority=res.priority, mission=res.mission)
        c.nav_command(t, {"kind": "waypoint", "waypoint": item.model_dump(), "local": list(target),
                          "priority": res.priority})

    def _fly_leg(self, t: float, pos: tuple, item: Waypoint, target: tuple) -> None:
        """The waypoint being flown: given up without progress; reached (within its acceptance radius and, to hold
        there, settled below ``hold.settle_speed``): WAYPOINT_HOLD; held for its ``hover_duration``: done."""
        c, f = self.ctx, self.flight
        v, now = c.backend, c.backend.state()
        dist = math.dist(pos, target)
        speed = math.hypot(*tuple(float(x) for x in now.velocity)[:2])
        radius = c.cfg.hold.radius(item.acceptance_radius, now.position_accuracy_m)  # the vehicle's accuracy at least
        within = dist <= radius
        if c.fsm.state == S.NAVIGATING:
            if c.progress.check(t, item, target, dist, within):
                # given up for lack of progress: dropped from the queue; the next tick flies what is queued next
                c.plan_log.discard(c.queue, item.id, "not_reached", t)
                f.active_wp, f.hold_until, f.hold = None, None, None
                return
            if not (within and (item.hover_duration <= 0 or speed <= c.cfg.hold.settle_speed)):
                return
            c.fsm.transition(S.WAYPOINT_HOLD, t)
            v.guidance.goto(target)  # keep station on the exact waypoint
            f.hold_until = t + item.hover_duration
            f.hold = WaypointHold(start=t, last=t, max_error_m=dist, max_speed=speed)
            c.event("waypoint_reached", waypoint=item.id, error_m=dist, speed=round(speed, 3),
                    **_widened(item, radius))
        elif c.fsm.state == S.WAYPOINT_HOLD and f.hold is not None:
            f.hold.update(t, dist, speed, within)
        if c.fsm.state == S.WAYPOINT_HOLD and f.hold is not None:
            self._end_hold(t, pos, item, target, dist, radius)

    def _end_hold(self, t: float, pos: tuple, item: Waypoint, target: tuple, dist: float, radius: float) -> None:
        """The hold's end: done once held long enough within the radius; failed (dropped, never a success) once
        ``hold.max_time_factor`` × ``hover_duration`` + ``hold.grace_s`` passed without that."""
        c, f = self.ctx, self.flight
        h, hc = f.hold, c.cfg.hold
        if h.within_s + 1e-9 >= item.hover_duration:
            c.plan_log.complete(c.queue, item.id, t)
            f.waypoint_done(item, {"id": item.id, "t": t, "position": list(pos), "target": list(target),
                                   "error_m": dist})
            c.event("waypoint_done", waypoint=item.id, held_s=round(h.within_s, 3),
                    max_error_m=round(h.max_error_m, 3))
        elif t - h.start > hc.max_time_factor * item.hover_duration + hc.grace_s:
            rec = {"waypoint": item.id, "held_s": round(h.within_s, 3), "needed_s": item.hover_duration,
                   "elapsed_s": round(t - h.start, 3), "max_error_m": round(h.max_error_m, 3),
                   "max_speed": round(h.max_speed, 3), "acceptance_radius": radius, **_widened(item, radius)}
            f.hold_failed.append(rec)
            c.event("hold_failed", **rec)
            c.plan_log.discard(c.queue, item.id, "hold_failed", t)
        else:
            return
        f.active_wp, f.hold_until, f.hold = None, None, None

    def _nothing_queued(self, t: float, res: Order) -> None:
        """Nothing to fly: land once the pre-planned mission is done or after ``idle_land_s`` idle; else hover."""
        c, f = self.ctx, self.flight
        v, st = c.backend, c.fsm.state
        if st == S.TRACKING:
            c.event("tracking_ended")
        if f.idle_since is None:
            f.idle_since = t
        done_plan = f.preplanned_total > 0 and res.preplanned_left == 0 and len(f.visited) > 0
        had_mission = f.flew_something or f.preplanned_total > 0
        idle_too_long = had_mission and t - f.idle_since >= c.cfg.idle_land_s
        if done_plan or idle_too_long:
            v.guidance.land()
            c.fsm.transition(S.LANDING, t)
            c.event("landing", reason="mission complete" if done_plan else
                    f"nothing to do for {c.cfg.idle_land_s:g} s")
            return
        if st != S.HOVERING:
            c.fsm.transition(S.HOVERING, t)
            v.guidance.hold()


def _widened(item: Waypoint, radius: float) -> dict:
    """``{"radius_widened": {"from_m", "to_m"}}`` when the hold radius is the vehicle's position accuracy, wider than
    the waypoint's ``acceptance_radius`` (``HoldConfig.radius``); else ``{}``."""
    if radius > item.acceptance_radius:
        return {"radius_widened": {"from_m": item.acceptance_radius, "to_m": round(radius, 3),
                                   "why": "the vehicle's reported position accuracy (GPS_RAW_INT h_acc)"}}
    return {}
