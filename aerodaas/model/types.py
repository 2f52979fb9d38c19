"""AeroDaaS data model (pydantic v2).

Conventions used everywhere in AeroDaaS:

* Local positions are **ENU metres relative to the robot's home**: ``x`` east, ``y`` north, ``z`` up.
* Geodetic positions are **WGS-84** latitude/longitude in degrees and altitude in metres.
* Angles are degrees; yaw is measured counter-clockwise from east (ENU convention, 0 = facing east).
* Times are seconds (simulation time on the simulator, wall time on real drones) unless a name says ``_ns``.

Invalid values are rejected at construction time with a :class:`pydantic.ValidationError` that names the
field and the bad value, so an invalid waypoint never reaches a drone.
"""
from __future__ import annotations

import math
import numbers
from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, Strict, field_validator, model_validator

__all__ = [
    "Waypoint", "VelocityCommand", "ActionCommand", "NavigationType", "SchedulingType", "AeroNavigation", "PriorityQueue",
    "GeoPoint", "Attitude", "Odometry", "CameraIntrinsics", "FramePose", "FrameMeta", "Detection",
    "NavCommand", "COCO_CLASSES",
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=False, validate_assignment=True)

    def __init__(self, /, **data: Any) -> None:
        # validated in this frame, which is AeroDaaS's: ``aerodaas run`` reports a refused value as bad input (exit 2,
        # aerodaas.runtime.app_errors), not as the application's own exception (exit 1 with its traceback)
        super().__init__(**data)


def _number(v: Any) -> Any:
    """A number as given (any real: ``int``, ``float``, numpy scalars), as a ``float``; a string, a ``bool`` or
    anything else is refused: ``Waypoint(x="1", y=True)`` is a typo, not a coordinate (pydantic's lax mode read them
    as 1.0 and 1.0)."""
    t = type(v)
    if t is float or t is int:  # the common case, without the ABC check below (every field of every command)
        return float(v)
    if isinstance(v, numbers.Real) and not isinstance(v, bool) and type(v).__name__ != "bool_":
        return float(v)
    raise ValueError(f"must be a number (int or float), got {type(v).__name__} {v!r:.40}")


#: a strictly typed number: ints and floats (numpy's too) only, never a string or a bool
Number = Annotated[float, BeforeValidator(_number)]
#: a strictly typed boolean: ``True`` / ``False`` only (not ``"yes"``, ``1``)
StrictBool = Annotated[bool, Strict()]


def _finite(v: float, info) -> float:
    if v is None:
        return v
    if not math.isfinite(float(v)):
        raise ValueError(f"{info.field_name} must be a finite number, got {v!r}")
    return v


#: relative waypoints, altitudes and velocity commands farther than this from home (metres) are refused: beyond any
#: multirotor's range, and large enough to lose precision in the ENU/geodetic conversions
MAX_LOCAL_M = 100_000.0
#: velocity commands faster than this (m/s, any axis) are refused before any safety limit is consulted
MAX_COMMAND_SPEED_MPS = 100.0
#: a waypoint's own ``speed`` below this (m/s) is refused: ArduPilot's WPNAV_SPEED has the same floor (10 cm/s,
#: ArduCopter parameter docs, range 10..2000 cm/s); 1e-300 m/s would hold the vehicle in place until its battery ends
MIN_WAYPOINT_SPEED_MPS = 0.1
#: velocity commands turning faster than this (deg/s) are refused (the configuration's own bound on
#: ``limits.max_yaw_rate``, aerodaas.model.bounds.MAX_YAW_RATE_DPS: 10 turns a second)
MAX_COMMAND_YAW_RATE_DPS = 3600.0


