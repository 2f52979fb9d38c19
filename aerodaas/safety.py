"""Safety limits: the one choke point every navigation command passes before it reaches a drone backend.

:class:`SafetyGate` checks waypoints and velocity commands against a robot's :class:`~aerodaas.config.SafetyConfig`:

* geofence (inclusion/exclusion polygons and circles, from the config or a QGroundControl ``.plan``): the
  target must be allowed *and* the straight leg from the drone's position to it must not cross a forbidden
  zone (the same semantics as PX4/ArduPilot fences: inside at least one inclusion zone if any exist, inside no
  exclusion zone);
* maximum altitude, and minimum altitude (metres above home) for everything except landing;
* maximum horizontal speed (m/s) and maximum vertical speed.

A violation raises :class:`SafetyViolation` (a ``ValueError`` naming the field, the value and the limit), or,
where ``on_violation == "clamp"``, the command is clamped into the limits (altitude and speed only: a geofence
breach cannot be clamped meaningfully and is always rejected). The drone actor calls the gate immediately
before commanding its backend; the scheduler actor and the human-in-the-loop API call the same gate when
navigation is added, so a bad waypoint is refused early (HTTP 422) and never queued.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

from .models import ActionCommand, AeroNavigation, GeoPoint, VelocityCommand, Waypoint

__all__ = ["SafetyViolation", "SafetyGate"]


class SafetyViolation(ValueError):
    """A navigation command outside the safety limits. ``field``/``value``/``limit`` say which and why."""

    def __init__(self, item_id: str, field: str, value: Any, reason: str) -> None:
        self.item_id, self.field, self.value, self.reason = item_id, field, value, reason
        super().__init__(f"{item_id}: {field}={value!r} rejected by the safety limits: {reason}")

    def __reduce__(self):  # picklable across Ray workers
        return (SafetyViolation, (self.item_id, self.field, self.value, self.reason))


class SafetyGate:
    """Checks (and optionally clamps) navigation items against a robot's safety limits.

    ``safety`` is a :class:`aerodaas.config.SafetyConfig`, ``limits`` the robot's
    :class:`aerodaas.config.Limits` (their ``max_speed``/``max_altitude`` are the defaults of the safety
    limits), ``home`` the robot's home GeoPoint (absolute waypoints and the geofence are converted to local ENU
    metres relative to it). Stateless apart from counters, so it can be copied into several actors.
    """

    def __init__(self, safety: Any, limits: Any, home: GeoPoint) -> None:
        from .geofence import Geofence

        self.cfg = safety
        self.home = home
        self.max_alt = float(safety.max_altitude if safety.max_altitude is not None else limits.max_altitude)
        self.min_alt = float(safety.min_altitude)
        self.max_speed = float(safety.max_speed if safety.max_speed is not None else limits.max_speed)
        self.max_vspeed = float(limits.max_vertical_speed)
        self.clamp = safety.on_violation == "clamp"
        self.fence = Geofence(safety.geofence, home)
        self.rejected = 0
        self.clamped = 0

    # ------------------------------------------------------------------ items
    def check_waypoint(self, wp: Waypoint, from_position: Sequence[float] | None = None) -> Waypoint:
        """Return ``wp`` (or a clamped copy) if it is within limits; raise :class:`SafetyViolation` otherwise.

        With ``from_position`` (local ENU metres), the leg from there to the waypoint is also checked against
        the geofence."""
        x, y, z = wp.to_local(self.home)
        upd: dict[str, Any] = {}
        if z > self.max_alt or z < self.min_alt:
            if not self.clamp:
                self.rejected += 1
                bound = "max_altitude" if z > self.max_alt else "min_altitude"
                raise SafetyViolation(wp.id, "z", z, f"altitude {z:.2f} m above home is outside "
                                      f"[{self.min_alt:g}, {self.max_alt:g}] m ({bound})")
            upd["z"] = min(max(z, self.min_alt), self.max_alt)
        if wp.speed is not None and wp.speed > self.max_speed:
            if not self.clamp:
                self.rejected += 1
                raise SafetyViolation(wp.id, "speed", wp.speed, f"above max_speed {self.max_speed:g} m/s")
            upd["speed"] = self.max_speed
        why = self.fence.check_point(x, y)
        if why is None and from_position is not None:
            why = self.fence.check_segment((float(from_position[0]), float(from_position[1])), (x, y))
        if why is not None:
            self.rejected += 1
            raise SafetyViolation(wp.id, "position", [round(x, 2), round(y, 2)], f"geofence: {why}")
        if upd:
            self.clamped += 1
            return wp.model_copy(update=upd)
        return wp

    def check_velocity(self, cmd: VelocityCommand, position: Sequence[float] | None = None) -> VelocityCommand:
        """Return ``cmd`` (or a clamped copy) if flying it for its ``duration`` stays within the limits.

        Horizontal speed above ``max_speed`` or vertical speed above the robot's ``max_vertical_speed`` is
        rejected (or scaled down when clamping). With ``position`` the predicted end point
        ``position + v * duration`` must respect the altitude limits and the geofence (an altitude breach is
        clamped by zeroing ``vz`` when clamping)."""
        upd: dict[str, Any] = {}
        h = math.hypot(cmd.vx, cmd.vy)
        if h > self.max_speed + 1e-9:
            if not self.clamp:
                self.rejected += 1
                raise SafetyViolation(cmd.id, "speed", round(h, 3), f"above max_speed {self.max_speed:g} m/s")
            s = self.max_speed / h
            upd["vx"], upd["vy"] = cmd.vx * s, cmd.vy * s
        if abs(cmd.vz) > self.max_vspeed + 1e-9:
            if not self.clamp:
                self.rejected += 1
                raise SafetyViolation(cmd.id, "vz", cmd.vz, f"above max_vertical_speed {self.max_vspeed:g} m/s")
            upd["vz"] = math.copysign(self.max_vspeed, cmd.vz)
        if position is not None:
            vx, vy, vz = upd.get("vx", cmd.vx), upd.get("vy", cmd.vy), upd.get("vz", cmd.vz)
            px, py, pz = (float(c) for c in position)
            ex, ey, ez = px + vx * cmd.duration, py + vy * cmd.duration, pz + vz * cmd.duration
            if (ez > self.max_alt and vz > 0) or (ez < self.min_alt and vz < 0):
                if not self.clamp:
                    self.rejected += 1
                    raise SafetyViolation(cmd.id, "vz", vz, f"would reach {ez:.2f} m above home, outside "
                                          f"[{self.min_alt:g}, {self.max_alt:g}] m within {cmd.duration:g} s")
                upd["vz"] = 0.0
            why = self.fence.check_point(ex, ey) or self.fence.check_segment((px, py), (ex, ey))
            if why is not None:
                self.rejected += 1
                raise SafetyViolation(cmd.id, "velocity", [round(vx, 2), round(vy, 2)],
                                      f"geofence within {cmd.duration:g} s: {why}")
        if upd:
            self.clamped += 1
            return cmd.model_copy(update=upd)
        return cmd

    def check_item(self, item: Any, position: Sequence[float] | None = None) -> Any:
        """Dispatch on the item type; actions (land, RTL) are always allowed."""
        if isinstance(item, Waypoint):
            return self.check_waypoint(item, position)
        if isinstance(item, VelocityCommand):
            return self.check_velocity(item, position)
        if isinstance(item, ActionCommand):
            return item
        raise TypeError(f"unknown navigation item {type(item).__name__}")

    def check_navigation(self, nav: AeroNavigation, position: Sequence[float] | None = None) -> AeroNavigation:
        """Check every item of ``nav`` (legs chained from ``position`` for ORDERED navigation); all or nothing:
        the first violation raises and nothing is returned half-checked."""
        ordered = nav.scheduling_type.value == "ORDERED"
        out, pos = [], position
        for item in nav.waypoints:
            checked = self.check_item(item, pos if (ordered or isinstance(item, VelocityCommand)) else None)
            out.append(checked)
            if isinstance(checked, Waypoint):
                pos = checked.to_local(self.home)
        if all(a is b for a, b in zip(out, nav.waypoints)):
            return nav
        return nav.model_copy(update={"waypoints": out})

    def stats(self) -> dict:
        return {"rejected": self.rejected, "clamped": self.clamped}
