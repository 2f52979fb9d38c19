"""What a drone's flights share with the drone: the flight state both read and write (:class:`FlightState`: the
waypoint being flown and its hold, the waypoints visited, refused or not held, the idle time, how much of the
pre-planned mission is left, the outcome, the failsafe, the return path, what a pause or a link loss interrupted)
and the drone's collaborators a flight works with (:class:`FlightContext`). The drone
(:class:`~aerodaas.actors.drone.component.DroneComponent`) owns one of each and hands them to its flight objects:
:class:`~aerodaas.actors.drone.queue_flight.QueueFlight` (its own queue) and
:class:`~aerodaas.actors.drone.autopilot.AutopilotFlight` (the autopilot's own mission, failsafes, link regain, the
return to launch). Neither flight knows the drone, nor the other flight."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from aerodaas.actors.drone.progress import NavigationProgress
from aerodaas.actors.drone.mission_plan import MissionPlanLog
from aerodaas.config import RobotConfig
from aerodaas.navigation.fsm import MissionFSM, MissionState
from aerodaas.navigation.safety import SafetyGate
from aerodaas.model.types import Waypoint
from aerodaas.navigation.waypoint_queue import Order, WaypointQueue


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


@dataclass
class FlightState:
    """The state of one drone's flight that the drone and its flight objects read and write (times in vehicle
    seconds, positions ENU metres). ``preplanned_total`` / ``preplanned_left``: the pre-planned (distance-driven)
    missions given and not yet flown; ``active_wp``: the id of the waypoint being flown (None: the next control
    step issues what is queued); ``hold_until`` and ``hold``: the hold at the reached waypoint; ``visited``: the
    waypoints done (id, time, position, target, error); ``rejected``: commands the safety gate refused;
    ``hold_failed``: waypoints whose hold could not be kept; ``idle_since``: when the drone last had nothing to fly;
    ``flew_something``: the queue gave it something to fly in this run; ``outcome``: how the mission ended (None
    while it runs); ``failsafe``: the autopilot's failsafe and what was done about it; ``backend_rtl``: the
    autopilot flies the return to launch; ``rtl_path``: else the legs AeroDaaS flies home; ``paused_from`` /
    ``link_lost_from``: the state a pause or a link loss interrupted; ``reissue``: the link dropped and came back,
    so the active target is sent again; ``preplanned_items``: the object ids of the queue's pre-planned waypoints
    not yet done (:meth:`waypoint_done` marks each visited waypoint ``preplanned`` or not)."""

    preplanned_total: int = 0
    preplanned_left: int = 0
    active_wp: str | None = None
    hold_until: float | None = None
    hold: WaypointHold | None = None
    visited: list[dict] = field(default_factory=list)
    rejected: list[dict] = field(default_factory=list)
    hold_failed: list[dict] = field(default_factory=list)
    idle_since: float | None = None
    flew_something: bool = False
    outcome: str | None = None
    failsafe: dict | None = None
    backend_rtl: bool = False
    rtl_path: list[tuple] | None = None
    paused_from: MissionState | None = None
    link_lost_from: MissionState | None = None
    reissue: bool = False
    preplanned_items: set[int] = field(default_factory=set)

    def mark_preplanned(self, queue: WaypointQueue) -> None:
        """The waypoints of ``queue``'s pre-planned (distance-driven) missions are the pre-planned ones (the
        drone's queue as it was given, before anything was added in flight)."""
        self.preplanned_items = {id(w) for m in queue.missions() if m.distance_driven for w in m.items
                                 if isinstance(w, Waypoint)}

    def waypoint_done(self, item: Any, rec: dict) -> None:
        """Waypoint ``item`` (the queue's own object) was reached and held: ``rec`` (``id``, ``t``, ``position``,
        ``target``, ``error_m``) joins :attr:`visited`, with ``preplanned`` saying whether it was pre-planned."""
        rec["preplanned"] = id(item) in self.preplanned_items
        self.preplanned_items.discard(id(item))
        self.visited.append(rec)

    @property
    def preplanned_reached(self) -> int:
        """How many of the pre-planned waypoints were reached (the others visited were added in flight)."""
        return sum(1 for v in self.visited if v.get("preplanned"))


@dataclass(frozen=True)
class FlightContext:
    """The drone's collaborators a flight works with: the robot's configuration ``cfg``, its vehicle ``backend``,
    its safety ``gate`` (every command passes it), its mission state machine ``fsm``, its waypoint ``queue`` and
    ``plan_log``, its navigation ``progress`` watch; ``event(kind, **fields)`` records a mission event;
    ``next_order(t, pos)`` says what the queue gives to fly at vehicle time ``t`` (s) from ``pos`` (ENU metres),
    recording the plan on the first call; ``nav_command(t, command)`` records a navigation command sent (or
    followed) at ``t``."""

    cfg: RobotConfig
    backend: Any
    gate: SafetyGate
    fsm: MissionFSM
    queue: WaypointQueue
    plan_log: MissionPlanLog
    progress: NavigationProgress
    event: Callable[..., None]
    next_order: Callable[[float, tuple], Order]
    nav_command: Callable[[float, dict], None]