class Waypoint(_Model):
    """A navigation target (paper Table 2: ``Waypoint(id, x, y, z, hover_duration, waypoint_type)``).

    ``waypoint_type="relative"``: ``x``/``y``/``z`` are ENU metres relative to the robot's home.
    ``waypoint_type="absolute"``: ``x`` is latitude (degrees), ``y`` longitude (degrees), ``z`` altitude in
    metres above the home position (the MAVLink ``MAV_FRAME_GLOBAL_RELATIVE_ALT`` convention).

    ``hover_duration`` is seconds to hold position once reached; ``speed`` (m/s, optional, at least
    :data:`MIN_WAYPOINT_SPEED_MPS`) caps the approach speed below the robot's own limit; ``acceptance_radius`` (metres) is how close counts as reached.

    Raises ``pydantic.ValidationError`` for NaN/inf coordinates, strings or booleans given for numbers
    (``x="1"``, ``y=True``), negative hover time, out-of-range lat/lon.
    """

    id: str = Field(min_length=1, max_length=256)
    x: Number
    y: Number
    z: Number
    hover_duration: Number = Field(default=0.0, ge=0.0, le=86_400.0)
    waypoint_type: Literal["relative", "absolute"] = "relative"
    speed: Number | None = Field(default=None, ge=MIN_WAYPOINT_SPEED_MPS, le=MAX_COMMAND_SPEED_MPS)
    acceptance_radius: Number = Field(default=0.3, gt=0.0, le=1000.0)

    _chk = field_validator("x", "y", "z", "hover_duration", "speed")(_finite)

    @model_validator(mode="after")
    def _check_geodetic(self) -> "Waypoint":
        if self.waypoint_type == "relative" and max(abs(self.x), abs(self.y)) > MAX_LOCAL_M:
            raise ValueError(f"x, y must be within +-{MAX_LOCAL_M:g} m of home for a relative waypoint, got "
                             f"({self.x!r}, {self.y!r})")
        if abs(self.z) > MAX_LOCAL_M:
            raise ValueError(f"z must be within +-{MAX_LOCAL_M:g} m of home, got {self.z!r}")
        if self.waypoint_type == "absolute":
            if not -90.0 <= self.x <= 90.0:
                raise ValueError(f"x (latitude) must be within [-90, 90] degrees for an absolute waypoint, got {self.x}")
            if not -180.0 <= self.y <= 180.0:
                raise ValueError(f"y (longitude) must be within [-180, 180] degrees for an absolute waypoint, got {self.y}")
        return self

    def to_local(self, home: "GeoPoint") -> tuple[float, float, float]:
        """ENU metres of this waypoint relative to ``home`` (``pymap3d.geodetic2enu``, as
        :func:`aerodaas.model.geo.geodetic_to_enu`, which imports this module)."""
        if self.waypoint_type == "relative":
            return (self.x, self.y, self.z)
        import pymap3d  # lazy: it imports numpy (~0.1 s); only absolute waypoints need it

        e, n, _ = pymap3d.geodetic2enu(self.x, self.y, home.alt, home.lat, home.lon, home.alt)
        return (float(e), float(n), self.z)


class VelocityCommand(_Model):
    """A velocity setpoint held for ``duration`` seconds: ENU ``vx``/``vy``/``vz`` in m/s, ``yaw_rate`` deg/s.

    Used by analytics-driven navigation (e.g. the follow analytics). Raises ``pydantic.ValidationError`` for
    non-finite values, strings or booleans for numbers, speeds beyond +-:data:`MAX_COMMAND_SPEED_MPS`, a yaw rate
    beyond +-:data:`MAX_COMMAND_YAW_RATE_DPS` or a non-positive duration.
    """

    id: str = "vel"
    vx: Number = 0.0
    vy: Number = 0.0
    vz: Number = 0.0
    yaw_rate: Number = Field(default=0.0, ge=-MAX_COMMAND_YAW_RATE_DPS, le=MAX_COMMAND_YAW_RATE_DPS)
    duration: Number = Field(default=0.5, gt=0.0, le=3600.0)
    issued_at: Number | None = None  # sim time (s) the command was issued; set by the scheduler if None

    _chk = field_validator("vx", "vy", "vz", "yaw_rate", "duration", "issued_at")(_finite)

    def left_at(self, now: float) -> "VelocityCommand":
        """This command as it stands at sim time ``now`` (s): ``duration`` cut to the seconds left of it since
        ``issued_at`` (at least 1 ms; unchanged when ``issued_at`` is None). The safety gate checks that much
        flight, not the whole command again on every tick."""
        if self.issued_at is None:
            return self
        left = max(1e-3, min(self.duration, self.issued_at + self.duration - now))
        return self if left >= self.duration else self.model_copy(update={"duration": left})

    @field_validator("vx", "vy", "vz")
    @classmethod
    def _bounded(cls, v: float, info) -> float:
        if abs(v) > MAX_COMMAND_SPEED_MPS:
            raise ValueError(f"{info.field_name} must be within +-{MAX_COMMAND_SPEED_MPS:g} m/s, got {v!r}")
        return v


class ActionCommand(_Model):
    """A terminal flight action issued by an analytics or a user: ``land`` (descend and land where the drone is)
    or ``rtl`` (return to launch: fly to home at the current altitude, then land). ``reason`` is recorded.

    Executed in priority order like any other navigation item; it ends the mission once the drone has landed."""

    id: str = "action"
    action: Literal["land", "rtl"]
    reason: str = ""


NavCommand = Union[Waypoint, VelocityCommand, ActionCommand]


class NavigationType(str, Enum):
    """Where a navigation comes from (paper §3): pre-planned by distance, or generated by analytics."""

    DISTANCE_DRIVEN = "DISTANCE_DRIVEN"
    ANALYTICS_DRIVEN = "ANALYTICS_DRIVEN"


class SchedulingType(str, Enum):
    """``ORDERED`` keeps the given order; ``UNORDERED`` lets the trajectory scheduler reorder."""

    ORDERED = "ORDERED"
    UNORDERED = "UNORDERED"


