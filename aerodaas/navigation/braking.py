"""The braking-aware position profile shared by the embedded simulator (:mod:`aerodaas.sim.vehicle`) and the safety
gate's prediction of it (:mod:`aerodaas.navigation.safety`), so that the vertical limit holds at every physics
step.

A vehicle stepping at ``dt`` seconds (velocity changed by at most ``a dt``, then position += velocity * dt) that
flies towards a point at the continuous-time ``sqrt(2 a d)`` overshoots it: at 10 Hz a waypoint 5 cm under
``max_altitude`` was passed by 0.14 m, and by up to a metre with fast climbs. Two rules make the approach exact in
discrete time:

* :func:`braking_speed`: at most the speed from which stepping braking still stops within the distance;
* :func:`limited_change` with ``vertical_first``: on a position target the vertical change gets the acceleration
  budget first (a turn sharing one budget in proportion starved a climb's braking: 0.8 m above the waypoint).
  Stopping (hold) and velocity commands keep one budget along the velocity change, which is what the gate's
  stopping-distance model ``v^2 / (2 a)`` assumes.
"""
from __future__ import annotations

import math
from typing import Sequence

__all__ = ["braking_speed", "limited_change"]


def braking_speed(distance: float, accel: float, dt: float) -> float:
    """The fastest speed (m/s) from which a vehicle stepping at ``dt`` seconds still stops within ``distance``
    metres braking at ``accel`` m/s^2: the root of ``v dt + v^2 / (2 accel) = distance``. Flying at most this it
    never passes the point: one step moves at most ``v dt <= distance``, and on the next step the bound is lower by
    at most ``accel dt`` (``(v - a dt) dt + (v - a dt)^2 / 2a = v^2 / 2a - a dt^2 / 2 <= distance - v dt``), so the
    braking can follow it. Below ``sqrt(2 accel distance)`` and ``distance / dt``."""
    if distance <= 0.0:
        return 0.0
    return accel * (math.sqrt(dt * dt + 2.0 * distance / accel) - dt)


def limited_change(dv: Sequence[float], amax: float, vertical_first: bool = False) -> list[float]:
    """The velocity change (m/s, ENU) one step makes towards ``dv`` with at most ``amax`` (``max_acceleration *
    dt``) in all: scaled along ``dv``; with ``vertical_first`` the vertical part is clipped to ``amax`` first and
    the horizontal part scaled into what remains."""
    out = [float(c) for c in dv]
    if vertical_first:
        out[2] = max(-amax, min(amax, out[2]))
        rest = math.sqrt(max(0.0, amax * amax - out[2] * out[2]))
        h = math.hypot(out[0], out[1])
        if h > rest:
            out[0], out[1] = out[0] * rest / h, out[1] * rest / h
        return out
    n = math.sqrt(sum(c * c for c in out))
    if n > amax:
        out = [c * amax / n for c in out]
    return out
