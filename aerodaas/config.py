"""``environment.json``: the configuration of robots, sensors, compute resources and the simulated world.

Everything is validated with pydantic before any actor starts. :func:`load_environment_config` turns any
validation problem into :class:`ConfigError`, whose message names the JSON path of the field and the bad
value, e.g. ``robots.0.limits.max_speed: Input should be greater than 0 (got -1)``.
Relative file paths (imagery) are resolved against the environment file's folder, then
``$AERODAAS_DATA_DIR``.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from .geofence import GeofenceConfig
from .models import GeoPoint

DATA_DIR_ENV = "AERODAAS_DATA_DIR"


class ConfigError(ValueError):
    """A malformed environment file; the message names each bad field and its value."""


class _Cfg(BaseModel):
    """Every configuration section: unknown keys are refused (with a "did you mean" suggestion, see
    :func:`_format_errors`), numbers must be finite (no NaN/Infinity), and types are strict: ``"yes"`` or ``1``
    is not a boolean, ``"3"`` is not a number (JSON has real booleans and numbers)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


#: Documented physical bounds of the configuration (README "Configuration bounds"). Numbers outside them are
#: refused: they are typos or attacks, not vehicles (a 1e308 m/s speed limit disables the check it configures).
MAX_SPEED_MPS = 100.0  # fastest multirotors are ~ 60 m/s
MAX_ACCEL_MPS2 = 100.0
MAX_YAW_RATE_DPS = 3600.0
MAX_ALTITUDE_M = 10_000.0  # above home
HOME_ALT_RANGE_M = (-500.0, 9_000.0)  # AMSL: below the Dead Sea shore .. above Everest
MAX_CAMERA_PX = 8192  # per side
MAX_CAMERA_FPS = 240.0
MAX_RATE_HZ = 1000.0  # control, physics, odometry, stream rates
MAX_SPEEDUP = 1000.0
MAX_DURATION_S = 86_400.0  # timeouts and intervals: one day
MAX_BATTERY_WH = 100_000.0
MAX_POWER_W = 1_000_000.0


class Limits(_Cfg):
    """Flight-envelope limits of a robot: speeds in m/s, acceleration in m/s², yaw rate in deg/s,
    altitudes in metres above home."""

    max_speed: float = Field(default=2.0, gt=0, le=MAX_SPEED_MPS, description="horizontal speed limit, m/s")
    max_vertical_speed: float = Field(default=1.0, gt=0, le=MAX_SPEED_MPS, description="m/s")
    max_acceleration: float = Field(default=2.0, gt=0, le=MAX_ACCEL_MPS2, description="m/s^2")
    max_yaw_rate: float = Field(default=90.0, gt=0, le=MAX_YAW_RATE_DPS, description="deg/s")
    max_altitude: float = Field(default=120.0, gt=0, le=MAX_ALTITUDE_M, description="metres above home")


class BatteryConfig(_Cfg):
    """Battery model: energy drawn = (hover_power_w + speed_power_w_per_mps * |v|) * dt.
    Voltage is linear between ``voltage_empty`` and ``voltage_full`` in state of charge (a simple LiPo model)."""

    capacity_wh: float = Field(default=60.0, gt=0, le=MAX_BATTERY_WH)
    hover_power_w: float = Field(default=180.0, ge=0, le=MAX_POWER_W)
    speed_power_w_per_mps: float = Field(default=10.0, ge=0, le=MAX_POWER_W)
    voltage_full: float = Field(default=16.8, gt=0, le=1000)
    voltage_empty: float = Field(default=13.2, gt=0, le=1000)
    initial_pct: float = Field(default=100.0, ge=0, le=100)


class NoiseConfig(_Cfg):
    """Optional sensor noise (standard deviations): GPS position in metres, velocity in m/s."""

    gps_std_m: float = Field(default=0.0, ge=0, le=1000)
    velocity_std_mps: float = Field(default=0.0, ge=0, le=MAX_SPEED_MPS)
    seed: int = 0


class SafetyConfig(_Cfg):
    """Safety limits, enforced by :class:`aerodaas.safety.SafetyGate` before any command reaches the drone.

    Altitudes are metres above home; ``max_altitude``/``max_speed`` default to the robot's ``limits``.
    ``min_altitude`` applies to everything except take-off and landing. ``geofence`` holds inclusion/exclusion
    polygons and circles (lat/lon degrees, radius metres); ``geofence_plan`` names a QGroundControl ``.plan``
    whose ``geoFence`` is added to it. ``on_violation``: ``reject`` (default) refuses a violating command;
    ``clamp`` clamps altitude and speed into the limits (geofence breaches are always rejected).
    ``low_battery_rtl_pct``: below this battery percentage the drone returns to launch and lands, whatever the
    queue holds (the stat-stream shows RETURNING). ``critical_battery_pct``: below this it lands in place."""

    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    geofence_plan: str | None = None
    max_altitude: float | None = Field(default=None, gt=0, le=MAX_ALTITUDE_M, description="metres above home")
    min_altitude: float = Field(default=0.5, ge=0, le=MAX_ALTITUDE_M,
                                description="metres above home, except take-off/landing")
    max_speed: float | None = Field(default=None, gt=0, le=MAX_SPEED_MPS, description="m/s, horizontal")
    command_latency_s: float = Field(default=0.2, ge=0, le=10.0, description="worst-case delay (s) between the gate's "
                                     "check and the vehicle acting on a command (link + autopilot); the stopping "
                                     "envelope of every command includes it")
    on_violation: Literal["reject", "clamp"] = "reject"
    low_battery_rtl_pct: float = Field(default=20.0, ge=0, le=100)
    critical_battery_pct: float = Field(default=5.0, ge=0, le=100)

    @model_validator(mode="after")
    def _check(self) -> "SafetyConfig":
        if self.max_altitude is not None and self.min_altitude >= self.max_altitude:
            raise ValueError(f"min_altitude ({self.min_altitude}) must be below max_altitude ({self.max_altitude})")
        if self.critical_battery_pct > self.low_battery_rtl_pct:
            raise ValueError(f"critical_battery_pct ({self.critical_battery_pct}) must not exceed "
                             f"low_battery_rtl_pct ({self.low_battery_rtl_pct})")
        return self