class AeroNavigation(_Model):
    """A list of navigation items (the paper's AeroNav): waypoints and/or velocity commands.

    Positional construction as in the paper is accepted:
    ``AeroNavigation(NavigationType.DISTANCE_DRIVEN, [wp1, wp2], SchedulingType.UNORDERED)``.
    """

    navigation_type: NavigationType = NavigationType.DISTANCE_DRIVEN
    waypoints: list[Union[Waypoint, VelocityCommand, ActionCommand]] = Field(default_factory=list)
    scheduling_type: SchedulingType = SchedulingType.ORDERED
    name: str = "mission"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        names = ["navigation_type", "waypoints", "scheduling_type"]
        if len(args) > len(names):
            raise TypeError(f"AeroNavigation takes at most {len(names)} positional arguments")
        for n, a in zip(names, args):
            kwargs[n] = a
        super().__init__(**kwargs)

    @model_validator(mode="after")
    def _unique_ids(self) -> "AeroNavigation":
        ids = [w.id for w in self.waypoints if isinstance(w, Waypoint)]
        seen: set = set()
        dup = {i for i in ids if i in seen or seen.add(i)}  # linear: ids.count made 100k-item missions quadratic
        if dup:
            raise ValueError(f"waypoints: duplicate waypoint ids {sorted(dup)}")
        return self


class PriorityQueue(_Model):
    """Navigation data with a priority (paper: ``PriorityQueue(data, priority)``); lower number = higher priority.

    ``replace=True`` (for an analytics output stream): the first navigation it delivers aborts every queued
    mission (``clear_navigation``) before it is added, so the old mission never resumes (pattern 5, mission
    abort); without it a higher priority only preempts (pattern 4, the old mission resumes)."""

    data: Any
    priority: Annotated[int, Strict()] = Field(default=2, ge=0, le=1_000_000)
    replace: StrictBool = False

    def __init__(self, data: Any = None, priority: int = 2, **kwargs: Any) -> None:
        super().__init__(data=data, priority=priority, **kwargs)


class GeoPoint(_Model):
    """WGS-84 position: latitude/longitude in degrees, altitude in metres (ellipsoidal). Numbers only: a string
    (``"13.02"``) or a boolean is refused."""

    lat: Number = Field(ge=-90.0, le=90.0)
    lon: Number = Field(ge=-180.0, le=180.0)
    alt: Number = 0.0

    _chk = field_validator("lat", "lon", "alt")(_finite)


class Attitude(_Model):
    """Roll, pitch, yaw in degrees (yaw counter-clockwise from east, ENU)."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0


class Odometry(_Model):
    """A robot's state at time ``t`` (s): ENU position (m) from home, geodetic fix, ENU velocity (m/s),
    attitude (deg), battery percent (0-100) and voltage (V), armed and in-air flags."""

    robot_id: str
    t: float
    position: tuple[float, float, float]
    geodetic: GeoPoint
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude: Attitude = Field(default_factory=Attitude)
    battery_pct: float | None = Field(default=100.0, ge=0.0, le=100.0, description="None: unknown (a log without "
                                      "battery data)")
    battery_voltage: float = 0.0
    armed: bool = False
    in_air: bool = False


class CameraIntrinsics(_Model):
    """Pinhole intrinsics in pixels for a ``width`` x ``height`` image (OpenCV convention, origin top-left)."""

    width: int = Field(gt=0)
    height: int = Field(gt=0)
    fx: float = Field(gt=0)
    fy: float = Field(gt=0)
    cx: float
    cy: float

    @classmethod
    def from_hfov(cls, width: int, height: int, hfov_deg: float) -> "CameraIntrinsics":
        """Square-pixel intrinsics from a horizontal field of view in degrees (0 < hfov < 180)."""
        if not 0.0 < hfov_deg < 180.0:
            raise ValueError(f"hfov_deg must be within (0, 180) degrees, got {hfov_deg}")
        f = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        return cls(width=width, height=height, fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)


class FramePose(_Model):
    """Drone pose at capture: ENU position (m) and yaw (deg); the camera's pitch below horizon (deg, 90 = nadir)."""

    position: tuple[float, float, float]
    yaw: float = 0.0
    camera_pitch: float = 90.0


class FrameMeta(_Model):
    """Metadata travelling with every camera frame (the pixels travel separately as an ObjectRef)."""

    robot_id: str
    sensor_id: str
    seq: int
    capture_time: float  # sim time, s
    wall_time: float  # time.time() at capture, s; used for latency accounting
    pose: FramePose
    intrinsics: CameraIntrinsics
    #: a video stream's frame: when it arrived (run clock, s; capture_time is its capture), and the time the pose
    #: is of (s; the capture time when odometry brackets it). None for rendered and replayed frames
    arrival_time: float | None = None
    pose_time: float | None = None


class Detection(_Model):
    """One object detection: COCO ``class_id``/``class_name``, ``score`` in [0, 1], pixel box ``(x0, y0, x1, y1)``."""

    class_id: int
    class_name: str
    score: float = Field(ge=0.0, le=1.0)
    box: tuple[float, float, float, float]

    @property
    def center(self) -> tuple[float, float]:
        return ((self.box[0] + self.box[2]) / 2.0, (self.box[1] + self.box[3]) / 2.0)


COCO_CLASSES = (
    "person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "couch",
    "potted plant", "bed", "dining table", "toilet", "tv", "laptop", "mouse", "remote", "keyboard",
    "cell phone", "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors",
    "teddy bear", "hair drier", "toothbrush",
)
