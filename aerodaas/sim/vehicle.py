"""Embedded multirotor simulator: point-mass kinematics with speed, acceleration and yaw-rate limits, a battery
model and GPS derived from the local position.

Model (per physics step ``dt`` seconds):

* A setpoint gives a desired ENU velocity: for a position target, the speed towards it is
  ``min(v_max, sqrt(2 * a_max * distance))`` horizontally (the standard trapezoidal-velocity profile) and
  vertically the discrete-time braking speed (:func:`aerodaas.navigation.braking.braking_speed`: no overshoot at
  any physics step, so a waypoint under ``max_altitude`` is never passed), axes limited separately; for a velocity
  target the commanded velocity, clipped to the limits.
* A hold brakes to rest at ``a_max`` along the velocity (the safety gate's stopping model), then hovers there.
* The actual velocity moves towards the desired one by at most ``a_max * dt`` (acceleration limit; for a position
  target the vertical change first: :func:`aerodaas.navigation.braking.limited_change`).
* Yaw moves towards the desired yaw by at most ``max_yaw_rate * dt``.
* Battery: energy drawn while airborne is ``(P_hover + k * |v|) * dt`` joules (W·s), voltage is linear in
  state of charge between empty and full (a deliberately simple LiPo model).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aerodaas.config import BatteryConfig, Limits, NoiseConfig
from aerodaas.navigation.braking import braking_speed, limited_change
from aerodaas.model.geo import enu_to_lat_lon_alt
from aerodaas.model.types import Attitude, GeoPoint, Odometry


@dataclass
class Setpoint:
    """``mode``: 'idle' (on ground), 'hold' (brake, then hover at ``target``: where it came to rest), 'position'
    (fly to ``target``), 'velocity' (hold ``velocity`` m/s), 'land' (descend at ``land_speed_high`` m/s, None: the
    vertical speed limit, down to ``land_alt_low`` m above home, then at ``land_speed`` m/s: ArduCopter's LAND,
    ``Mode::land_run_vertical_control`` in ``ArduCopter/mode.cpp``, with ``LAND_SPEED_HIGH`` 0 (``WPNAV_SPEED_DN``)
    above ``LAND_ALT_LOW`` 10 m and ``LAND_SPEED`` 50 cm/s below; PX4 slows from ``MPC_Z_V_AUTO_DN`` below
    ``MPC_LAND_ALT1`` 10 m alike). ``stopped``:
    a hold has come to rest (before, it brakes)."""

    mode: str = "idle"
    target: tuple[float, float, float] | None = None
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    speed: float | None = None  # m/s cap for position mode
    yaw_rate: float = 0.0  # deg/s for velocity mode
    land_speed: float = 0.5
    land_speed_high: float | None = None  # m/s above land_alt_low (None: the vertical speed limit)
    land_alt_low: float = 10.0  # m above home
    stopped: bool = False


@dataclass
class SimState:
    """The simulated multirotor's own mutable state: position (3,) ENU m, velocity (3,) ENU m/s, yaw deg ENU, armed,
    in-air, battery energy J."""

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 90.0  # deg, ENU (90 = facing north)
    armed: bool = False
    in_air: bool = False
    energy_j: float = 0.0


class SimVehicle:
    """One simulated multirotor. Positions in ENU metres from home, velocities in m/s, yaw in degrees."""

    def __init__(self, robot_id: str, home: GeoPoint, limits: Limits, battery: BatteryConfig,
                 noise: NoiseConfig | None = None) -> None:
        self.robot_id = robot_id
        self.home = home
        self.limits = limits
        self.battery = battery
        self.noise = noise or NoiseConfig()
        self._rng = np.random.default_rng(self.noise.seed)
        self.state = SimState(energy_j=battery.capacity_wh * 3600.0 * battery.initial_pct / 100.0)
        self.setpoint = Setpoint()
        self.t = 0.0

    @property
    def noise_state(self) -> dict:
        """The state of the noise generator (numpy ``bit_generator.state``, a dict; not a copy): with
        :attr:`state`, :attr:`setpoint` and :attr:`t`, what a checkpoint needs to continue the same noisy run."""
        return self._rng.bit_generator.state

    @noise_state.setter
    def noise_state(self, value: dict) -> None:
        """Restore a :attr:`noise_state`. Raises TypeError/ValueError (numpy) for a state of another generator."""
        self._rng.bit_generator.state = value

    # ------------------------------------------------------------------ dynamics
    def step(self, dt: float) -> None:
        """Advance the simulation by ``dt`` seconds. Computed on Python floats (a step is a few dozen operations on
        3-vectors, for which numpy's per-call overhead is most of the cost); :attr:`state`'s position and velocity
        arrays are updated in place."""
        s, sp, lim = self.state, self.setpoint, self.limits
        self.t += dt
        if not s.in_air and sp.mode not in ("position",):
            s.velocity[:] = 0.0
            return
        px, py, pz = s.position.tolist()
        vx, vy, vz = s.velocity.tolist()
        dx = dy = dz = 0.0  # the desired velocity
        if sp.mode == "position" and sp.target is not None:
            ex, ey, ez = float(sp.target[0]) - px, float(sp.target[1]) - py, float(sp.target[2]) - pz
            dh = math.hypot(ex, ey)
            vmax = min(lim.max_speed, sp.speed) if sp.speed else lim.max_speed
            if dh > 1e-6:
                vh = min(vmax, math.sqrt(2.0 * lim.max_acceleration * dh), dh / dt)
                dx, dy = ex / dh * vh, ey / dh * vh
            if abs(ez) > 1e-6:
                dz = math.copysign(min(lim.max_vertical_speed, braking_speed(abs(ez), lim.max_acceleration, dt)), ez)
        elif sp.mode == "velocity":
            dx, dy, dz = (float(c) for c in sp.velocity)
            h = math.hypot(dx, dy)
            if h > lim.max_speed:
                dx, dy = dx * (lim.max_speed / h), dy * (lim.max_speed / h)
            dz = min(max(dz, -lim.max_vertical_speed), lim.max_vertical_speed)
            yr = min(max(float(sp.yaw_rate), -lim.max_yaw_rate), lim.max_yaw_rate)
            s.yaw = (s.yaw + yr * dt) % 360.0
        elif sp.mode == "land":
            high = lim.max_vertical_speed if sp.land_speed_high is None else sp.land_speed_high
            dz = -min(sp.land_speed if pz <= sp.land_alt_low else high, lim.max_vertical_speed)
        elif sp.mode == "hold" and sp.target is not None and sp.stopped:
            m = lim.max_speed
            dx, dy, dz = (min(max((float(c) - p) * 1.5, -m), m) for c, p in zip(sp.target, (px, py, pz)))
        # a hold not yet at rest brakes at the full acceleration along its velocity (desired 0): the stop the safety
        # gate predicts from every point (v^2 / 2a along v); steering back to where the hold was commanded at the
        # same time took part of the budget and passed that stop point (0.57 m above max_altitude)
        # a position target: the vertical change first, so a climb brakes under its target whatever the turn needs
        cx, cy, cz = limited_change((dx - vx, dy - vy, dz - vz), lim.max_acceleration * dt,
                                    vertical_first=sp.mode == "position")
        vx, vy, vz = vx + cx, vy + cy, vz + cz
        px, py, pz = px + vx * dt, py + vy * dt, pz + vz * dt
        if sp.mode == "hold" and not sp.stopped and not (vx or vy or vz):
            sp.stopped, sp.target = True, (px, py, pz)  # at rest: hover here
        if pz <= 0.0:
            pz = 0.0
            if vz < 0:
                vx = vy = vz = 0.0
                if sp.mode == "land":
                    s.in_air = False
        elif pz > 0.05:
            s.in_air = True
        s.position[:] = (px, py, pz)
        s.velocity[:] = (vx, vy, vz)
        if s.in_air:
            speed = math.sqrt(vx * vx + vy * vy + vz * vz)
            p = self.battery.hover_power_w + self.battery.speed_power_w_per_mps * speed
            s.energy_j = max(0.0, s.energy_j - p * dt)

    # ------------------------------------------------------------------ commands
    def arm(self) -> None:
        self.state.armed = True

    def disarm(self) -> None:
        if self.state.in_air:
            raise RuntimeError(f"{self.robot_id}: cannot disarm while airborne")
        self.state.armed = False
        self.setpoint = Setpoint("idle")

    def takeoff(self, altitude: float) -> None:
        if not self.state.armed:
            raise RuntimeError(f"{self.robot_id}: takeoff refused, vehicle not armed")
        x, y, _ = self.state.position
        self.setpoint = Setpoint("position", target=(float(x), float(y), float(altitude)))

    def goto(self, target: tuple[float, float, float], speed: float | None = None) -> None:
        self.setpoint = Setpoint("position", target=tuple(float(v) for v in target), speed=speed)

    def set_velocity(self, v: tuple[float, float, float], yaw_rate: float = 0.0) -> None:
        self.setpoint = Setpoint("velocity", velocity=tuple(float(c) for c in v), yaw_rate=yaw_rate)

    def hold(self) -> None:
        self.setpoint = Setpoint("hold", target=tuple(float(c) for c in self.state.position))

    def land(self) -> None:
        self.setpoint = Setpoint("land")

    def return_to_launch(self) -> bool:
        """False: the simulator has no return mode of its own (the drone flies home and lands)."""
        return False

    # ------------------------------------------------------------------ sensing
    @property
    def battery_pct(self) -> float:
        return 100.0 * self.state.energy_j / (self.battery.capacity_wh * 3600.0)

    @property
    def battery_voltage(self) -> float:
        b = self.battery
        return b.voltage_empty + (b.voltage_full - b.voltage_empty) * self.battery_pct / 100.0

    def _sample(self) -> tuple:
        """One odometry sample's values as plain floats and bools, noise drawn: ``(t, position, (lat, lon, alt),
        velocity, pitch, yaw, battery_pct, battery_voltage, armed, in_air)``; the geodetic fix unvalidated."""
        s = self.state
        pos = s.position.copy()
        vel = s.velocity.copy()
        if self.noise.gps_std_m > 0:
            pos[:2] += self._rng.normal(0.0, self.noise.gps_std_m, 2)
        if self.noise.velocity_std_mps > 0:
            vel += self._rng.normal(0.0, self.noise.velocity_std_mps, 3)
        px, py, pz = (float(v) for v in pos)
        vx, vy, vz = (float(v) for v in vel)
        pitch = min(max(-vx * 3.0, -25.0), 25.0)  # cosmetic: lean into motion
        return (float(self.t), [px, py, pz], enu_to_lat_lon_alt(px, py, pz, self.home), [vx, vy, vz], pitch,
                float(s.yaw), max(0.0, min(100.0, self.battery_pct)), float(self.battery_voltage), bool(s.armed),
                bool(s.in_air))

    def odometry(self) -> Odometry:
        """Current odometry; GPS comes from the local position (:func:`aerodaas.model.geo.enu_to_lat_lon_alt`), plus
        optional noise. Raises ``pydantic.ValidationError`` for a non-finite position."""
        t, pos, (lat, lon, alt), vel, pitch, yaw, bat, volt, armed, in_air = self._sample()
        return Odometry(robot_id=self.robot_id, t=t, position=tuple(pos), geodetic=GeoPoint(lat=lat, lon=lon, alt=alt),
                        velocity=tuple(vel), attitude=Attitude(roll=0.0, pitch=pitch, yaw=yaw), battery_pct=bat,
                        battery_voltage=volt, armed=armed, in_air=in_air)

    def odometry_json(self) -> dict:
        """:meth:`odometry` as ``Odometry.model_dump(mode="json")`` gives it (the same keys in the same order, the
        same values), built directly: what the drone records and publishes for every sample, without pydantic's
        validation and dump. Raises ``pydantic.ValidationError`` for a non-finite position, as :meth:`odometry`."""
        t, pos, (lat, lon, alt), vel, pitch, yaw, bat, volt, armed, in_air = self._sample()
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
            GeoPoint(lat=lat, lon=lon, alt=alt)  # raises the validation error odometry() raises
        return {"robot_id": self.robot_id, "t": t, "position": pos, "geodetic": {"lat": lat, "lon": lon, "alt": alt},
                "velocity": vel, "attitude": {"roll": 0.0, "pitch": pitch, "yaw": yaw}, "battery_pct": bat,
                "battery_voltage": volt, "armed": armed, "in_air": in_air}