#: where a camera's frames come from: the simulated world, the robot's backend (its own video stream, e.g. the
#: Tello's), or a recorded MCAP camera channel
CAMERA_SOURCES = ("sim", "backend", "mcap")
#: backends whose :meth:`~aerodaas.backends.base.VehicleBackend.camera_frame` gives frames
BACKENDS_WITH_CAMERA = ("tello",)


class SensorConfig(_Cfg):
    """A sensor. ``type``: ``camera`` (properties width, height in px, hfov_deg, fps, pitch_deg with 90 = nadir,
    jpeg_quality, source), ``odometry`` (rate_hz) or ``stat_stream``. ``buffer`` is the stream buffer length
    (frames kept for a slow consumer; older ones are dropped and counted).

    A camera's ``source`` is ``sim`` (default: rendered from the simulated world), ``backend`` (the robot's own
    video, e.g. a Tello's; needs such a backend) or ``mcap`` (replay a recording: ``mcap`` names the file,
    resolved like other files at load time, and ``topic`` its ``foxglove.CompressedImage`` channel, by default
    ``/<robot>/camera/<sensor id>`` as AeroDaaS records it)."""

    id: str = Field(min_length=1)
    type: Literal["camera", "odometry", "stat_stream"]
    properties: dict[str, Any] = Field(default_factory=dict)
    buffer: int = Field(default=1, ge=1)

    @model_validator(mode="after")
    def _check_props(self) -> "SensorConfig":
        p = self.properties
        spec = SENSOR_PROPERTIES.get(self.type, {})
        for k in p:
            if k not in spec:
                raise ValueError(f"properties.{k}: unknown {self.type} property{did_you_mean(k, spec)}; "
                                 f"known: {sorted(spec)}")
        for k, (kind, default, lo, hi, lo_open) in spec.items():
            if k not in p:
                if default is not None:
                    p[k] = default
                continue
            v = p[k]
            if kind == "str":
                if not isinstance(v, str) or not v:
                    raise ValueError(f"properties.{k} must be a non-empty string, got {v!r}")
                continue
            ok_type = isinstance(v, int) if kind == "int" else isinstance(v, (int, float))
            if isinstance(v, bool) or not ok_type or not math.isfinite(v) or v > hi or (v <= lo if lo_open else v < lo):
                what = "an integer" if kind == "int" else "a finite number"
                rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
                raise ValueError(f"properties.{k} must be {what} within {rng}, got {v!r}")
        if self.type == "camera":
            src = p["source"]
            if src not in CAMERA_SOURCES:
                raise ValueError(f"properties.source must be one of {list(CAMERA_SOURCES)}, got {src!r}")
            if p["hfov_deg"] >= 180:
                raise ValueError(f"properties.hfov_deg must be within (0, 180), got {p['hfov_deg']!r}")
            if src == "mcap":
                if not p.get("mcap"):
                    raise ValueError(f"properties.mcap must name the MCAP recording to replay when properties.source "
                                     f"is 'mcap', got {p.get('mcap')!r}")
                if "topic" in p and not p["topic"].startswith("/"):
                    raise ValueError(f"properties.topic must be an MCAP topic starting with '/', got {p['topic']!r}")
            else:
                for k in ("mcap", "topic"):
                    if k in p:
                        raise ValueError(f"properties.{k} is only used with properties.source 'mcap', "
                                         f"but source is {src!r}")
        return self


#: the properties of each sensor type: name -> (kind, default, low, high, low bound exclusive). Camera sizes are
#: pixels, fps frames/s, angles degrees (pitch 90 = nadir), rates Hz. Unknown properties are refused.
SENSOR_PROPERTIES: dict[str, dict[str, tuple]] = {
    "camera": {"width": ("int", 640, 1, MAX_CAMERA_PX, False), "height": ("int", 480, 1, MAX_CAMERA_PX, False),
               "hfov_deg": ("float", 78.0, 0.0, 180.0, True), "fps": ("float", 15.0, 0.0, MAX_CAMERA_FPS, True),
               "pitch_deg": ("float", 90.0, 0.0, 90.0, True), "jpeg_quality": ("int", 80, 1, 100, False),
               "source": ("str", "sim", 0, 0, False), "mcap": ("str", None, 0, 0, False),
               "topic": ("str", None, 0, 0, False)},
    "odometry": {"rate_hz": ("float", 10.0, 0.0, MAX_RATE_HZ, True)},
    "stat_stream": {},
}


