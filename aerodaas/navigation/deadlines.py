"""How long a flight phase may take before it counts as stalled (a ground-rover backend sat in
TAKING_OFF for 4,000 vehicle seconds, until the battery failsafe ended it).

A phase's deadline is derived from the vehicle's limits: the phase is cut into legs, each a distance (metres) flown
at a speed (m/s) — a climb at ``limits.max_vertical_speed``, a horizontal leg at the robot's horizontal speed limit,
a descent at the landing speed — and the deadline is ``speed_factor`` x the sum of ``distance / speed`` plus
``margin_s`` (vehicle seconds). The factor covers a vehicle that flies below its limit (acceleration ramps, PX4's
own take-off speed ``MPC_TKO_SPEED``), the margin what takes time without moving (spool-up after arming, a land
detector confirming touchdown: ArduCopter ``land_detector.cpp`` needs 1 s, PX4 ``MultirotorLandDetector`` a few).
Pure functions, no I/O: the drone (:mod:`aerodaas.actors.drone.deadline`) measures the legs when a phase starts
and reads the vehicle's clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Sequence


@dataclass(frozen=True)
class Leg:
    """One part of a phase: ``distance_m`` metres at ``speed_mps`` m/s; ``kind`` says which (``climb``,
    ``horizontal``, ``descent``), for the recorded event."""

    kind: str
    distance_m: float
    speed_mps: float

    @property
    def seconds(self) -> float:
        """``distance_m / speed_mps`` (0 for a leg of no length)."""
        return abs(self.distance_m) / self.speed_mps if self.distance_m else 0.0


def deadline_s(legs: Iterable[Leg], speed_factor: float, margin_s: float) -> float:
    """``speed_factor`` x the legs' nominal time + ``margin_s``, vehicle seconds. Raises ValueError for a factor
    below 1, a negative margin or a leg whose speed is not a positive finite number."""
    if not speed_factor >= 1.0 or not margin_s >= 0.0:
        raise ValueError(f"speed_factor must be >= 1 and margin_s >= 0, got {speed_factor!r} and {margin_s!r}")
    total = 0.0
    for leg in legs:
        if not (leg.speed_mps > 0 and math.isfinite(leg.speed_mps)):
            raise ValueError(f"{leg.kind} leg: speed {leg.speed_mps!r} m/s must be a positive finite number")
        total += leg.seconds
    return speed_factor * total + margin_s


def takeoff_legs(height_m: float, takeoff_altitude_m: float, max_vertical_speed: float) -> tuple[Leg, ...]:
    """The climb from ``height_m`` to ``takeoff_altitude_m`` (metres above home) at ``max_vertical_speed``."""
    return (Leg("climb", abs(takeoff_altitude_m - height_m), max_vertical_speed),)


def landing_speed(max_vertical_speed: float, landing_speed_mps: float) -> float:
    """The descent rate a landing is judged by: the autopilot's landing speed (ArduCopter ``LAND_SPEED`` 50 cm/s,
    PX4 ``MPC_LAND_SPEED`` 0.7 m/s, the simulator 0.5 m/s), never above the robot's vertical limit."""
    return min(max_vertical_speed, landing_speed_mps)


def landing_legs(height_m: float, max_vertical_speed: float, landing_speed_mps: float) -> tuple[Leg, ...]:
    """The descent from ``height_m`` (metres above home; nothing below 0) to the ground."""
    return (Leg("descent", max(height_m, 0.0), landing_speed(max_vertical_speed, landing_speed_mps)),)


def path_length_m(pos: Sequence[float], path: Iterable[Sequence[float]]) -> float:
    """Horizontal metres from ``pos`` through every point of ``path`` (ENU metres) in order."""
    total, (x, y) = 0.0, (float(pos[0]), float(pos[1]))
    for p in path:
        total += math.hypot(float(p[0]) - x, float(p[1]) - y)
        x, y = float(p[0]), float(p[1])
    return total


def return_legs(pos: Sequence[float], path: Sequence[Sequence[float]], max_speed: float, max_vertical_speed: float,
                landing_speed_mps: float, autopilot_return_alt_m: float | None) -> tuple[Leg, ...]:
    """A return to launch from ``pos`` along ``path`` (ENU metres; empty: straight home) at ``max_speed``. When
    the autopilot flies it (``autopilot_return_alt_m`` not None) its return also climbs to that altitude first
    when lower (ArduCopter ``RTL_ALT``, default 15 m; PX4 ``RTL_RETURN_ALT``, 30-60 m) and lands at home, so
    the climb and the descent from there are legs too; AeroDaaS's own return lands in a phase of its own."""
    legs = [Leg("horizontal", path_length_m(pos, path or [(0.0, 0.0)]), max_speed)]
    if autopilot_return_alt_m is not None:
        top = max(float(pos[2]), autopilot_return_alt_m)
        legs.insert(0, Leg("climb", top - max(float(pos[2]), 0.0), max_vertical_speed))
        legs.append(Leg("descent", top, landing_speed(max_vertical_speed, landing_speed_mps)))
    return tuple(legs)
