"""Randomized flights against the safety gate: the embedded simulator's vehicle driven by arbitrary command sequences
through :class:`aerodaas.navigation.safety.SafetyGate`, exactly as the drone component does (every control tick: the head
command is checked with the vehicle's position and velocity; a refused one makes the vehicle hold), measuring from
the vehicle's odometry how far it ever got outside its inclusion fence, into an exclusion zone, or above
``max_altitude``. Used by ``tests/test_safety_model.py`` (hypothesis) and ``python -m aerodaas.reliability``."""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any, Sequence

__all__ = ["PROBE_ENV", "Excursion", "fly_commands", "random_commands"]

#: the probe's robot: 3 m/s, 2 m/s² (the issue's velocity attack), a 60 m square inclusion fence around home with an
#: exclusion circle of 6 m radius inside it, and max_altitude 10 m
PROBE_HOME = (47.3977, 8.5456, 488.0)


def _probe_robot(on_violation: str = "reject") -> Any:
    import pymap3d

    from aerodaas.config import RobotConfig

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
    from shapely.geometry import Point

    from aerodaas.model.types import VelocityCommand, Waypoint
    from aerodaas.navigation.safety import SafetyGate, SafetyViolation
    from aerodaas.sim.vehicle import SimVehicle

    cfg = _probe_robot(on_violation)
    gate = SafetyGate(cfg.safety, cfg.limits, cfg.home, control_period_s=1.0 / cfg.control_rate_hz)
    veh = SimVehicle("probe", cfg.home, cfg.limits, cfg.battery)
    dt = 1.0 / physics_hz
    steps_per_tick = max(1, round(physics_hz / cfg.control_rate_hz))
    inc, exc = list(gate.fence.inclusions), list(gate.fence.exclusions)
    ex = Excursion()

    def measure() -> None:
        o = veh.odometry()
        x, y, z = o.position
        ex.samples += 1
        if inc:
            out = min(_outside(zn, x, y, Point) for zn in inc)
            if out > ex.outside_inclusion_m:
                ex.outside_inclusion_m, ex.worst["inclusion"] = out, (x, y, z)
        for zn in exc:
            depth = _inside(zn, x, y, Point)
            if depth > ex.inside_exclusion_m:
                ex.inside_exclusion_m, ex.worst["exclusion"] = depth, (x, y, z)
        if z - gate.max_alt > ex.above_max_altitude_m:
            ex.above_max_altitude_m, ex.worst["altitude"] = z - gate.max_alt, (x, y, z)

    def run_ticks(n: int, on_tick) -> None:
        for _ in range(n):
            on_tick()
            for _ in range(steps_per_tick):
                veh.step(dt)
                measure()

    veh.arm()
    veh.takeoff(gate.check_takeoff(cfg.takeoff_altitude))
    run_ticks(60, lambda: None)
    for c in commands:
        kind = c[0]
        if kind == "hold":
            veh.hold()
            run_ticks(int(c[1]), lambda: None)
            continue
        if kind == "wp":
            wp = Waypoint(id="w", x=c[1], y=c[2], z=c[3])
            try:
                wp = gate.check_waypoint(wp, tuple(veh.state.position), tuple(veh.state.velocity))
                veh.goto(wp.to_local(cfg.home), wp.speed)
                ex.accepted += 1
            except SafetyViolation:
                ex.rejected += 1
                veh.hold()
            run_ticks(int(c[4]), lambda: None)
            continue
        cmd = VelocityCommand(vx=c[1], vy=c[2], vz=c[3], duration=c[4])
        left = [c[4]]
        live = [True]

        def tick(cmd=cmd, left=left, live=live) -> None:
            if not live[0]:
                return
            if left[0] <= 1e-9:  # expired: nothing queued, the drone holds
                live[0] = False
                veh.hold()
                return
            try:
                ok = gate.check_velocity(cmd, tuple(veh.state.position), tuple(veh.state.velocity))
                veh.set_velocity((ok.vx, ok.vy, ok.vz))
                ex.accepted += 1
            except SafetyViolation:
                ex.rejected += 1
                live[0] = False
                veh.hold()
            left[0] -= 1.0 / cfg.control_rate_hz

        run_ticks(int(c[5]), tick)
    return ex


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
