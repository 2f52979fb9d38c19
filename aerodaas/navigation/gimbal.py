"""A two-axis camera gimbal: its limits, the angles that point it at a region of interest, its slew, and the
attitude quaternion MAVLink's gimbal protocol v2 carries.

Conventions are MAVLink's gimbal protocol v2 (``MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW``,
``GIMBAL_DEVICE_ATTITUDE_STATUS``; https://mavlink.io/en/services/gimbal_v2.html): **pitch** in degrees, 0 at the
horizon, positive up, -90 straight down (nadir); **yaw** in degrees relative to the vehicle's nose, positive to the
right (clockwise seen from above, the FRD body frame), unless said to be in the earth frame (then from north,
clockwise). AeroDaaS's camera pose uses ENU: the camera's pitch below the horizon is ``-pitch_deg`` and its heading
counter-clockwise from east is ``vehicle_yaw_enu - gimbal_yaw_deg`` (:func:`camera_angles`).

Default limits are ArduPilot's for a servo mount (``MNT1_PITCH_MIN`` -90, ``MNT1_PITCH_MAX`` 20, ``MNT1_YAW_MIN``
-180, ``MNT1_YAW_MAX`` 180 degrees, as its GIMBAL_MANAGER_INFORMATION reports them).
"""
from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["GimbalError", "GimbalLimits", "MAX_ROI_M", "GimbalModel", "roi_angles", "camera_angles", "quaternion_from_euler",
           "euler_from_quaternion", "wrap_deg"]


def wrap_deg(a: float) -> float:
    """``a`` degrees wrapped into [-180, 180)."""
    return (a + 180.0) % 360.0 - 180.0


#: how far (ENU metres, each axis) a region of interest may be from home: a bound on bad input, not a sensor range
MAX_ROI_M = 100_000.0


class GimbalError(ValueError):
    """A gimbal command that cannot be carried out: the robot has no gimbal, or a value (``field``, ``value``) is
    not finite or outside the gimbal's limits. Raised before anything is sent to the vehicle."""

    def __init__(self, message: str, field: str = "gimbal", value: object = None) -> None:
        super().__init__(message)
        self.field, self.value = field, value

    def __reduce__(self):  # picklable across Ray workers
        return (GimbalError, (str(self), self.field, self.value))


