"""Safety limits: the one choke point every navigation command passes before it reaches a drone backend.

:class:`SafetyGate` checks waypoints and velocity commands against a robot's :class:`~aerodaas.config.SafetyConfig`:

* geofence (inclusion/exclusion polygons and circles, from the config or a QGroundControl ``.plan``): the
  target must be allowed *and* the straight leg from the drone's position to it must not cross a forbidden
  zone (inside at least one inclusion zone if any exist, inside no exclusion zone: the rule the MAVLink backend
  makes the autopilot's own fence follow, or refuses before flight; :mod:`aerodaas.navigation.geofence`);
* maximum altitude, and minimum altitude (metres above home) for everything except landing;
* maximum horizontal speed (m/s) and maximum vertical speed.

**The vehicle's dynamics.** A command is judged by where the vehicle can end up, not by where it is told to go:
the vehicle is modelled as a point mass whose velocity changes by at most ``limits.max_acceleration`` (m/s²,
vector norm) — the model of :mod:`aerodaas.sim.vehicle`, and a conservative one for an autopilot whose
``max_acceleration`` is configured at or below its own (ArduPilot ``WPNAV_ACCEL``/``PSC_ACCZ_MAX``, PX4
``MPC_ACC_HOR``/``MPC_ACC_UP_MAX``). For a velocity command the predicted path is: the current velocity held for
``safety.command_latency_s`` (the link and autopilot delay before the command acts), then the velocity moving
towards the command at the acceleration limit for the command's ``duration`` plus one control period (the gate
checks again at every control tick; a refused command makes the vehicle hold), and **from every point of that path
the stopping distance** ``v² / (2 a)`` along the velocity at that point (the vehicle may be told to hold at any
tick). For a waypoint flown from a moving vehicle the same model flies the turn towards the target (speed
``min(v_max, sqrt(2 a d))``, as the simulator and the autopilots' trapezoidal profiles) with the stopping fan. The
whole envelope must stay inside the geofence and under ``max_altitude``: by induction over ticks the vehicle,
whatever it is told, never leaves it.

A violation raises :class:`SafetyViolation` (a ``ValueError`` naming the field, the value and the limit), or,
where ``on_violation == "clamp"``, the command is clamped into the limits (altitude and speed only: a geofence
breach cannot be clamped meaningfully and is always rejected). The drone actor calls the gate immediately
before commanding its backend; the scheduler actor and the human-in-the-loop API call the same gate when
navigation is added, so a bad waypoint is refused early (HTTP 422) and never queued.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

from pydantic import ValidationError

from aerodaas.model.types import ActionCommand, AeroNavigation, GeoPoint, VelocityCommand, Waypoint
from aerodaas.navigation.braking import braking_speed, limited_change

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

    #: time step (s) of the envelope prediction; the path between samples is checked as straight legs
    PREDICT_DT_S = 0.1

    def __init__(self, safety: Any, limits: Any, home: GeoPoint, control_period_s: float = 0.1) -> None:
        from aerodaas.navigation.geofence import Geofence  # lazy: heavy pymap3d, shapely

        self.cfg = safety
        self.home = home
        # one limit set: the effective limit is the minimum of every configured one (limits.*, safety.*); the
        # waypoint's own speed can only lower it further (check_waypoint)
        self.max_alt = min(float(limits.max_altitude), float(safety.max_altitude if safety.max_altitude is not None
                                                              else math.inf))
        self.min_alt = float(safety.min_altitude)
        self.max_speed = min(float(limits.max_speed), float(safety.max_speed if safety.max_speed is not None
                                                            else math.inf))
        #: a backend flies a waypoint without its own speed at the robot's limits.max_speed
        self._backend_default_speed = float(limits.max_speed)
        self.max_vspeed = float(limits.max_vertical_speed)
        self.clamp = safety.on_violation == "clamp"
        self.accel = float(limits.max_acceleration)
        self.latency = float(getattr(safety, "command_latency_s", 0.2))
        self.period = float(control_period_s)
        self.fence = Geofence(safety.geofence, home)
        #: horizontal distance from home (m) no waypoint or velocity command may reach (safety.max_distance)
        self.max_dist = float(safety.max_distance)
        self.rejected = 0
        self.clamped = 0

    # ------------------------------------------------------------------ items
    def check_waypoint(self, wp: Waypoint, from_position: Sequence[float] | None = None,
                       velocity: Sequence[float] | None = None) -> Waypoint:
        """Return ``wp`` (or a clamped copy) if it is within limits; raise :class:`SafetyViolation` otherwise.

        With ``from_position`` (local ENU metres), the leg from there to the waypoint is also checked against
        the geofence; with ``velocity`` too (ENU m/s, the vehicle's now), the predicted turn towards the waypoint
        and the stopping distance from every point of it (see the module docstring). A waypoint without its own
        ``speed`` gets the effective ``max_speed`` (the minimum of ``limits.max_speed`` and ``safety.max_speed``) when
        that is below ``limits.max_speed``, the speed a backend flies it at otherwise."""
        self._check_values(wp)
        x, y, z = wp.to_local(self.home)
        upd: dict[str, Any] = {}
        if wp.speed is None and self.max_speed < self._backend_default_speed:
            # only where the backend's default would be too fast: a speed on every waypoint would add a
            # DO_CHANGE_SPEED item to every uploaded autopilot mission for nothing
            wp = wp.model_copy(update={"speed": self.max_speed})
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
        dist = math.hypot(x, y)
        if dist > self.max_dist:  # never clamped: a waypoint this far is a typo, not a nudge
            self.rejected += 1
            raise SafetyViolation(wp.id, "position", [round(x, 2), round(y, 2)],
                                  f"{dist:.0f} m from home, beyond max_distance {self.max_dist:g} m")
        why = self.fence.check_point(x, y)
        if why is None and from_position is not None:
            why = self.fence.check_segment((float(from_position[0]), float(from_position[1])), (x, y))
        if why is not None:
            self.rejected += 1
            raise SafetyViolation(wp.id, "position", [round(x, 2), round(y, 2)], f"geofence: {why}")
        if from_position is not None:
            speed = min(self.max_speed, upd.get("speed", wp.speed) or self.max_speed)
            vel0 = tuple(float(c) for c in velocity) if velocity is not None else (0.0, 0.0, 0.0)
            tz = upd.get("z", z)
            for _ in range(4):  # the approach of the vehicle model may overshoot the target altitude
                turn, path, samples = self._predict_goto(from_position, vel0, (x, y, tz), speed)
                # the path, and the stop (a hold) from any point of it: a climb with horizontal speed stops higher
                # than its target (0.52-0.57 m above max_altitude when a hold came mid-climb)
                over = max(max(p[2] for p in path), self._z_range(turn)[0], self._z_range(samples)[0]) - self.max_alt
                if over <= 1e-9 or not self.clamp:
                    break
                tz -= over + 0.01
                upd["z"] = tz
            if over > 1e-9:
                self.rejected += 1
                raise SafetyViolation(wp.id, "z", z, f"the approach (from {math.hypot(*vel0[:2]):.1f} m/s, "
                                      f"{self.accel:g} m/s^2) would reach {self.max_alt + over:.2f} m above home, "
                                      f"above max_altitude {self.max_alt:g} m")
            why = self._fence_violation(turn)
            if why is None and not self.fence.is_empty:
                from shapely.geometry import LineString  # lazy: heavy shapely

                xy = [(p[0], p[1]) for p in path]
                if len(xy) > 2:
                    xy = list(LineString(xy).simplify(0.002).coords)
                why = self.fence.check_path(xy)
                if why is not None:
                    why = why.split("): ", 1)[-1]  # the leg index of the prediction means nothing to a user
            if why is not None:
                self.rejected += 1
                raise SafetyViolation(wp.id, "position", [round(x, 2), round(y, 2)],
                                      f"geofence: the predicted flight there (from the current velocity) {why}")
        if upd:
            self.clamped += 1
            return wp.model_copy(update=upd)
        return wp

    def check_velocity(self, cmd: VelocityCommand, position: Sequence[float] | None = None,
                       velocity: Sequence[float] | None = None) -> VelocityCommand:
        """Return ``cmd`` (or a clamped copy) if flying it keeps the vehicle within the limits.

        Horizontal speed above ``max_speed`` or vertical speed above the robot's ``max_vertical_speed`` is
        rejected (or scaled down when clamping). With ``position`` (ENU m) and ``velocity`` (ENU m/s, default at
        rest) the predicted envelope (module docstring: latency, the command for ``duration`` + one control
        period, the stopping distance from every point) must stay under ``max_altitude``, above ``min_altitude``
        when descending, and inside the geofence. An altitude breach is clamped by zeroing ``vz`` when clamping
        (if the envelope is then still outside, the command is rejected); a geofence breach is always rejected."""
        self._check_values(cmd)
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
            vel0 = tuple(float(c) for c in velocity) if velocity is not None else (0.0, 0.0, 0.0)
            v = (upd.get("vx", cmd.vx), upd.get("vy", cmd.vy), upd.get("vz", cmd.vz))
            horizon = cmd.duration + self.period
            path = self._predict_velocity(position, vel0, v, horizon)
            zmax, zmin = self._z_range(path)
            alt_bad = (zmax > self.max_alt + 1e-9 and v[2] > 0) or (zmin < self.min_alt - 1e-9 and v[2] < 0)
            if alt_bad and self.clamp:
                upd["vz"] = 0.0
                v = (v[0], v[1], 0.0)
                path = self._predict_velocity(position, vel0, v, horizon)
                zmax, zmin = self._z_range(path)
                alt_bad = zmax > self.max_alt + 1e-9 and vel0[2] > 0
            if alt_bad:
                self.rejected += 1
                ez = zmax if v[2] > 0 or zmax > self.max_alt else zmin
                raise SafetyViolation(cmd.id, "vz", v[2], f"could reach {ez:.2f} m above home (with the stopping "
                                      f"distance at {self.accel:g} m/s^2), outside [{self.min_alt:g}, "
                                      f"{self.max_alt:g}] m within {horizon:g} s")
            # where each predicted point would come to rest (braking at max_acceleration along its velocity); a vehicle
            # already beyond the limit may still be commanded back: only going farther than the points it reaches
            # whatever it is told (the command latency, at its present velocity) is refused
            two_a, hypot = 2.0 * self.accel, math.hypot
            reach = [hypot(q[0] + w[0] * k, q[1] + w[1] * k)
                     for q, w in path for k in (hypot(w[0], w[1]) / two_a,)]
            far = max(reach)
            n_latency = int(math.ceil(self.latency / self.PREDICT_DT_S - 1e-9)) + 1
            unavoidable = max(reach[:n_latency])
            if far > max(self.max_dist, unavoidable) + 1e-6:
                self.rejected += 1
                raise SafetyViolation(cmd.id, "velocity", [round(c, 3) for c in v],
                                      f"could reach {far:.0f} m from home within {horizon:g} s, beyond max_distance "
                                      f"{self.max_dist:g} m")
            why = self._fence_violation(path)
            if why is not None:
                self.rejected += 1
                raise SafetyViolation(cmd.id, "velocity", [round(v[0], 2), round(v[1], 2)],
                                      f"geofence within {horizon:g} s (+ stopping distance at {self.accel:g} m/s^2): "
                                      f"{why}")
        if upd:
            self.clamped += 1
            return cmd.model_copy(update=upd)
        return cmd

    def check_vehicle_home(self, vehicle_home: GeoPoint, position: Sequence[float]) -> None:
        """The gate judges in the robot's frame (ENU metres about ``robots[].home``: the geofence, ``max_distance``,
        relative waypoints); a vehicle with a home of its own (an autopilot sets it where it arms) reports and flies
        positions about that one. Raise :class:`SafetyViolation` (field ``home``) when the vehicle's home, or where
        it stands (``position``, ENU metres about ``vehicle_home``), is more than ``safety.home_tolerance_m``
        metres from the robot's home: the gate and the vehicle would place every point that far apart. Distances
        are horizontal (pymap3d ENU)."""
        from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu  # lazy: heavy pymap3d

        here = enu_to_geodetic(float(position[0]), float(position[1]), 0.0, vehicle_home)
        tol = float(getattr(self.cfg, "home_tolerance_m", 5.0))
        for what, g in (("its home", vehicle_home), ("its position", here)):
            e, n, _ = geodetic_to_enu(g.lat, g.lon, self.home.alt, self.home)
            off = math.hypot(float(e), float(n))
            if off > tol:
                self.rejected += 1
                raise SafetyViolation("home", "home", [round(g.lat, 7), round(g.lon, 7)],
                                      f"the vehicle reports {what} {off:.1f} m from the robot's home "
                                      f"({self.home.lat}, {self.home.lon}), beyond safety.home_tolerance_m "
                                      f"{tol:g} m: the geofence, max_distance and relative waypoints are placed "
                                      f"from robots[].home; set it to where the vehicle is")

    def check_takeoff(self, altitude: float) -> float:
        """The take-off target altitude (m above home) through the same limits: above the effective ``max_altitude``
        (the minimum of ``limits.max_altitude`` and ``safety.max_altitude``) it is
        rejected (or clamped to it when clamping); it must be > 0. Returns the altitude to fly."""
        if not (math.isfinite(altitude) and altitude > 0):
            self.rejected += 1
            raise SafetyViolation("takeoff", "altitude", altitude, "must be a positive number of metres")
        if altitude > self.max_alt:
            if not self.clamp:
                self.rejected += 1
                raise SafetyViolation("takeoff", "altitude", altitude, f"above max_altitude {self.max_alt:g} m")
            self.clamped += 1
            return self.max_alt
        return float(altitude)

    def _check_values(self, item: Any) -> None:
        """The gate checks the item's values itself, whatever built it: every field validated again against its
        model (finite numbers, no strings or booleans for numbers, the models' bounds). An item made with
        ``model_construct`` or changed by ``model_copy(update=...)`` skips pydantic's validation: a NaN waypoint
        built so passed the pre-flight check and the gate (every comparison with NaN is False) before. Raises
        :class:`SafetyViolation` naming the field and its value."""
        try:
            type(item).model_validate(dict(item.__dict__))
        except ValidationError as e:
            err = e.errors()[0]
            field = ".".join(str(x) for x in err["loc"]) or "item"
            self.rejected += 1
            raise SafetyViolation(str(getattr(item, "id", "?")), field, err.get("input"),
                                  f"not a valid {type(item).__name__} ({err['msg']})") from None

    # ------------------------------------------------------------------ the dynamics model
    def stopping_distance(self, speed: float) -> float:
        """Metres a point mass at ``speed`` m/s needs to stop at ``max_acceleration``: ``v² / (2 a)``."""
        return speed * speed / (2.0 * self.accel)

    def _accelerate(self, v: list[float], desired: Sequence[float], dt: float, vertical_first: bool = False) -> None:
        """``v`` moved towards ``desired`` as the simulator's step does (:func:`~aerodaas.navigation.braking.
        limited_change`; ``vertical_first`` for a position target)."""
        dv = limited_change([d - c for d, c in zip(desired, v)], self.accel * dt, vertical_first)
        for i in range(3):
            v[i] += dv[i]

    def _predict_velocity(self, position: Sequence[float], vel0: Sequence[float], v_cmd: Sequence[float],
                          horizon: float) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
        """(position, velocity) samples: ``vel0`` held for the latency, then accelerating towards ``v_cmd`` for
        ``horizon`` seconds."""
        # _accelerate and limited_change (one budget along the change) written out, operation for operation: the
        # gate runs this for every velocity command taken and again on every control step that flies one
        px, py, pz = (float(c) for c in position)
        vx, vy, vz = (float(c) for c in vel0)
        cx, cy, cz = v_cmd
        sqrt, accel, latency = math.sqrt, self.accel, self.latency
        out = [((px, py, pz), (vx, vy, vz))]
        t, dt = 0.0, self.PREDICT_DT_S
        total = latency + horizon
        while t < total - 1e-9:
            step = min(dt, total - t)
            if t >= latency - 1e-9:
                dx, dy, dz = float(cx - vx), float(cy - vy), float(cz - vz)
                amax = accel * step
                n = sqrt(dx * dx + dy * dy + dz * dz)
                if n > amax:
                    dx, dy, dz = dx * amax / n, dy * amax / n, dz * amax / n
                vx, vy, vz = vx + dx, vy + dy, vz + dz
            px, py, pz = px + vx * step, py + vy * step, pz + vz * step
            t += step
            out.append(((px, py, pz), (vx, vy, vz)))
        return out

    def _predict_goto(self, position: Sequence[float], vel0: Sequence[float], target: Sequence[float],
                      speed: float, dt: float = 0.02) -> tuple[list, list]:
        """A position target flown from ``position`` at ``vel0``: the latency at ``vel0``, then the trapezoidal law
        of :mod:`aerodaas.sim.vehicle` (horizontal speed ``min(v_max, sqrt(2 a d), d / dt)``, vertical the
        braking speed of :mod:`aerodaas.navigation.braking`, the velocity changing by at most ``a dt``, the vertical
        change first) until it has settled on the target (at most 120 s), integrated
        at ``dt`` (the simulator's physics step). Returns (the turn: (position, velocity) samples every
        :attr:`PREDICT_DT_S` until the velocity points at the target, for the stopping fan; the whole path's
        positions; (position, velocity) samples of the whole path every :attr:`PREDICT_DT_S`, for the stop from any
        point of it under ``max_altitude``)."""
        p, v = [float(c) for c in position], [float(c) for c in vel0]
        turn = [(tuple(p), tuple(v))]
        path = [tuple(p)]
        samples = [(tuple(p), tuple(v))]
        t, aligned, every = 0.0, False, max(1, round(self.PREDICT_DT_S / dt))
        n = 0
        while t < 120.0:
            desired = list(v)
            if t >= self.latency - 1e-9:
                err = [a - b for a, b in zip(target, p)]
                dh = math.hypot(err[0], err[1])
                desired = [0.0, 0.0, 0.0]
                if dh > 1e-6:
                    vh = min(speed, math.sqrt(2.0 * self.accel * dh), dh / dt)
                    desired[0], desired[1] = err[0] / dh * vh, err[1] / dh * vh
                dz = abs(err[2])
                if dz > 1e-6:
                    desired[2] = math.copysign(min(self.max_vspeed, braking_speed(dz, self.accel, dt)), err[2])
                if not aligned:
                    vh_now = math.hypot(v[0], v[1])
                    aligned = vh_now < 1e-3 or dh < 1e-3 or (v[0] * err[0] + v[1] * err[1]) / (vh_now * dh) > 0.999
                if dh < 1e-3 and dz < 1e-3 and math.sqrt(sum(c * c for c in v)) < 1e-3:
                    break
            self._accelerate(v, desired, dt, vertical_first=t >= self.latency - 1e-9)
            p = [a + b * dt for a, b in zip(p, v)]
            t += dt
            n += 1
            path.append(tuple(p))
            if n % every == 0:
                samples.append((tuple(p), tuple(v)))
                if not aligned:
                    turn.append((tuple(p), tuple(v)))
        turn.append((tuple(p), tuple(v)))
        samples.append((tuple(p), tuple(v)))
        return turn, path, samples

    def _stop_point(self, p: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
        vx, vy, vz = v
        n = math.sqrt(vx * vx + vy * vy + vz * vz)
        if n < 1e-9:
            return (p[0], p[1], p[2])
        d = n * n / (2.0 * self.accel) / n  # stopping_distance(n) / n
        return (p[0] + vx * d, p[1] + vy * d, p[2] + vz * d)

    def _fence_violation(self, path: list) -> str | None:
        """The first geofence violation of a predicted path or of the stop from any of its points, or None."""
        if self.fence.is_empty:
            return None
        pts = [p for p, _ in path]
        why = self.fence.check_path([(p[0], p[1]) for p in pts])
        if why is not None:
            return f"path: {why}"
        for p, v in path:
            e = self._stop_point(p, v)
            why = self.fence.check_segment((p[0], p[1]), (e[0], e[1]))
            if why is not None:
                return f"stopping from ({p[0]:.1f}, {p[1]:.1f}) m at {math.hypot(v[0], v[1]):.1f} m/s: {why}"
        return None

    def _z_range(self, path: list) -> tuple[float, float]:
        """Lowest and highest altitude (m) of a predicted path and of the stop from each of its points."""
        two_a, sqrt = 2.0 * self.accel, math.sqrt
        zs = []
        for p, (vx, vy, vz) in path:  # _stop_point's height, written out
            n = sqrt(vx * vx + vy * vy + vz * vz)
            zs += (p[2], p[2] if n < 1e-9 else p[2] + vz * (n * n / two_a / n))
        return max(zs), min(zs)

    def check_item(self, item: Any, position: Sequence[float] | None = None,
                   velocity: Sequence[float] | None = None) -> Any:
        """Dispatch on the item type; actions (land, RTL) are always allowed. ``velocity`` (ENU m/s): the
        vehicle's current one, for the dynamics envelope."""
        if isinstance(item, Waypoint):
            return self.check_waypoint(item, position, velocity)
        if isinstance(item, VelocityCommand):
            return self.check_velocity(item, position, velocity)
        if isinstance(item, ActionCommand):
            self._check_values(item)
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

    def check_gimbal(self, limits: Any, pitch_deg: float | None = None, yaw_deg: float | None = None,
                     roi_enu: Sequence[float] | None = None) -> None:
        """A gimbal command against the robot's gimbal ``limits`` (:class:`aerodaas.navigation.gimbal.GimbalLimits`):
        pitch/yaw degrees within them, or a region of interest (ENU metres) finite and near home. Raises
        :class:`SafetyViolation` (item ``gimbal``, the field and value) and counts it as rejected."""
        try:
            if roi_enu is not None:
                limits.check_roi(*roi_enu)
            else:
                limits.check(pitch_deg, yaw_deg)
        except ValueError as e:
            self.rejected += 1
            raise SafetyViolation("gimbal", getattr(e, "field", "gimbal"), getattr(e, "value", None), str(e)) from None

    def stats(self) -> dict:
        return {"rejected": self.rejected, "clamped": self.clamped}
