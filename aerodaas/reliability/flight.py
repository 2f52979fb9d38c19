"""Randomized flights against the safety gate: the embedded simulator's vehicle driven by arbitrary command sequences
through :class:`aerodaas.navigation.safety.SafetyGate`, exactly as the drone component does (every control tick: the head
command is checked with the vehicle's position and velocity; a refused one makes the vehicle hold), measuring from
the vehicle's odometry how far it ever got outside its inclusion fence, into an exclusion zone, or above
``max_altitude``. Used by ``tests/safety/test_safety_model.py`` (hypothesis) and ``python -m aerodaas.reliability``."""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any, Sequence

import pymap3d
from shapely.geometry import Point

from aerodaas.config import RobotConfig
from aerodaas.model.types import VelocityCommand, Waypoint
from aerodaas.navigation.safety import SafetyGate, SafetyViolation
from aerodaas.sim.vehicle import SimVehicle

__all__ = ["PROBE_ENV", "Excursion", "fly_commands", "random_commands"]

#: the probe's robot: 3 m/s, 2 m/s² (a velocity push at the fence), a 60 m square inclusion fence around home with an
#: exclusion circle of 6 m radius inside it, and max_altitude 10 m
PROBE_HOME = (47.3977, 8.5456, 488.0)


def _probe_robot(on_violation: str = "reject") -> Any:
    def ll(e: float, n: float) -> list[float]:
        lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, *PROBE_HOME)
        return [lat, lon]

    square = [ll(-30, -30), ll(30, -30), ll(30, 30), ll(-30, 30)]
    return RobotConfig.model_validate({
        "id": "probe", "home": {"lat": PROBE_HOME[0], "lon": PROBE_HOME[1], "alt": PROBE_HOME[2]},
        "takeoff_altitude": 3.0,
        "limits": {"max_speed": 3.0, "max_vertical_speed": 1.5, "max_acceleration": 2.0},
        "safety": {"max_altitude": 10.0, "min_altitude": 1.0, "on_violation": on_violation,
                   "geofence": {"polygons": [{"points": square, "inclusion": True}],
                                "circles": [{"center": ll(12.0, 8.0), "radius": 6.0, "inclusion": False}]}}})


PROBE_ENV = _probe_robot


@dataclass
class Excursion:
    """Worst excursions seen (metres; 0 = never outside): beyond the inclusion fence, into an exclusion zone, above
    max_altitude; ``samples`` odometry samples checked, ``rejected`` commands the gate refused."""

    outside_inclusion_m: float = 0.0
    inside_exclusion_m: float = 0.0
    above_max_altitude_m: float = 0.0
    samples: int = 0
    rejected: int = 0
    accepted: int = 0
    worst: dict = field(default_factory=dict)

    def merge(self, o: "Excursion") -> None:
        self.outside_inclusion_m = max(self.outside_inclusion_m, o.outside_inclusion_m)
        self.inside_exclusion_m = max(self.inside_exclusion_m, o.inside_exclusion_m)
        self.above_max_altitude_m = max(self.above_max_altitude_m, o.above_max_altitude_m)
        self.samples += o.samples
        self.rejected += o.rejected
        self.accepted += o.accepted


def fly_commands(commands: Sequence[tuple], on_violation: str = "reject", physics_hz: float = 50.0) -> Excursion:
    """Fly ``commands`` on a :class:`~aerodaas.sim.vehicle.SimVehicle` behind the probe robot's gate.

    Each command is ``("vel", vx, vy, vz, duration_s, ticks)``, ``("wp", x, y, z, ticks)`` or ``("hold", ticks)``,
    issued at a control tick (10 Hz) and kept for ``ticks`` ticks: a velocity command is re-checked at every tick
    (as the drone does) and expires after its duration (then the vehicle holds); a waypoint is checked once when it
    becomes active. Take-off to the configured altitude first. Returns the worst excursions seen at every physics
    step (from the vehicle's odometry, noise-free)."""
    flight = _ProbeFlight(_probe_robot(on_violation), physics_hz)
    flight.take_off()
    for c in commands:
        if c[0] == "hold":
            flight.veh.hold()
            flight.run_ticks(int(c[1]))
        elif c[0] == "wp":
            flight.waypoint(c[1], c[2], c[3], int(c[4]))
        else:
            flight.velocity(c[1], c[2], c[3], c[4], int(c[5]))
    return flight.ex


