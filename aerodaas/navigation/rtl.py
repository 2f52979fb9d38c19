"""Return to launch (and every failsafe that returns) through the safety gate: a path around the exclusion zones
(:func:`aerodaas.navigation.route.plan_path`), each leg then checked by :class:`aerodaas.navigation.safety.SafetyGate` exactly as
a waypoint from an app would be (the first leg from the vehicle's current velocity, with the stopping envelope), or
no path at all: the caller lands in place."""
from __future__ import annotations

import math
from typing import Any, Sequence

from aerodaas.model.types import Waypoint
from aerodaas.navigation.route import plan_path
from aerodaas.navigation.safety import SafetyViolation

__all__ = ["RTL_MARGIN_M", "plan_return"]

#: extra clearance (metres) around every exclusion zone, beyond the stopping distance at the return speed
RTL_MARGIN_M = 1.0


def plan_return(gate: Any, position: Sequence[float], velocity: Sequence[float], altitude: float,
                home: Sequence[float] = (0.0, 0.0)) -> tuple[list[tuple[float, float]] | None, str]:
    """Plan the way home for a vehicle at ``position`` (ENU m) moving at ``velocity`` (ENU m/s), flown at ``altitude``
    (m above home) and the gate's ``max_speed``. Returns ``(path, "")`` with ``path`` the ENU ``(x, y)`` points from
    the position to ``home``, or ``(None, reason)`` when no path exists or a leg of it is refused by the gate."""
    clearance = gate.stopping_distance(gate.max_speed) + RTL_MARGIN_M
    start = (float(position[0]), float(position[1]))
    path = plan_path(gate.fence, start, home, clearance) if not gate.fence.is_empty else [start, tuple(home)]
    if path is None:
        where = f"({start[0]:.1f}, {start[1]:.1f}) m, {math.hypot(*start):.0f} m from home"
        if gate.fence.exclusions:
            return None, (f"no path home from {where} keeps {clearance:.1f} m clear of the exclusion zones and inside "
                          f"the inclusion zones")
        # inclusion zones only (a fence without exclusion zones was reported as one before): the straight leg
        # leaves them, and the planner routes around exclusion zones only
        why = gate.fence.check_point(*start) or gate.fence.check_segment(start, tuple(home))
        return None, f"no path home from {where} stays inside the inclusion zones" + (f" ({why})" if why else "")
    prev, vel = (start[0], start[1], float(position[2])), tuple(float(c) for c in velocity)
    for i, (x, y) in enumerate(path[1:]):
        wp = Waypoint(id=f"rtl-{i}", x=x, y=y, z=altitude, speed=gate.max_speed)
        try:
            gate.check_waypoint(wp, prev, vel)
        except SafetyViolation as e:
            gate.rejected -= 1  # a planning probe, not a refused command
            return None, f"leg {i} of the path home refused: {e.reason}"
        prev, vel = (x, y, altitude), (0.0, 0.0, 0.0)
    return path, ""
