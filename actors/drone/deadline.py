"""Every flight phase of a drone is bounded: take-off, landing and the return to launch each get a
deadline in vehicle seconds when the drone enters them (:mod:`aerodaas.navigation.deadlines`, the robot's
``deadlines`` settings: :class:`~aerodaas.config.deadlines.PhaseDeadlinesConfig`). Past it the phase is stalled:
a ``takeoff_stalled`` / ``landing_stalled`` / ``rtl_stalled`` event, an outcome that is not success, and the
configured action (land, hold, or abort the mission). An object of its drone
(:attr:`~aerodaas.actors.drone.component.DroneComponent.deadlines`), given the drone's collaborators and the flight state it
shares with the drone (:mod:`aerodaas.actors.drone.flight`); it knows nothing else of the drone."""
from __future__ import annotations

import math
from dataclasses import dataclass

from aerodaas.actors.drone.flight import FlightContext, FlightState
from aerodaas.navigation import deadlines as dl
from aerodaas.navigation.fsm import MissionState as S


@dataclass(frozen=True)
class PhaseTimer:
    """The deadline under way: the phase (a mission state), its name in events and outcomes (``takeoff``,
    ``landing``, ``rtl``), when it started and how long it may take (vehicle seconds), the legs it was derived from
    (empty: a fixed deadline from the configuration), and whether it is the landing commanded once more."""

    state: S
    name: str
    start: float
    seconds: float
    legs: tuple[dl.Leg, ...]
    again: bool = False


class PhaseDeadlines:
    """Watches the phases of one drone's flight. ``ctx``: the drone's collaborators (its configuration's
    ``deadlines``, ``limits`` and ``takeoff_altitude``, backend, gate, state machine, event recorder); ``flight``: the
    flight state shared with the drone (the return path, whether the autopilot flies the return; this object writes
    the outcome and what a hold interrupted). :meth:`check` runs at every control step."""

    def __init__(self, ctx: FlightContext, flight: FlightState) -> None:
        self.ctx, self.flight = ctx, flight
        self.timer: PhaseTimer | None = None

    def check(self, t: float, st: S, pos: tuple) -> bool | None:
        """The control step at vehicle time ``t`` (s) in state ``st`` with the vehicle at ``pos`` (ENU metres):
        start the deadline of a phase just entered, or act on one overrun. Returns None when nothing was done (the
        state's own handler runs), else whether the mission is over (True after an abort). Raises the backend's
        BackendError when the vehicle refuses the action's command (the stall is recorded before)."""
        if st not in (S.TAKING_OFF, S.LANDING, S.RETURNING):
            self.timer = None
            return None
        if self.timer is None or self.timer.state != st:
            self.timer = self._start(t, st, pos)
            return None
        if t - self.timer.start <= self.timer.seconds:
            return None
        return self._stalled(t, pos, self.timer)

    def _start(self, t: float, st: S, pos: tuple, again: bool = False) -> PhaseTimer:
        """The deadline of phase ``st`` entered at ``t`` with the vehicle at ``pos``."""
        c, f = self.ctx.cfg.deadlines, self.flight
        lim = self.ctx.cfg.limits
        if st == S.TAKING_OFF:
            name, fixed = "takeoff", c.takeoff_s
            legs = dl.takeoff_legs(pos[2], self.ctx.cfg.takeoff_altitude, lim.max_vertical_speed)
        elif st == S.LANDING:
            name, fixed = "landing", c.landing_s
            legs = dl.landing_legs(pos[2], lim.max_vertical_speed, c.landing_speed)
        else:
            name, fixed = "rtl", c.rtl_s
            legs = dl.return_legs(pos, f.rtl_path or [], self.ctx.gate.max_speed, lim.max_vertical_speed,
                                  c.landing_speed, c.autopilot_return_alt if f.backend_rtl else None)
        seconds = fixed if fixed is not None else dl.deadline_s(legs, c.speed_factor, c.margin_s)
        return PhaseTimer(st, name, t, seconds, () if fixed is not None else legs, again)

    def _action(self, timer: PhaseTimer) -> str:
        """The configured action of the phase (a landing commanded once more that stalls again: abort)."""
        c = self.ctx.cfg.deadlines
        if timer.state == S.TAKING_OFF:
            return c.on_takeoff_stalled
        if timer.state == S.RETURNING:
            return c.on_rtl_stalled
        return "abort" if timer.again else c.on_landing_stalled

    def _stalled(self, t: float, pos: tuple, timer: PhaseTimer) -> bool:
        """Record the stall, set the outcome, carry out the action. Returns True when the mission is over. The
        deadline is spent first: a command the vehicle refuses (BackendError) leaves the phase, still under way,
        a new deadline from the next control step, never a stall at every step."""
        ctx, f = self.ctx, self.flight
        self.timer = None
        action = self._action(timer)
        ctx.event(f"{timer.name}_stalled", deadline_s=round(timer.seconds, 3), elapsed_s=round(t - timer.start, 3),
                  legs=[{"kind": g.kind, "distance_m": round(g.distance_m, 2), "speed_mps": g.speed_mps}
                        for g in timer.legs], height_m=round(float(pos[2]), 2),
                  distance_from_home_m=round(math.hypot(pos[0], pos[1]), 2), action=action)
        f.outcome = f.outcome or f"{timer.name}_stalled"
        v, fsm = ctx.backend, ctx.fsm
        if action == "abort":
            return True
        if action == "hold":
            f.paused_from = timer.state
            v.guidance.hold()
            fsm.transition(S.PAUSED, t)
            ctx.event("paused", reason=f"{timer.name} stalled")
            return False
        if timer.state == S.LANDING:  # the landing commanded once more, with a new deadline
            v.guidance.land()
            self.timer = self._start(t, S.LANDING, pos, again=True)
            ctx.event("landing", reason="landing stalled: commanded again")
            return False
        f.active_wp, f.rtl_path = None, None
        v.guidance.land()
        fsm.transition(S.LANDING, t)
        ctx.event("landing", reason=f"{timer.name} stalled: landing where it is")
        return False