class _ProbeFlight:
    """:func:`fly_commands`' vehicle behind the probe robot ``cfg``'s gate, stepped at ``physics_hz`` with the
    gate's control ticks, and the excursions measured at every physics step."""

    def __init__(self, cfg: Any, physics_hz: float) -> None:
        self.point = Point
        self.cfg = cfg
        self.gate = SafetyGate(cfg.safety, cfg.limits, cfg.home, control_period_s=1.0 / cfg.control_rate_hz)
        self.veh = SimVehicle("probe", cfg.home, cfg.limits, cfg.battery)
        self.dt = 1.0 / physics_hz
        self.steps_per_tick = max(1, round(physics_hz / cfg.control_rate_hz))
        self.inc, self.exc = list(self.gate.fence.inclusions), list(self.gate.fence.exclusions)
        self.ex = Excursion()

    def measure(self) -> None:
        """The vehicle's excursions now (noise-free odometry): outside the inclusion zones, inside the exclusion
        zones, above the maximum altitude (m); the worst of each is kept with where it happened."""
        Point, ex, o = self.point, self.ex, self.veh.odometry()
        x, y, z = o.position
        ex.samples += 1
        if self.inc:
            out = min(_outside(zn, x, y, Point) for zn in self.inc)
            if out > ex.outside_inclusion_m:
                ex.outside_inclusion_m, ex.worst["inclusion"] = out, (x, y, z)
        for zn in self.exc:
            depth = _inside(zn, x, y, Point)
            if depth > ex.inside_exclusion_m:
                ex.inside_exclusion_m, ex.worst["exclusion"] = depth, (x, y, z)
        if z - self.gate.max_alt > ex.above_max_altitude_m:
            ex.above_max_altitude_m, ex.worst["altitude"] = z - self.gate.max_alt, (x, y, z)

    def run_ticks(self, n: int, on_tick: Any = None) -> None:
        """``n`` control ticks: ``on_tick()`` at each, then the physics steps of one tick, each measured."""
        for _ in range(n):
            if on_tick is not None:
                on_tick()
            for _ in range(self.steps_per_tick):
                self.veh.step(self.dt)
                self.measure()

    def take_off(self) -> None:
        self.veh.arm()
        self.veh.takeoff(self.gate.check_takeoff(self.cfg.takeoff_altitude))
        self.run_ticks(60)

    def waypoint(self, x: float, y: float, z: float, ticks: int) -> None:
        """A waypoint, checked once by the gate when it becomes active (refused: the vehicle holds)."""
        veh, wp = self.veh, Waypoint(id="w", x=x, y=y, z=z)
        try:
            wp = self.gate.check_waypoint(wp, tuple(veh.state.position), tuple(veh.state.velocity))
            veh.goto(wp.to_local(self.cfg.home), wp.speed)
            self.ex.accepted += 1
        except SafetyViolation:
            self.ex.rejected += 1
            veh.hold()
        self.run_ticks(ticks)

    def velocity(self, vx: float, vy: float, vz: float, duration_s: float, ticks: int) -> None:
        """A velocity command re-checked at every tick (as the drone does) until it expires after ``duration_s``
        or is refused; then the vehicle holds."""
        cmd, veh, ex = VelocityCommand(vx=vx, vy=vy, vz=vz, duration=duration_s), self.veh, self.ex
        left, live = [duration_s], [True]

        def tick() -> None:
            if not live[0]:
                return
            if left[0] <= 1e-9:  # expired: nothing queued, the drone holds
                live[0] = False
                veh.hold()
                return
            try:
                ok = self.gate.check_velocity(cmd, tuple(veh.state.position), tuple(veh.state.velocity))
                veh.set_velocity((ok.vx, ok.vy, ok.vz))
                ex.accepted += 1
            except SafetyViolation:
                ex.rejected += 1
                live[0] = False
                veh.hold()
            left[0] -= 1.0 / self.cfg.control_rate_hz

        self.run_ticks(ticks, tick)


def _outside(zone: Any, x: float, y: float, Point: Any) -> float:
    if zone.polygon is not None:
        return 0.0 if zone.polygon.covers(Point(x, y)) else float(zone.polygon.exterior.distance(Point(x, y)))
    return max(0.0, math.hypot(x - zone.center[0], y - zone.center[1]) - zone.radius)


def _inside(zone: Any, x: float, y: float, Point: Any) -> float:
    if zone.polygon is not None:
        return float(zone.polygon.exterior.distance(Point(x, y))) if zone.polygon.contains(Point(x, y)) else 0.0
    return max(0.0, zone.radius - math.hypot(x - zone.center[0], y - zone.center[1]))


def random_commands(rng: random.Random, n: int = 25) -> list[tuple]:
    """A random command sequence biased towards the attacks: fast velocity commands at the fence edges, the
    exclusion zone and the ceiling, waypoints beyond them, holds."""
    out: list[tuple] = []
    for _ in range(n):
        r = rng.random()
        if r < 0.6:
            ang = rng.uniform(0, 2 * math.pi)
            sp = rng.choice([3.0, 3.0, rng.uniform(0, 3.5)])
            out.append(("vel", sp * math.cos(ang), sp * math.sin(ang), rng.choice([0.0, 1.5, -1.0, rng.uniform(-2, 2)]),
                        rng.choice([0.5, 0.5, rng.uniform(0.1, 3.0)]), rng.randint(1, 40)))
        elif r < 0.9:
            out.append(("wp", rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(0.5, 12), rng.randint(5, 80)))
        else:
            out.append(("hold", rng.randint(1, 20)))
    return out