class GimbalLimits(BaseModel):
    """The angles a gimbal may be pointed at and how fast it turns (degrees, degrees/s; pitch -90 = nadir, yaw
    relative to the vehicle's nose, positive right). Raises pydantic's ValidationError naming the field for a
    value out of range, a string or a bool, or a minimum not below its maximum."""

    model_config = ConfigDict(strict=True, frozen=True, extra="forbid")

    pitch_min_deg: float = Field(-90.0, ge=-180.0, le=180.0)
    pitch_max_deg: float = Field(20.0, ge=-180.0, le=180.0)
    yaw_min_deg: float = Field(-180.0, ge=-180.0, le=180.0)
    yaw_max_deg: float = Field(180.0, ge=-180.0, le=180.0)
    #: slew rate of each axis, degrees/s
    rate_deg_s: float = Field(60.0, gt=0.0, le=1000.0)

    @model_validator(mode="after")
    def _ordered(self) -> "GimbalLimits":
        if not self.pitch_min_deg < self.pitch_max_deg:
            raise ValueError(f"pitch_min_deg ({self.pitch_min_deg}) must be below pitch_max_deg ({self.pitch_max_deg})")
        if not self.yaw_min_deg < self.yaw_max_deg:
            raise ValueError(f"yaw_min_deg ({self.yaw_min_deg}) must be below yaw_max_deg ({self.yaw_max_deg})")
        return self

    @property
    def yaw_full_circle(self) -> bool:
        """Whether yaw turns all the way round (limits -180..180): then it takes the shorter way."""
        return self.yaw_max_deg - self.yaw_min_deg >= 360.0 - 1e-9

    def check(self, pitch_deg: float, yaw_deg: float) -> None:
        """Raise :class:`GimbalError` (a ValueError) naming the axis and value when (pitch, yaw) degrees is not a
        finite number or is outside the limits."""
        for name, v, lo, hi in (("pitch_deg", pitch_deg, self.pitch_min_deg, self.pitch_max_deg),
                                ("yaw_deg", yaw_deg, self.yaw_min_deg, self.yaw_max_deg)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise GimbalError(f"gimbal {name} {v!r} is outside the gimbal's limits [{lo}, {hi}] degrees", name, v)

    @staticmethod
    def check_roi(x: float, y: float, z: float) -> None:
        """Raise :class:`GimbalError` naming the coordinate and value when a region of interest (ENU metres from
        home) is not finite or farther than :data:`MAX_ROI_M` on an axis."""
        for name, v in (("x", x), ("y", y), ("z", z)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > MAX_ROI_M:
                raise GimbalError(f"gimbal region of interest {name} {v!r} is not a finite ENU coordinate within "
                                  f"±{MAX_ROI_M:g} m of home", f"roi_{name}", v)

    def clamp(self, pitch_deg: float, yaw_deg: float) -> tuple[float, float]:
        """(pitch, yaw) degrees brought within the limits (yaw wrapped first). Raises ValueError if not finite."""
        if not (math.isfinite(pitch_deg) and math.isfinite(yaw_deg)):
            raise ValueError(f"gimbal angles must be finite, got pitch {pitch_deg!r}, yaw {yaw_deg!r}")
        yaw = wrap_deg(yaw_deg) if self.yaw_full_circle else yaw_deg
        return (min(max(pitch_deg, self.pitch_min_deg), self.pitch_max_deg),
                min(max(yaw, self.yaw_min_deg), self.yaw_max_deg))


def roi_angles(vehicle_enu: tuple[float, float, float], vehicle_yaw_enu_deg: float,
               roi_enu: tuple[float, float, float]) -> tuple[float, float]:
    """The gimbal (pitch, yaw) in degrees that points the camera from ``vehicle_enu`` (ENU metres) at ``roi_enu``
    (ENU metres), the vehicle's nose at ``vehicle_yaw_enu_deg`` (counter-clockwise from east): pitch =
    atan2(dz, horizontal distance), yaw = the bearing to the point relative to the nose, positive right.
    Straight below the vehicle (horizontal distance under 1 mm) the yaw is 0. Raises ValueError for a
    non-finite input."""
    vals = (*vehicle_enu, vehicle_yaw_enu_deg, *roi_enu)
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"roi_angles needs finite values, got vehicle {vehicle_enu}, yaw {vehicle_yaw_enu_deg}, "
                         f"roi {roi_enu}")
    dx, dy, dz = (roi_enu[i] - vehicle_enu[i] for i in range(3))
    h = math.hypot(dx, dy)
    pitch = math.degrees(math.atan2(dz, h))
    if h < 1e-3:
        return pitch, 0.0
    bearing_enu = math.degrees(math.atan2(dy, dx))
    return pitch, wrap_deg(vehicle_yaw_enu_deg - bearing_enu)


def camera_angles(vehicle_yaw_enu_deg: float, pitch_deg: float, yaw_deg: float) -> tuple[float, float]:
    """The camera's (heading ENU degrees counter-clockwise from east, pitch below the horizon in degrees, 90 =
    nadir) for a gimbal at (pitch, yaw relative to the nose) on a vehicle heading ``vehicle_yaw_enu_deg``: what
    :class:`aerodaas.app.models.FramePose` carries."""
    return wrap_deg(vehicle_yaw_enu_deg - yaw_deg), -pitch_deg


class GimbalModel:
    """A gimbal that turns each axis towards its target at ``limits.rate_deg_s`` (the simulator's and the MAVLink
    emulator's gimbal). Angles in degrees (module conventions); time in seconds."""

    def __init__(self, limits: GimbalLimits | None = None, pitch_deg: float = 0.0, yaw_deg: float = 0.0) -> None:
        self.limits = limits or GimbalLimits()
        self.pitch_deg, self.yaw_deg = self.limits.clamp(pitch_deg, yaw_deg)
        self.target = (self.pitch_deg, self.yaw_deg)

    def point(self, pitch_deg: float, yaw_deg: float) -> tuple[float, float]:
        """Aim at (pitch, yaw), clamped to the limits; returns the target taken. ValueError if not finite."""
        self.target = self.limits.clamp(pitch_deg, yaw_deg)
        return self.target

    def step(self, dt: float) -> None:
        """Turn for ``dt`` seconds (each axis at most ``rate_deg_s * dt``; yaw the shorter way on a full circle)."""
        if dt <= 0:
            return
        reach = self.limits.rate_deg_s * dt
        dp = self.target[0] - self.pitch_deg
        self.pitch_deg += max(-reach, min(reach, dp))
        dy = self.target[1] - self.yaw_deg
        if self.limits.yaw_full_circle:
            dy = wrap_deg(dy)
        self.yaw_deg += max(-reach, min(reach, dy))
        if self.limits.yaw_full_circle:
            self.yaw_deg = wrap_deg(self.yaw_deg)

    @property
    def settled(self) -> bool:
        """Whether both axes are within 0.01 degrees of the target."""
        return abs(self.target[0] - self.pitch_deg) < 0.01 and abs(wrap_deg(self.target[1] - self.yaw_deg)) < 0.01


def quaternion_from_euler(roll_deg: float, pitch_deg: float, yaw_deg: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the rotation yaw (z), then pitch (y), then roll (x) — the aerospace ZYX sequence MAVLink's
    attitude quaternions use (``GIMBAL_DEVICE_ATTITUDE_STATUS.q``, FRD frame; pymavlink's ``mavextra`` and
    ArduPilot's ``Quaternion::from_euler`` likewise). Angles in degrees."""
    r, p, y = (math.radians(a) / 2.0 for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def euler_from_quaternion(q: tuple[float, float, float, float]) -> tuple[float, float, float]:
    """(roll, pitch, yaw) degrees of the (w, x, y, z) quaternion (ZYX, as :func:`quaternion_from_euler`; pitch
    clipped to ±90 at the gimbal-lock singularity). Raises ValueError for a quaternion that is not finite or of
    norm 0 (MAVLink sends NaN for an unknown attitude)."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"not an attitude quaternion: {tuple(q)}")
    w, x, y, z = w / n, x / n, y / n, z / n
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)
