"""Vehicle backend ``ground_rover``: a ground rover written from scratch on the backend contract (a direct
:class:`~aerodaas.backends.base.VehicleBackend` subclass; AeroDaaS docs/extending-vehicles.md walks
through it).

The rover never leaves the ground (``needs_takeoff = False``): armed, it is ready to drive; its ``in_air`` is always
False, its position's z always 0, and ``land`` stops it where it is.

Model: the kinematic unicycle (a differential-drive or skid-steer vehicle without wheel slip; Siegwart, Nourbakhsh &
Scaramuzza, *Introduction to Autonomous Mobile Robots*, 2nd ed., MIT Press 2011, section 3.2.1): the rover moves
along its heading psi at forward speed v and turns at rate omega,

    dx/dt = v cos(psi),   dy/dt = v sin(psi),   dpsi/dt = omega,

integrated exactly over each step for the step's constant (v, omega) (a circular arc, a straight line when omega is
0). Its own clock (``clock = "sim"``): it moves only in :meth:`RoverBackend.step`, by ``dt`` simulated seconds. The
controller turns towards the target at up to ``turn_rate_dps`` and drives only as far as it faces it
(``v * max(0, cos(heading error))``: on the spot while the target is abeam or behind), accelerating and braking
at ``accel_mps2`` to stop on the target. The battery drains per second while armed and per metre driven; an empty battery stops the rover
(a ``battery_empty`` event). Settings: ``robots[].backend_config`` = :class:`RoverConfig`.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from typing import Any, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from aerodaas.backends.base import CommandRefused, VehicleBackend, VehicleState
from aerodaas.config import ConfigError
from aerodaas.model.types import Waypoint

#: below this distance (m) to its target the rover counts as on it and stops (no turning on the spot over a mm)
ON_TARGET_M = 0.01


class RoverConfig(BaseModel):
    """``backend_config`` of ``ground_rover``: the vehicle's top speed (m/s), turn rate (deg/s), acceleration and
    braking (m/s^2), heading at start (deg, ENU: counter-clockwise from east), battery at start (percent) and its drain
    (percent per second armed, percent per metre driven). Unknown keys are refused."""

    model_config = ConfigDict(extra="forbid")

    max_speed_mps: float = Field(default=2.0, gt=0, le=20.0, description="top speed, m/s")
    turn_rate_dps: float = Field(default=90.0, gt=0, le=720.0, description="top turn rate, deg/s")
    accel_mps2: float = Field(default=1.0, gt=0, le=20.0, description="acceleration and braking, m/s^2")
    start_yaw_deg: float = Field(default=0.0, ge=-360.0, le=360.0, description="heading at start, deg CCW from east")
    start_battery_pct: float = Field(default=100.0, gt=0, le=100.0, description="percent")
    drain_pct_per_s: float = Field(default=0.01, ge=0, le=100.0, description="percent per second while armed")
    drain_pct_per_m: float = Field(default=0.05, ge=0, le=100.0, description="percent per metre driven")


class Mode(enum.Enum):
    """What the rover is doing: standing (HOLD: braking to a stop), driving to a point (GOTO) or following a
    velocity (VELOCITY)."""

    HOLD = "hold"
    GOTO = "goto"
    VELOCITY = "velocity"


@dataclasses.dataclass(frozen=True)
class Command:
    """The last command: its mode, the GOTO target (ENU m, z ignored) and speed cap (m/s), the VELOCITY command's
    ground velocity (ENU m/s, z ignored) and yaw rate (deg/s, CCW positive)."""

    mode: Mode = Mode.HOLD
    target: tuple[float, float] = (0.0, 0.0)
    speed_mps: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    yaw_rate_dps: float = 0.0


@dataclasses.dataclass(frozen=True)
class RoverState:
    """The rover at time ``t`` (s): position (ENU m from home, on the ground), heading ``psi`` (rad, CCW from
    east), forward speed ``v`` (m/s, >= 0) and turn rate ``omega`` (rad/s), battery (percent), armed, the command
    it follows and the metres driven. Immutable: :meth:`RoverBackend.step` swaps in a new one, so a status thread
    reading the state never sees half a step."""

    t: float = 0.0
    x: float = 0.0
    y: float = 0.0
    psi: float = 0.0
    v: float = 0.0
    omega: float = 0.0
    battery_pct: float = 100.0
    armed: bool = False
    command: Command = Command()
    odometer_m: float = 0.0


def unicycle(x: float, y: float, psi: float, v: float, omega: float, dt: float) -> tuple[float, float, float]:
    """The unicycle's pose after ``dt`` s at constant forward speed ``v`` (m/s) and turn rate ``omega`` (rad/s)
    from (``x``, ``y``) m, heading ``psi`` rad: the exact solution (an arc of radius v/omega; a straight line for
    omega = 0). Returns (x, y, psi), psi wrapped to (-pi, pi]."""
    psi1 = psi + omega * dt
    if abs(omega) < 1e-9:
        x1, y1 = x + v * dt * math.cos(psi), y + v * dt * math.sin(psi)
    else:
        r = v / omega
        x1, y1 = x + r * (math.sin(psi1) - math.sin(psi)), y - r * (math.cos(psi1) - math.cos(psi))
    return x1, y1, math.atan2(math.sin(psi1), math.cos(psi1))


def _wrap(a: float) -> float:
    """Angle ``a`` (rad) wrapped to (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


class RoverBackend(VehicleBackend):
    """See the module docstring. Constructed by the drone actor as ``RoverBackend(cfg)`` with the robot's
    :class:`aerodaas.config.RobotConfig`."""

    kind = "ground_rover"
    clock = "sim"  # it moves only in step(dt): simulated time, speedup and lock-step apply
    needs_takeoff = False  # armed, it is ready to drive: no take-off command, no take-off phase
    Config = RoverConfig
    produces = ("odometry", "events:battery_empty")

    def __init__(self, cfg: Any) -> None:
        super().__init__(cfg.id, cfg.home)
        self.opts: RoverConfig = self.options(cfg)
        self._s = RoverState(psi=math.radians(self.opts.start_yaw_deg), battery_pct=self.opts.start_battery_pct)
        self._events: list[dict[str, Any]] = []
        #: the command groups the drone calls: the rover carries its commands itself (the methods under "control")
        self.actions = self.guidance = self

    # ------------------------------------------------------------------ pre-flight checks (before Ray starts)
    @classmethod
    def check_config(cls, robot: Any, where: str) -> None:
        """The robot's safety floor must be the ground: a waypoint at z = 0 is below any ``safety.min_altitude``
        above 0, and the safety gate would refuse every one. Raises ConfigError naming the field and value."""
        if robot.safety.min_altitude != 0.0:
            raise ConfigError(f"{where}.safety.min_altitude: {robot.safety.min_altitude:g} m; a rover (backend "
                              f"{robot.backend!r}) drives on the ground at z = 0, so set it to 0")

    @classmethod
    def check_mission(cls, robot: Any, sched: Any, hitl_on: bool) -> None:
        """Every queued waypoint lies on the ground (z = 0): the rover cannot climb to any other, and the drone
        judges arrival in 3-D. Raises ConfigError naming the robot, the waypoint and its z."""
        for item in sched.queued():
            if isinstance(item, Waypoint) and item.z != 0:
                raise ConfigError(f"robot {robot.id!r}: waypoint {item.id!r} at z = {item.z:g} m; a rover (backend "
                                  f"{cls.kind!r}) drives on the ground, so its waypoints lie at z = 0")

    # ------------------------------------------------------------------ lifecycle (the simulation needs no link)
    def checkpoint(self) -> RoverState:
        """The whole simulated state (immutable, so the value itself)."""
        return self._s

    def restore(self, state: RoverState) -> None:
        self._s = state

    # ------------------------------------------------------------------ time and state
    def step(self, dt: float) -> None:
        """Advance ``dt`` simulated seconds: the controller picks (v, omega) for the command, the unicycle moves,
        the battery drains. Raises ValueError for a negative ``dt``."""
        if dt < 0:
            raise ValueError(f"robot {self.robot_id!r}: step dt must be >= 0 s, got {dt!r}")
        s = self._s
        v, omega = self._control(s, dt) if s.armed and s.battery_pct > 0 else (0.0, 0.0)
        x, y, psi = unicycle(s.x, s.y, s.psi, v, omega, dt)
        drain = (self.opts.drain_pct_per_s * dt if s.armed else 0.0) + self.opts.drain_pct_per_m * v * dt
        battery = max(0.0, s.battery_pct - drain)
        if battery == 0.0 < s.battery_pct:
            self._events.append({"event": "battery_empty", "odometer_m": round(s.odometer_m + v * dt, 3)})
        self._s = dataclasses.replace(s, t=s.t + dt, x=x, y=y, psi=psi, v=v, omega=omega, battery_pct=battery,
                                      odometer_m=s.odometer_m + v * dt)

    def _control(self, s: RoverState, dt: float) -> tuple[float, float]:
        """(v m/s, omega rad/s) for the next ``dt`` s of command ``s.command``: turn towards the wanted heading
        (reaching it within the step when the turn rate allows), drive as far as the rover faces it, speed up
        and brake at ``accel_mps2`` so that a GOTO stops on its target without overshooting."""
        c, o = s.command, self.opts
        rate, dt = math.radians(o.turn_rate_dps), max(dt, 1e-9)
        if c.mode is Mode.HOLD:
            return max(0.0, s.v - o.accel_mps2 * dt), 0.0
        if c.mode is Mode.VELOCITY:
            want = math.hypot(*c.velocity)
            if want < 1e-6:  # a yaw rate alone: turn on the spot
                return max(0.0, s.v - o.accel_mps2 * dt), float(np.clip(math.radians(c.yaw_rate_dps), -rate, rate))
            heading, cap, brake = math.atan2(c.velocity[1], c.velocity[0]), min(want, o.max_speed_mps), math.inf
        else:
            d = math.hypot(c.target[0] - s.x, c.target[1] - s.y)
            if d < ON_TARGET_M:
                return 0.0, 0.0
            heading, cap = math.atan2(c.target[1] - s.y, c.target[0] - s.x), c.speed_mps
            brake = min(math.sqrt(2.0 * o.accel_mps2 * d), d / dt)  # stop on the target, never past it
        err = _wrap(heading - s.psi)
        omega = float(np.clip(err / dt, -rate, rate))
        v = min(cap, brake, s.v + o.accel_mps2 * dt) * max(0.0, math.cos(err - omega * dt))
        return max(0.0, v), omega

    def state(self) -> VehicleState:
        """The rover now (exact: no noise): ENU metres from home on the ground (z always 0), its ground velocity
        along the heading (ENU m/s, z 0), the heading as yaw (degrees CCW from east in [0, 360)), battery percent,
        armed; never in the air; the link (there is none) always up. The base class's ``telemetry`` records it as
        odometry, with the geodetic position from ``home``."""
        s = self._s
        return VehicleState(t=s.t, position=(s.x, s.y, 0.0),
                            velocity=(s.v * math.cos(s.psi), s.v * math.sin(s.psi), 0.0),
                            yaw=math.degrees(s.psi) % 360.0, battery_pct=s.battery_pct, armed=s.armed, in_air=False,
                            home=self.home)

    def drain_events(self) -> list[dict[str, Any]]:
        out, self._events = self._events, []
        return out

    # ------------------------------------------------------------------ control (``actions`` and ``guidance``)
    def arm(self) -> None:
        """Arm (standing still). Raises CommandRefused when the battery is empty."""
        if self._s.battery_pct <= 0.0:
            raise CommandRefused(self.robot_id, "arm", "DENIED", "battery empty")
        self._s = dataclasses.replace(self._s, armed=True, command=Command())

    def disarm(self) -> None:
        """Disarm: the motors stop at once (the kinematic model has no coasting). Never raises."""
        self._s = dataclasses.replace(self._s, armed=False, v=0.0, omega=0.0, command=Command())

    def takeoff(self, altitude_m: float) -> None:
        """Refused: a rover does not fly (the runtime never asks, as ``needs_takeoff`` is False)."""
        raise CommandRefused(self.robot_id, f"takeoff to {altitude_m:g} m", "UNSUPPORTED",
                             "a ground rover never leaves the ground")

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Drive to the ground point under ``target_enu`` (ENU m; z ignored: the mission check keeps it 0) at up to
        ``speed`` m/s (None, or above ``max_speed_mps``: ``max_speed_mps``). Raises CommandRefused when disarmed."""
        self._require_armed("goto")
        cap = self.opts.max_speed_mps if speed is None else min(float(speed), self.opts.max_speed_mps)
        self._command(Command(Mode.GOTO, target=(float(target_enu[0]), float(target_enu[1])), speed_mps=cap))

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Drive at the ground velocity ``v_enu[:2]`` (ENU m/s, capped at ``max_speed_mps``; a unicycle cannot move
        sideways, so it turns to that direction first; ``v_enu[2]`` ignored); with no ground velocity, turn on the
        spot at ``yaw_rate_dps`` (deg/s, CCW positive, capped at ``turn_rate_dps``). Raises CommandRefused when
        disarmed."""
        self._require_armed("set_velocity")
        self._command(Command(Mode.VELOCITY, velocity=(float(v_enu[0]), float(v_enu[1])),
                              yaw_rate_dps=float(yaw_rate_dps)))

    def hold(self) -> None:
        """Brake to a stop where it is (at ``accel_mps2``). Never raises."""
        self._command(Command(Mode.HOLD))

    def land(self) -> None:
        """Stop: a rover is always on the ground, so a landing is a hold. Never raises."""
        self.hold()

    def return_to_launch(self) -> bool:
        """False: no return mode of its own (the drone drives it home with ``goto`` and stops it with ``land``)."""
        return False

    def _require_armed(self, command: str) -> None:
        if not self._s.armed:
            raise CommandRefused(self.robot_id, command, "DENIED", "not armed")

    def _command(self, c: Command) -> None:
        self._s = dataclasses.replace(self._s, command=c)
