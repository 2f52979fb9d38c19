"""Whether the vehicle flies where the safety gate thinks it does: in the gate's frame (its home, checked once it
has armed: :meth:`NavigationProgress.check_vehicle_home`) and towards its waypoint (:class:`ProgressWatch`: a
target the autopilot refuses or does not progress towards becomes an event, and if that persists, the waypoint ends
as not reached).

Why: an autopilot may drop a position target without a word. ArduCopter in GUIDED ignores a
SET_POSITION_TARGET_GLOBAL_INT whose destination its own fence refuses (``ModeGuided::set_destination`` returns false
after ``AC_Fence::check_destination_within_fence``; no COMMAND_ACK exists for that message) and keeps flying to its
previous target; PX4 acknowledges a DO_REPOSITION outside its geofence and ignores it ("Reposition is outside
geofence"). A drone waiting in NAVIGATING for such a target sat there for 330 vehicle seconds until its battery
failsafe. The watch judges the vehicle's own progress, whatever the reason it stopped: the distance to the
target must shrink by ``progress.min_progress_m`` within a window, or the vehicle be inside the acceptance radius
(settling there is the hold's business, :class:`~aerodaas.config.robot.HoldConfig`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Literal

from aerodaas.backends import BackendError
from aerodaas.config import ProgressConfig
from aerodaas.navigation.safety import SafetyGate, SafetyViolation


@dataclass
class ProgressWatch:
    """The progress towards one waypoint, in vehicle seconds and metres.

    ``window_s``: how long without ``min_progress_m`` of progress before :meth:`update` says ``"stalled"`` (once per
    stall); ``abandon_s``: how long before it says ``"abandon"``. Build it with :meth:`for_leg`."""

    min_progress_m: float
    window_s: float
    abandon_s: float
    start_t: float = 0.0
    #: the distance (m) at the last progress, and when that was (vehicle s)
    ref_m: float = 0.0
    since_t: float = 0.0
    closest_m: float = 0.0
    stalled: bool = False

    @classmethod
    def for_leg(cls, cfg, t: float, distance_m: float, speed_mps: float) -> "ProgressWatch":
        """A watch for a leg begun at vehicle time ``t`` (s), ``distance_m`` from its target, flown at ``speed_mps``
        (the waypoint's speed or the robot's limit). ``cfg``: the robot's :class:`~aerodaas.config.ProgressConfig`.
        The window is ``cfg.stall_s``, longer when ``min_progress_m`` at a quarter of the speed takes longer (a
        slow leg is not a stalled one); abandonment comes at ``cfg.abandon_s``, never before the window."""
        window = max(float(cfg.stall_s), 4.0 * float(cfg.min_progress_m) / max(float(speed_mps), 1e-6))
        return cls(min_progress_m=float(cfg.min_progress_m), window_s=window,
                   abandon_s=max(float(cfg.abandon_s), window), start_t=t, ref_m=distance_m, since_t=t,
                   closest_m=distance_m)

    def update(self, t: float, distance_m: float, within: bool) -> Literal["stalled", "resumed", "abandon"] | None:
        """Feed the vehicle's distance (m) to the target at vehicle time ``t`` (s); ``within``: inside the
        waypoint's acceptance radius. Returns ``"stalled"`` when the window passed without progress (once),
        ``"resumed"`` on the first progress after that, ``"abandon"`` once ``abandon_s`` passed without progress,
        else None."""
        self.closest_m = min(self.closest_m, distance_m)
        if within or distance_m <= self.ref_m - self.min_progress_m:
            self.ref_m, self.since_t = distance_m, t
            if self.stalled:
                self.stalled = False
                return "resumed"
            return None
        waited = t - self.since_t
        if waited >= self.abandon_s:
            return "abandon"
        if waited >= self.window_s and not self.stalled:
            self.stalled = True
            return "stalled"
        return None

    def figures(self, t: float, distance_m: float) -> dict:
        """The figures events carry: distance now, closest so far, seconds since the last progress (rounded)."""
        return {"distance_m": round(distance_m, 2), "closest_m": round(self.closest_m, 2),
                "since_progress_s": round(t - self.since_t, 1)}


class NavigationProgress:
    """Whether robot ``robot_id``'s vehicle (``backend``) flies where its safety ``gate`` thinks it does: in the
    gate's frame once it has armed (:meth:`check_vehicle_home`) and towards the waypoint being flown (:meth:`start`
    a leg, :meth:`check` each tick), judged by ``cfg`` (the robot's :class:`~aerodaas.config.ProgressConfig`);
    ``event(kind, **fields)`` records the drone's events. ``watch``: the :class:`ProgressWatch` of the leg being
    flown (None before the first and after one was given up); ``not_reached``: the waypoints given up for lack of
    progress (never a success). An object of its drone (:attr:`~aerodaas.actors.drone.component.DroneComponent.progress`); it
    knows nothing else of the drone."""

    def __init__(self, backend: Any, robot_id: str, cfg: ProgressConfig, gate: SafetyGate,
                 event: Callable[..., None]) -> None:
        self.backend, self.robot_id, self.cfg, self.gate, self.event = backend, robot_id, cfg, gate, event
        self.watch: ProgressWatch | None = None
        self.not_reached: list[dict] = []

    def check_vehicle_home(self) -> None:
        """After arming (an autopilot's home is where it armed): the vehicle's frame must be the gate's
        (:meth:`~aerodaas.navigation.safety.SafetyGate.check_vehicle_home`, ``safety.home_tolerance_m``); else a
        ``vehicle_home_refused`` event, disarm, and BackendError, before any take-off."""
        b, now = self.backend, self.backend.state()
        try:
            self.gate.check_vehicle_home(now.home, now.position)
        except SafetyViolation as e:
            self.event("vehicle_home_refused", reason=e.reason, vehicle_home=[now.home.lat, now.home.lon])
            try:
                b.actions.disarm()
            except BackendError as de:
                self.event("backend_error", error=str(de))
            raise BackendError(f"robot {self.robot_id!r}: refusing to take off: {e.reason}") from None

    def start(self, t: float, distance_m: float, speed_mps: float | None) -> None:
        """A new leg: watched from vehicle time ``t`` at ``distance_m`` from its target, flown at ``speed_mps``
        (None: the gate's speed limit)."""
        self.watch = ProgressWatch.for_leg(self.cfg, t, distance_m, speed_mps or self.gate.max_speed)

    def check(self, t: float, item: Any, target: tuple, distance_m: float, within: bool) -> bool:
        """Judge one NAVIGATING tick towards waypoint ``item`` (its ENU ``target``); records ``navigation_stalled``
        / ``navigation_progress_resumed`` events and, once ``progress.abandon_s`` passed without progress, gives the
        waypoint up: a ``waypoint_abandoned`` event, a ``not_reached`` entry, the watch ended. Returns True when it
        gave the waypoint up (the drone then drops it from its queue)."""
        w = self.watch
        if w is None:
            return False
        verdict = w.update(t, distance_m, within)
        if verdict is None:
            return False
        where = {"waypoint": item.id, "target": [round(float(c), 2) for c in target], **w.figures(t, distance_m)}
        if verdict == "stalled":
            self.event("navigation_stalled", **where, window_s=round(w.window_s, 1),
                       note="the vehicle is not getting closer: an autopilot that refuses a target (its own fence "
                            "or limits) keeps flying to its previous one without a word")
        elif verdict == "resumed":
            self.event("navigation_progress_resumed", **where)
        else:
            rec = {**where, "after_s": round(w.abandon_s, 1), "elapsed_s": round(t - w.start_t, 1)}
            self.not_reached.append(rec)
            self.event("waypoint_abandoned", **rec)
            self.watch = None
            return True
        return False