def did_you_mean(word: str, choices) -> str:
    """``" (did you mean 'width'?)"`` for the closest of ``choices`` to a misspelt ``word`` (difflib), else ``""``."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class MavlinkConfig(_Cfg):
    """A MAVLink autopilot (ArduPilot or PX4) reached through pymavlink.

    ``connection`` is a pymavlink connection string (``udpin:0.0.0.0:14550``, ``udpout:HOST:PORT``,
    ``tcp:HOST:PORT``, ``/dev/ttyACM0`` with ``baud``). ``autopilot``: ``auto`` identifies it from its HEARTBEAT
    (MAV_AUTOPILOT_ARDUPILOTMEGA / MAV_AUTOPILOT_PX4). We speak as ``source_system``/``source_component`` (a GCS).
    The link is lost after ``heartbeat_timeout_s`` seconds without a HEARTBEAT (wall seconds, and as many of the
    vehicle's own clock while its timestamped telemetry still arrives: a simulator may run slower than real time,
    and its heartbeats with it). Every COMMAND_LONG waits
    ``command_timeout_s`` seconds for its COMMAND_ACK and is re-sent up to ``command_retries`` times.
    ``stream_rate_hz`` is the rate requested for telemetry (MAV_CMD_SET_MESSAGE_INTERVAL).
    ``use_autopilot_mission``: fly the robot's pre-planned waypoints (in the order its trajectory scheduler gave
    them) as an autopilot mission instead of streaming position targets: NAV_TAKEOFF to ``takeoff_altitude``, one
    NAV_WAYPOINT per waypoint (hold = ``hover_duration``), then NAV_LAND at the last waypoint (or
    NAV_RETURN_TO_LAUNCH when the navigation ends with an ``rtl`` action), uploaded with the MISSION_ITEM_INT
    protocol and flown in ArduPilot AUTO / PX4 AUTO.MISSION; MISSION_CURRENT / MISSION_ITEM_REACHED drive the
    stat-stream. The autopilot's own acceptance radius (ArduPilot WPNAV_RADIUS, PX4 NAV_ACC_RAD or the item's)
    decides "reached", not ``acceptance_radius``. Missions it cannot express are refused before any actor
    starts (ConfigError naming this field): navigation from analytics or the HITL API, velocity commands,
    time-driven navigation, no waypoints.
    ``arm_timeout_s``: how long (wall seconds) ``arm()`` waits for the vehicle to report itself armable (3-D GPS
    fix, pre-arm and AHRS health bits of SYS_STATUS) before it asks anyway, so that a refusal carries the
    autopilot's reason. ``setpoint_rate_hz``: rate, in the vehicle's own time, at which the active position or
    velocity target is re-sent (PX4 OFFBOARD needs more than 2 Hz; ArduPilot stops a velocity target after 3 s)."""

    connection: str = Field(default="tcp:127.0.0.1:5760", min_length=1)
    baud: int = Field(default=57600, gt=0, le=10_000_000)
    autopilot: Literal["auto", "ardupilot", "px4"] = "auto"
    source_system: int = Field(default=255, ge=1, le=255)
    source_component: int = Field(default=190, ge=0, le=255)
    target_system: int | None = Field(default=None, ge=1, le=255)
    connect_timeout_s: float = Field(default=30.0, gt=0, le=MAX_DURATION_S)
    heartbeat_timeout_s: float = Field(default=3.0, gt=0, le=MAX_DURATION_S)
    command_timeout_s: float = Field(default=1.5, gt=0, le=MAX_DURATION_S)
    command_retries: int = Field(default=3, ge=0, le=100)
    stream_rate_hz: float = Field(default=10.0, gt=0, le=MAX_RATE_HZ)
    use_autopilot_mission: bool = False
    arm_timeout_s: float = Field(default=30.0, gt=0, le=MAX_DURATION_S)
    setpoint_rate_hz: float = Field(default=10.0, gt=2.0, le=MAX_RATE_HZ)
    #: set the vehicle's own speed limits from the robot's ``limits`` on connect (ArduCopter WPNAV_SPEED*, PX4
    #: MPC_XY_VEL_MAX/MPC_XY_CRUISE/MPC_Z_VEL_MAX_*), read back to verify; ``restore_params``: put the user's
    #: values back when the backend closes
    set_speed_limits: bool = True
    restore_params: bool = True
    #: what closing the backend does with a vehicle still in the air (run timeout, error, Ctrl-C): ``land`` here
    #: or ``rtl``, waiting up to ``safe_end_timeout_s`` vehicle seconds for it to land and disarm
    on_close: Literal["land", "rtl"] = "land"
    safe_end_timeout_s: float = Field(default=120.0, gt=0, le=MAX_DURATION_S)


class TelloConfig(_Cfg):
    """A DJI Tello (SDK 2.0 over UDP): commands to ``host:command_port`` (replies on the same socket), state
    packets on local ``state_port``, H.264 video on local ``video_port`` (both bound on ``bind_host``). A command
    without reply within ``command_timeout_s`` seconds is retried ``command_retries`` times; a keep-alive is sent
    every ``keepalive_s`` seconds (the Tello lands after 15 s without a command).

    The Tello has no compass: its yaw is relative to where it pointed at power-on. ``initial_heading_deg`` is the
    compass heading (degrees clockwise from north) the Tello faces when :meth:`connect` runs (mission start); the
    yaw reported then is taken as that heading. ``velocity_frame`` says how to read the state packet's
    ``vgx``/``vgy`` (the SDK guide does not say): ``yaw_zero`` (default: x along the heading of yaw 0, y 90 deg
    clockwise of it, z down) or ``body`` (x forward, y right, z down). Motion commands (takeoff, go, land) are
    answered only when the Tello has finished them; a motion call returns once the command has not been refused
    within ``accept_window_s`` seconds."""

    host: str = "192.168.10.1"
    command_port: int = Field(default=8889, ge=1, le=65535)
    local_command_port: int = Field(default=0, ge=0, le=65535, description="0: any free port")
    state_port: int = Field(default=8890, ge=0, le=65535)
    video_port: int = Field(default=11111, ge=0, le=65535)
    video: bool = True
    command_timeout_s: float = Field(default=7.0, gt=0, le=MAX_DURATION_S)
    command_retries: int = Field(default=2, ge=0, le=100)
    keepalive_s: float = Field(default=5.0, gt=0, le=MAX_DURATION_S, lt=15)
    state_timeout_s: float = Field(default=3.0, gt=0, le=MAX_DURATION_S, description="link lost after this long without a state packet")
    bind_host: str = Field(default="0.0.0.0", description="local address the state and video sockets bind to")
    initial_heading_deg: float = Field(default=0.0, ge=-360, le=360, description="compass heading at connect(), deg")
    velocity_frame: Literal["yaw_zero", "body"] = "yaw_zero"
    accept_window_s: float = Field(default=0.3, ge=0, le=MAX_DURATION_S, description="wait this long for a motion command's refusal")


class ReplayConfig(_Cfg):
    """Replay a recorded flight as odometry, battery and mode/state streams: ``log`` is a MAVLink telemetry log
    (``.tlog``, as QGroundControl, MAVProxy or Mission Planner record it) or a PX4 flight log (``.ulg``, as the
    autopilot writes it to its SD card); ``rate`` is the replay speed (1 = real time)."""

    log: str = Field(min_length=1)
    rate: float = Field(default=1.0, gt=0, le=MAX_SPEEDUP)


class RobotConfig(_Cfg):
    """A robot (drone). ``backend`` selects the driver: ``sim`` (the embedded simulator), ``mavlink`` (ArduPilot or
    PX4, settings in ``mavlink``), ``tello`` (DJI Tello, settings in ``tello``) or ``replay`` (a recorded flight,
    settings in ``replay``; not navigable)."""

    id: str = Field(min_length=1)
    backend: Literal["sim", "mavlink", "tello", "replay"] = "sim"
    mavlink: MavlinkConfig | None = None
    tello: TelloConfig | None = None
    replay: ReplayConfig | None = None
    home: GeoPoint = Field(default_factory=lambda: GeoPoint(lat=47.3977, lon=8.5456, alt=488.0))
    limits: Limits = Field(default_factory=Limits)
    battery: BatteryConfig = Field(default_factory=BatteryConfig)
    noise: NoiseConfig = Field(default_factory=NoiseConfig)
    safety: SafetyConfig = Field(default_factory=SafetyConfig)
    takeoff_altitude: float = Field(default=1.5, gt=0, le=MAX_ALTITUDE_M, description="metres above home; within "
                                    "[safety.min_altitude, max_altitude]")
    control_rate_hz: float = Field(default=10.0, gt=0, le=MAX_RATE_HZ)
    idle_land_s: float = Field(default=10.0, gt=0, le=MAX_DURATION_S, description="land after this many seconds (sim time) with "
                               "nothing queued, once some navigation has been flown")
    sensors: list[SensorConfig] = Field(default_factory=list)
    compute: str | None = Field(default=None, description="id of the edge compute resource this robot flies from "
                                "(its drone actor runs there); default: the environment's first edge compute")
    max_waypoints_per_request: int = Field(default=1000, ge=1, le=100_000, description="bounded work: items in one "
                                           "navigation added while flying (HITL request, analytics output)")
    max_queued_items: int = Field(default=5000, ge=1, le=1_000_000, description="bounded work: items queued in "
                                  "all missions of this robot; more are refused (HTTP 422 / navigation_refused)")

    @model_validator(mode="after")
    def _unique_sensors(self) -> "RobotConfig":
        ids = [s.id for s in self.sensors]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"sensors: duplicate sensor ids {dup}")
        if not any(s.type == "stat_stream" for s in self.sensors):
            self.sensors.append(SensorConfig(id="stat", type="stat_stream"))
        if self.backend == "mavlink" and self.mavlink is None:
            self.mavlink = MavlinkConfig()
        if self.backend == "tello" and self.tello is None:
            self.tello = TelloConfig()
        if self.mavlink is not None and self.mavlink.use_autopilot_mission and self.backend != "mavlink":
            raise ValueError(f"mavlink.use_autopilot_mission: true needs backend 'mavlink' (an autopilot that flies "
                             f"uploaded missions), but backend is {self.backend!r}")
        if self.backend == "replay" and self.replay is None:
            raise ValueError("replay: backend 'replay' needs a 'replay' section naming the log to play")
        lo, hi = HOME_ALT_RANGE_M
        if not lo <= self.home.alt <= hi:
            raise ValueError(f"home.alt: {self.home.alt!r} m AMSL is outside [{lo:g}, {hi:g}] m")
        max_alt = self.safety.max_altitude if self.safety.max_altitude is not None else self.limits.max_altitude
        if self.takeoff_altitude > max_alt:
            which = "safety.max_altitude" if self.safety.max_altitude is not None else "limits.max_altitude"
            raise ValueError(f"takeoff_altitude: {self.takeoff_altitude:g} m is above {which} ({max_alt:g} m); the "
                             f"take-off target passes the same safety gate as every command")
        if self.takeoff_altitude < self.safety.min_altitude:
            raise ValueError(f"takeoff_altitude: {self.takeoff_altitude:g} m is below safety.min_altitude "
                             f"({self.safety.min_altitude:g} m); the drone would hover below the floor it must keep")
        for j, s in enumerate(self.sensors):
            if s.type == "camera" and s.properties.get("source") == "backend" and self.backend not in BACKENDS_WITH_CAMERA:
                raise ValueError(f"sensors.{j}.properties.source: 'backend' needs a backend with its own camera "
                                 f"stream ({list(BACKENDS_WITH_CAMERA)}), but backend is {self.backend!r}")
        return self


_LABEL_KEY = re.compile(r"^([a-z0-9]([-a-z0-9.]*[a-z0-9])?/)?[A-Za-z0-9]([-A-Za-z0-9_.]{0,61}[A-Za-z0-9])?$")
_LABEL_VALUE = re.compile(r"^([A-Za-z0-9]([-A-Za-z0-9_.]{0,61}[A-Za-z0-9])?)?$")


class ComputeConfig(_Cfg):
    """A compute resource, and the place its actors run: ``tier`` ``edge`` or ``cloud``; ``labels`` are Ray node
    labels beyond ``tier`` that a node must carry to run this resource's actors (e.g.
    ``{"aerodaas/site": "field-2"}``; ``ray start --labels``), matched with Ray's ``label_selector``;
    ``properties`` e.g. cpus, memory_gb, accelerators (informative). Label keys and values follow Ray's (Kubernetes')
    label syntax: ``[prefix/]name`` of at most 63 characters, alphanumerics, ``-``, ``_``, ``.``."""

    id: str = Field(min_length=1)
    tier: Literal["edge", "cloud"]
    labels: dict[str, str] = Field(default_factory=dict)
    properties: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _labels(self) -> "ComputeConfig":
        for k, v in self.labels.items():
            if k == "tier":
                raise ValueError(f"labels.tier: the tier is the compute resource's 'tier' field ({self.tier!r}); "
                                 f"do not repeat it as a label")
            if not _LABEL_KEY.match(k):
                raise ValueError(f"labels: {k!r} is not a Ray node label key ([prefix/]name, alphanumerics, '-', '_', "
                                 f"'.', at most 63 characters)")
            if not isinstance(v, str) or not _LABEL_VALUE.match(v):
                raise ValueError(f"labels.{k}: {v!r} is not a Ray node label value (alphanumerics, '-', '_', '.', "
                                 f"at most 63 characters)")
        return self


class GroundConfig(_Cfg):
    """The textured ground plane. With ``image`` (any PNG/JPEG) and ``metres_per_pixel``, the image is laid on
    the ground with its top edge north; ``home_px`` is the pixel (x, y) under the home position (default:
    image centre). Without ``image``, a procedural ground is generated from ``seed``."""

    image: str | None = None
    metres_per_pixel: float = Field(default=0.05, gt=0, le=100_000)
    home_px: Annotated[tuple[float, float], Strict(False)] | None = None
    seed: int = 0
    size_m: float = Field(default=120.0, gt=0, le=100_000, description="procedural ground side length, metres")


class TargetPathPoint(_Cfg):
    """Target position (ENU metres from the home of the first robot) at sim time ``t`` seconds."""

    t: float = Field(ge=0, le=MAX_DURATION_S * 365)
    x: float = Field(ge=-100_000, le=100_000)
    y: float = Field(ge=-100_000, le=100_000)

    @field_validator("t", "x", "y")
    @classmethod
    def _finite(cls, v: float, info) -> float:
        if not math.isfinite(v):
            raise ValueError(f"{info.field_name} must be finite, got {v!r}")
        return v


class TargetConfig(_Cfg):
    """A moving ground target drawn from a crop of a real image. ``crop`` is (x0, y0, x1, y1) in pixels of
    ``image``; the crop's long axis is drawn ``length_m`` long, facing along its path (the crop's front is
    its right edge, i.e. the crop image points east). The target exists between the first and last ``path``
    times; it is linearly interpolated in between."""

    id: str = Field(min_length=1)
    class_name: str = "car"
    image: str
    crop: Annotated[tuple[int, int, int, int], Strict(False)]
    length_m: float = Field(default=4.3, gt=0, le=100_000)
    path: list[TargetPathPoint] = Field(min_length=2)

    @model_validator(mode="after")
    def _check(self) -> "TargetConfig":
        x0, y0, x1, y1 = self.crop
        if x1 <= x0 or y1 <= y0 or min(self.crop) < 0:
            raise ValueError(f"crop must be (x0, y0, x1, y1) with x1 > x0 >= 0 and y1 > y0 >= 0, got {self.crop}")
        ts = [p.t for p in self.path]
        if any(b <= a for a, b in zip(ts, ts[1:])):
            raise ValueError(f"path times must be strictly increasing, got {ts}")
        return self


class WorldConfig(_Cfg):
    ground: GroundConfig = Field(default_factory=GroundConfig)
    targets: list[TargetConfig] = Field(default_factory=list)


class SimulationConfig(_Cfg):
    """Simulation clock: ``speedup`` x real time; ``lockstep`` makes sim time wait for analytics to consume each
    frame; ``physics_hz`` is the integration rate."""

    speedup: float = Field(default=1.0, gt=0, le=MAX_SPEEDUP)
    lockstep: bool = False
    physics_hz: float = Field(default=50.0, gt=0, le=MAX_RATE_HZ)


class HitlConfig(_Cfg):
    """Human-in-the-loop HTTP API (see :mod:`aerodaas.hitl`). Loopback-only by default; ``token`` is the
    bearer token (generated at start and printed once when not given). ``port`` 0 picks a free port."""

    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = Field(default=8470, ge=0, le=65535)
    token: str | None = Field(default=None, min_length=16, max_length=256)
    docs: bool = Field(default=False, description="serve /docs and /openapi.json (behind the bearer token)")


class AnalyticsQosConfig(_Cfg):
    """Quality of service of one scheduled analytics, in the terms of the Ocularone workload (Raj et al., FGCS 2025):
    a result within ``deadline_ms`` of the frame's capture earns ``benefit``; running it costs ``edge_cost`` on the
    edge or ``cloud_cost`` on the cloud, charged whether or not it met the deadline. ``edge_ms`` / ``cloud_ms`` are
    the expected execution times (ms; the cloud's includes the network round trip) the scheduler plans with."""

    deadline_ms: float = Field(gt=0, le=1e7, description="relative deadline from capture, ms")
    edge_ms: float = Field(gt=0, le=1e7, description="expected execution time on the edge, ms")
    cloud_ms: float = Field(gt=0, le=1e7, description="expected round trip on the cloud, ms")
    benefit: float = Field(ge=0, le=1e9)
    edge_cost: float = Field(default=0.0, ge=0, le=1e9)
    cloud_cost: float = Field(default=0.0, ge=0, le=1e9)


class AnalyticsSchedulerConfig(_Cfg):
    """The analytics scheduler (the paper's ``setAnalyticsScheduler``): per frame, it places each *scheduled*
    analytics on the edge, on the cloud, or drops it with a reason.

    ``name``: a registered scheduler (``EDGE_FIFO`` ... ``DEMS``, ``DEMS-A``, ``GEMS``, ``GAINPLAN``, or a plug-in
    registered with :func:`aerodaas.schedulers.analytics_base.register_analytics_scheduler`); ``default`` runs
    every analytics where it is deployed. ``models``: analytics name -> its QoS, inline, or the name of a model
    of ``workload`` under ``load`` (e.g. ``"HV"`` of ``workloads/ocularone_lambda.json``). Analytics not named
    here run where they are deployed. ``cloud_executors``: cloud executor actors (tier=cloud nodes, else this
    node). ``network``: emulated extra cloud latency (:class:`aerodaas.schedulers.dispatch.emulation.NetworkModel` specs, e.g.
    ``"const:40"`` or ``"normal:60,15"``; ``"none"`` for a real network)."""

    name: str = "default"
    models: dict[str, AnalyticsQosConfig | str] = Field(default_factory=dict)
    workload: str | None = Field(default=None, description="workload JSON (Ocularone format) for named models")
    load: str | None = Field(default=None, description="load of the workload: LIGHT, MEDIUM, HEAVY")
    cloud_executors: int = Field(default=1, ge=1, le=64)
    network: list[str] = Field(default_factory=lambda: ["none"])
    jpeg_quality: int = Field(default=90, ge=10, le=100, description="JPEG quality of frames sent to the cloud")

    @field_validator("network", mode="before")
    @classmethod
    def _one_or_many(cls, v: Any) -> Any:
        return [v] if isinstance(v, str) else v

    @model_validator(mode="after")
    def _check(self) -> "AnalyticsSchedulerConfig":
        if self.name == "default":
            return self
        from aerodaas.schedulers.analytics_base import analytics_scheduler_names

        names = analytics_scheduler_names()
        if self.name not in names:
            raise ValueError(f"name: unknown analytics scheduler {self.name!r}; available: ['default', {', '.join(map(repr, names))}]")
        if not self.models:
            raise ValueError(f"models: the {self.name} scheduler needs the QoS of at least one analytics "
                             f"(analytics name -> {{deadline_ms, edge_ms, cloud_ms, benefit, edge_cost, cloud_cost}})")
        named = sorted(k for k, v in self.models.items() if isinstance(v, str))
        if named and (self.workload is None or self.load is None):
            raise ValueError(f"models: {named} name workload models, which needs 'workload' and 'load'")
        from aerodaas.schedulers.dispatch.emulation import NetworkModel

        NetworkModel.parse(self.network)  # ValueError naming the bad spec
        return self

    def resolved_workload(self, base: "EnvironmentConfig | None" = None):
        """The QoS of every scheduled analytics as a :class:`aerodaas.schedulers.analytics_base.Workload` keyed by
        analytics name (named models read from ``workload``, resolved like every file of the environment).
        Raises ConfigError naming the field for a missing file, load or model."""
        from aerodaas.schedulers.analytics_base import ModelProfile, Workload

        data = None
        if any(isinstance(v, str) for v in self.models.values()):
            path = base.resolve_path(self.workload, "analytics_scheduler.workload") if base is not None \
                else Path(self.workload)
            try:
                data = json.loads(Path(path).read_text())
            except (OSError, json.JSONDecodeError) as e:
                raise ConfigError(f"analytics_scheduler.workload: cannot read {str(path)!r}: {e}") from None
        models = {}
        for name, v in self.models.items():
            if isinstance(v, str):
                try:
                    p = Workload.from_dict(data, self.load)[v]
                except (ValueError, KeyError) as e:
                    raise ConfigError(f"analytics_scheduler.models.{name}: {str(e).strip(chr(34))}") from None
                models[name] = ModelProfile(name, p.edge_ms, p.cloud_ms, p.benefit, p.edge_cost, p.cloud_cost,
                                            p.deadline_ms)
            else:
                models[name] = ModelProfile(name, v.edge_ms, v.cloud_ms, v.benefit, v.edge_cost, v.cloud_cost,
                                            v.deadline_ms)
        return Workload(self.load or "custom", models)


class EnvironmentConfig(_Cfg):
    """Root of ``environment.json``. ``aerodaas schema`` prints its JSON Schema."""

    name: str = "environment"
    robots: list[RobotConfig] = Field(min_length=1)
    env_sensors: list[SensorConfig] = Field(default_factory=list)
    compute: list[ComputeConfig] = Field(default_factory=lambda: [ComputeConfig(id="edge", tier="edge")])
    world: WorldConfig = Field(default_factory=WorldConfig)
    simulation: SimulationConfig = Field(default_factory=SimulationConfig)
    hitl: HitlConfig = Field(default_factory=HitlConfig)
    analytics_scheduler: AnalyticsSchedulerConfig = Field(default_factory=AnalyticsSchedulerConfig)
    drones_per_actor: int = Field(default=1, ge=1, le=256, description="drones sharing one drone actor (one process); "
                                  "1: an actor per drone; more for memory-bound fleets")
    actor_max_restarts: int = Field(default=1, ge=0, le=100, description="Ray max_restarts of every drone, analytics "
                                    "and dispatcher actor of a run (the recorder is never restarted)")
    actor_restart_timeout_s: float = Field(default=60.0, gt=0, le=3600, description="how long the driver waits for "
                                           "a dead drone actor to come back before its drones end as 'lost', s")
    base_dir: str | None = Field(default=None, description="set by the loader: folder of the environment file")

    @model_validator(mode="after")
    def _unique(self) -> "EnvironmentConfig":
        for name, items in (("robots", self.robots), ("compute", self.compute), ("env_sensors", self.env_sensors),
                            ("world.targets", self.world.targets)):
            ids = [i.id for i in items]
            dup = sorted({i for i in ids if ids.count(i) > 1})
            if dup:
                raise ValueError(f"{name}: duplicate ids {dup}")
        edges = [c.id for c in self.compute if c.tier == "edge"]
        for j, r in enumerate(self.robots):
            if r.compute is not None and r.compute not in edges:
                raise ValueError(f"robots.{j}.compute: {r.compute!r} is not an edge compute resource of this "
                                 f"environment (edge: {edges})")
        for j, s in enumerate(self.env_sensors):
            src = s.properties.get("source") if s.type == "camera" else None
            if src == "backend":
                raise ValueError(f"env_sensors.{j}.properties.source: 'backend' is for a robot's camera; an "
                                 f"environment camera has no backend (use 'sim' or 'mcap')")
            if src == "mcap" and "topic" not in s.properties:
                raise ValueError(f"env_sensors.{j}.properties.topic: an environment camera replayed from an MCAP "
                                 f"recording needs the topic to read")
        return self

    def resolve_path(self, rel: str, field: str) -> Path:
        """Resolve a file named in the config: absolute, relative to the env file, or under $AERODAAS_DATA_DIR.

        Raises ConfigError naming ``field`` and the search locations when it is not found."""
        p = Path(os.path.expanduser(rel))
        cands = [p] if p.is_absolute() else []
        if not p.is_absolute():
            if self.base_dir:
                cands.append(Path(self.base_dir) / p)
            if os.environ.get(DATA_DIR_ENV):
                cands.append(Path(os.environ[DATA_DIR_ENV]) / p)
            cands.append(Path.cwd() / p)
        for c in cands:
            if c.is_file():
                return c.resolve()
        raise ConfigError(f"{field}: file {rel!r} not found (looked in: {', '.join(str(c) for c in cands)}); "
                          f"set {DATA_DIR_ENV} to the folder that holds it, or give an absolute path")


def _format_errors(err: ValidationError, source: str) -> str:
    lines = [f"invalid environment configuration in {source}:"]
    for e in err.errors():
        loc = ".".join(str(x) for x in e["loc"]) or "(root)"
        if e["type"] == "extra_forbidden" and e["loc"]:
            known = _fields_at(EnvironmentConfig, e["loc"][:-1])
            e["msg"] = f"unknown key{did_you_mean(e['loc'][-1], known)}" + (f"; known: {sorted(known)}" if known else "")
        val = e.get("input")
        sval = json.dumps(val, default=str) if not isinstance(val, dict) else "{...}"
        if len(sval) > 80:
            sval = sval[:77] + "..."
        lines.append(f"  {loc}: {e['msg']} (got {sval})")
    return "\n".join(lines)


def _fields_at(model: type, loc: tuple) -> list[str]:
    """The field names of the pydantic model reached from ``model`` along an error location (list indices and dict
    keys skipped); [] when the path does not end at a model."""
    import typing

    def models_in(tp) -> list[type]:
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            return [tp]
        return [m for a in typing.get_args(tp) for m in models_in(a)]

    cur: list[type] = [model]
    for part in loc:
        if isinstance(part, int) or not cur:
            continue
        nxt = []
        for m in cur:
            f = m.model_fields.get(str(part))
            if f is not None:
                nxt += models_in(f.annotation)
        if not nxt and any(str(part) not in m.model_fields for m in cur):
            continue  # a dict key (e.g. analytics_scheduler.models.<name>)
        cur = nxt
    return sorted({k for m in cur for k in m.model_fields if k != "base_dir"})


def parse_environment_config(data: dict[str, Any], source: str = "<dict>", base_dir: str | None = None) -> EnvironmentConfig:
    """Validate a parsed ``environment.json`` dict. Raises ConfigError naming each bad field and value."""
    if not isinstance(data, dict):
        raise ConfigError(f"invalid environment configuration in {source}: the top level must be a JSON object")
    try:
        cfg = EnvironmentConfig.model_validate(data)
    except ValidationError as e:
        raise ConfigError(_format_errors(e, source)) from None
    cfg.base_dir = base_dir
    # resolve referenced files now, so a missing image fails before any actor starts
    if cfg.world.ground.image:
        cfg.world.ground.image = str(cfg.resolve_path(cfg.world.ground.image, "world.ground.image"))
        _image_size(cfg.world.ground.image, "world.ground.image")
    for i, t in enumerate(cfg.world.targets):
        t.image = str(cfg.resolve_path(t.image, f"world.targets.{i}.image"))
        w, h = _image_size(t.image, f"world.targets.{i}.image")
        if t.crop[2] > w or t.crop[3] > h:
            raise ConfigError(f"world.targets.{i}.crop: {list(t.crop)} reaches outside its image {t.image!r} "
                              f"({w} x {h} px); x1 must be <= {w} and y1 <= {h}")
    cameras = [(f"robots.{i}.sensors.{j}", r.id, s) for i, r in enumerate(cfg.robots) for j, s in enumerate(r.sensors)]
    cameras += [(f"env_sensors.{j}", None, s) for j, s in enumerate(cfg.env_sensors)]
    for where, robot_id, s in cameras:
        if s.type == "camera" and s.properties.get("source") == "mcap":
            s.properties["mcap"] = str(cfg.resolve_path(s.properties["mcap"], f"{where}.properties.mcap"))
            s.properties.setdefault("topic", f"/{robot_id}/camera/{s.id}")
    for i, r in enumerate(cfg.robots):
        if r.replay is not None:
            r.replay.log = str(cfg.resolve_path(r.replay.log, f"robots.{i}.replay.log"))
            from .backends.base import BackendError
            from .backends.replay import check_log

            try:
                check_log(r.replay.log)
            except BackendError as e:
                raise ConfigError(f"robots.{i}.replay.log: {e}") from None
        if r.safety.geofence_plan:
            field = f"robots.{i}.safety.geofence_plan"
            path = cfg.resolve_path(r.safety.geofence_plan, field)
            from .missionfile import MissionFileError, load_mission

            try:
                fence = load_mission(path).geofence
            except (MissionFileError, OSError) as e:
                raise ConfigError(f"{field}: {e}") from None
            r.safety.geofence = GeofenceConfig(polygons=[*r.safety.geofence.polygons, *fence.polygons],
                                               circles=[*r.safety.geofence.circles, *fence.circles])
            r.safety.geofence_plan = str(path)
    for i, r in enumerate(cfg.robots):
        from .geofence import Geofence

        try:
            why = Geofence(r.safety.geofence, r.home).check_point(0.0, 0.0)
        except ValueError as e:
            raise ConfigError(f"robots.{i}.safety.geofence: {e}") from None
        if why is not None:
            raise ConfigError(f"robots.{i}.safety.geofence: the home position ({r.home.lat}, {r.home.lon}) is {why}; "
                              f"the drone takes off there, so the fence must allow it")
    sched = cfg.analytics_scheduler
    if sched.name != "default":
        if sched.workload is not None and any(isinstance(v, str) for v in sched.models.values()):
            sched.workload = str(cfg.resolve_path(sched.workload, "analytics_scheduler.workload"))
        sched.resolved_workload(cfg)  # a missing load or model fails here, before any actor starts
    return cfg


def _image_size(path: str, field: str) -> tuple[int, int]:
    """(width, height) in pixels of an image file, read with OpenCV; ConfigError naming ``field`` if unreadable."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ConfigError(f"{field}: {str(path)!r} is not an image OpenCV can read (PNG, JPEG, ...)")
    return int(img.shape[1]), int(img.shape[0])


def load_environment_config(path: str | os.PathLike) -> EnvironmentConfig:
    """Read and validate an environment file. Raises ConfigError (missing file, bad JSON, bad fields)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"environment file {str(p)!r} not found")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise ConfigError(f"environment file {p}: invalid JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    return parse_environment_config(data, source=str(p), base_dir=str(p.resolve().parent))


def json_schema() -> dict[str, Any]:
    """The JSON Schema of ``environment.json``."""
    return EnvironmentConfig.model_json_schema()
