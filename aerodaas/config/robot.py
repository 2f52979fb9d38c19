"""A robot's configuration (``robots[]`` of ``environment.json``): its limits (m/s, metres, degrees/s), battery,
sensor noise, safety rules, sensors, backend (the simulator, a MAVLink autopilot, a Tello, a replayed log) and the
backend's own settings."""
from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, ValidationError, field_validator, model_validator

from aerodaas.navigation.geofence import GeofenceConfig
from aerodaas.model.types import MAX_LOCAL_M, GeoPoint
from aerodaas.model.ids import Identifier, RobotId, check_topic_name, check_unique
from aerodaas.plugins.builtin_sensors import CAMERA_SOURCES, STREAM_PROPERTIES, StatStreamSensor  # noqa: F401
from aerodaas.plugins.sensor import SensorDelivery
from aerodaas.config.base import (DEFAULT_MAX_DISTANCE_M, HOME_ALT_RANGE_M, MAX_ACCEL_MPS2, MAX_ALTITUDE_M, MAX_BATTERY_WH, MAX_CAMERA_FPS, MAX_CAMERA_PX,
                   MAX_DURATION_S, MAX_POWER_W, MAX_RATE_HZ, MAX_SPEEDUP, MAX_SPEED_MPS, MAX_YAW_RATE_DPS, _Cfg,
                   did_you_mean)


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
    seed: int = Field(default=0, ge=0, le=2**32 - 1)


class SafetyConfig(_Cfg):
    """Safety limits, enforced by :class:`aerodaas.navigation.safety.SafetyGate` before any command reaches the drone.

    Altitudes are metres above home; ``max_altitude``/``max_speed`` default to the robot's ``limits``.
    ``min_altitude`` applies to everything except take-off and landing. ``geofence`` holds inclusion/exclusion
    polygons and circles (lat/lon degrees, radius metres); ``geofence_plan`` names a QGroundControl ``.plan``
    whose ``geoFence`` is added to it. ``on_violation``: ``reject`` (default) refuses a violating command;
    ``clamp`` clamps altitude and speed into the limits (geofence breaches are always rejected).
    ``max_distance`` (metres, default 10 km, at most 100 km) bounds the horizontal distance from home of every
    waypoint and of every velocity command's predicted path: a mistyped absolute waypoint thousands of kilometres
    away is refused, not flown until the battery ends. ``low_battery_rtl_pct``: below this battery percentage the
    drone returns to launch and lands, whatever the queue holds (the stat-stream shows RETURNING).
    ``critical_battery_pct``: below this it lands in place."""

    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    geofence_plan: str | None = None
    max_altitude: float | None = Field(default=None, gt=0, le=MAX_ALTITUDE_M, description="metres above home")
    min_altitude: float = Field(default=0.5, ge=0, le=MAX_ALTITUDE_M,
                                description="metres above home, except take-off/landing")
    max_speed: float | None = Field(default=None, gt=0, le=MAX_SPEED_MPS, description="m/s, horizontal")
    max_distance: float = Field(default=DEFAULT_MAX_DISTANCE_M, gt=0, le=MAX_LOCAL_M,
                                description="metres horizontally from home: farther waypoints, and velocity commands "
                                "that could carry the vehicle farther, are refused (never clamped)")
    command_latency_s: float = Field(default=0.2, ge=0, le=10.0, description="worst-case delay (s) between the gate's "
                                     "check and the vehicle acting on a command (link + autopilot); the stopping "
                                     "envelope of every command includes it")
    on_violation: Literal["reject", "clamp"] = "reject"
    home_tolerance_m: float = Field(default=5.0, ge=0, le=1000.0, description="metres: how far a vehicle with its "
                                    "own home (an autopilot) may be from robots[].home when it arms; farther, the "
                                    "drone refuses to take off (the gate places the geofence, max_distance and "
                                    "relative waypoints from robots[].home, the vehicle flies from its own)")
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


def sensor_class(type_: str) -> type:
    """The sensor class (:class:`aerodaas.plugins.sensor.SensorPlugin`) a sensor ``type`` names: a built-in
    (:mod:`aerodaas.plugins.builtin_sensors`), a registered plug-in, an installed entry point or
    ``"module.path:ClassName"``. Raises :class:`aerodaas.plugins.registry.UnknownPlugin` (a ValueError) listing the
    available sensor types with their origins."""
    from aerodaas.plugins import registry

    return registry.get("sensor", type_)


def properties_error(cls: type, err: ValidationError) -> str:
    """The first error of validating a sensor's ``properties`` against ``cls.Config``, worded as
    ``properties.<name> must be an integer within [1, 8192], got 0`` (type and range errors of numbers),
    ``properties.<name>: unknown camera property (did you mean 'width'?); known: [...]``, or the model's own
    message (``properties.mcap must name ...``)."""
    e = err.errors()[0]
    loc = ".".join(str(x) for x in e["loc"])
    fields = cls.Config.model_fields
    if not loc:  # a check of the whole model: its message names the property
        msg = str(e.get("ctx", {}).get("error", e["msg"]))
        return msg if msg.startswith("properties.") else f"properties: {msg}"
    if e["type"] == "extra_forbidden":
        return f"properties.{loc}: unknown {cls.name or cls.__name__} property{did_you_mean(loc, fields)}; " \
               f"known: {sorted(fields)}"
    f = fields.get(str(e["loc"][0]))
    v = e.get("input")
    if f is not None and len(e["loc"]) == 1:
        lo = hi = None
        lo_open = hi_open = False
        for m in f.metadata:
            for attr, is_lo, is_open in (("gt", True, True), ("ge", True, False), ("lt", False, True),
                                         ("le", False, False)):
                x = getattr(m, attr, None)
                if x is not None and is_lo:
                    lo, lo_open = x, is_open
                elif x is not None:
                    hi, hi_open = x, is_open
        ann = str(f.annotation)
        if lo is not None or hi is not None:
            what = "an integer" if "int" in ann else "a finite number"
            rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf':g}, " \
                  f"{hi if hi is not None else 'inf':g}{')' if hi_open else ']'}" if lo is not None and hi is not None \
                else ""
            return f"properties.{loc} must be {what}{' within ' + rng if rng else ''}, got {v!r}"
        if "str" in ann:
            return f"properties.{loc} must be a non-empty string, got {v!r}"
    return f"properties.{loc}: {e['msg']}, got {v!r}"


def _known_sensor(type_: str) -> type | None:
    """The class sensor ``type_`` names, None when it names none (reported where the robot is known)."""
    from aerodaas.plugins import registry

    try:
        cls = sensor_class(type_)
    except registry.UnknownPlugin:
        return None
    return cls if hasattr(cls, "validate_properties") else None


def check_sensor_properties(type_: str, properties: dict[str, Any]) -> dict[str, Any] | None:
    """``properties`` validated against the ``Config`` of sensor type ``type_`` and completed with its defaults;
    None when ``type_`` names no sensor class (an unknown type, or a class that is not a SensorPlugin, is reported
    with the robot's context by :func:`check_plugin_sensors`). Raises ValueError worded by
    :func:`properties_error`."""
    cls = _known_sensor(type_)
    if cls is None:
        return None
    try:
        return cls.validate_properties(properties)
    except ValidationError as e:
        raise ValueError(properties_error(cls, e)) from None


class SensorConfig(_Cfg):
    """A sensor. ``type``: ``camera`` (properties width, height in px, hfov_deg, fps, pitch_deg with 90 = nadir,
    jpeg_quality, source), ``odometry`` (rate_hz), ``stat_stream``, or a sensor plug-in; each type's ``properties``
    are checked against its class's ``Config`` (:mod:`aerodaas.plugins.builtin_sensors` for the built-ins).
    ``buffer`` is the stream buffer length (frames kept for a slow consumer; older ones are dropped and counted).

    A camera's ``source`` is ``sim`` (default: rendered from the simulated world), ``backend`` (the robot's own
    video, e.g. a Tello's; needs such a backend), ``mcap`` (replay a recording: ``mcap`` names the file,
    resolved like other files at load time, and ``topic`` its ``foxglove.CompressedImage`` channel, by default
    ``/<robot>/camera/<sensor id>`` as AeroDaaS records it) or a video stream: an ``rtsp://`` URL, ``rtp://host:port``
    (QGroundControl-style RTP H.264/H.265 on UDP, e.g. port 5600), ``udp://host:port`` (MPEG-TS), an ``.sdp`` file,
    ``/dev/videoN`` or a video file (looped), with ``transport`` (rtsp: tcp/udp), ``codec`` (rtp: h264/h265),
    ``first_frame_timeout_s`` (default 10) and ``stall_timeout_s`` (default 2): docs/video.md."""

    id: Identifier
    type: str = Field(min_length=1, description="camera, odometry, stat_stream, or a sensor plug-in: a registered "
                      "name (decorator, installed entry point of group aerodaas.sensors) or 'module.path:ClassName'")
    properties: dict[str, Any] = Field(default_factory=dict)
    buffer: int = Field(default=1, ge=1, le=100_000)

    @model_validator(mode="after")
    def _check_props(self) -> "SensorConfig":
        cls = _known_sensor(self.type)
        if cls is None or getattr(cls, "own_topic", True):
            check_topic_name(self.id, f"sensor id (a {self.type!r} sensor records on /<robot>/<id>)")
        props = check_sensor_properties(self.type, self.properties)
        if props is not None:
            self.properties = props
        return self


class MavlinkFenceConfig(_Cfg):
    """The autopilot's own geofence (``mavlink.fence``): the second line of defence, enforced by the firmware even
    when our process is gone; our :class:`~aerodaas.navigation.safety.SafetyGate` stays the first.

    ``upload``: on connect, when the robot has a geofence (``safety.geofence`` / ``safety.geofence_plan``), send its
    polygons and circles as the vehicle's fence (MAVLink mission protocol, ``MAV_MISSION_TYPE_FENCE``) and set the
    fence parameters (ArduPilot ``FENCE_ENABLE``/``FENCE_TYPE``/``FENCE_ALT_MAX``/``FENCE_ACTION``, PX4
    ``GF_ACTION``/``GF_MAX_VER_DIST``/``GF_MAX_HOR_DIST``), read everything back and refuse to fly on a mismatch.
    A robot without a geofence leaves the vehicle's fence as it is. The vehicle's fence accepts the points our gate
    does (ArduPilot ``FENCE_OPTIONS`` bit 1 for several inclusion zones; refused for PX4, which intersects them:
    :func:`check_autopilot_fence`). ``max_altitude``: also fence the altitude at the gate's ceiling, the lower of
    ``safety.max_altitude`` and ``limits.max_altitude`` (metres above home). ``home_radius_m``: also a circle of this
    radius (metres) around home (ArduPilot ``FENCE_TYPE`` bit 2 + ``FENCE_RADIUS``, PX4 ``GF_MAX_HOR_DIST``), at
    least ``safety.max_distance``.
    ``action``: what the firmware does on a breach: ``rtl`` (ArduPilot FENCE_ACTION 1 "RTL or Land", PX4 GF_ACTION 3
    "Return"), ``land`` (2 / 5), ``hold`` (ArduPilot 4 "Brake or Land", PX4 2 "Hold"), ``report`` (0 "Report only" /
    1 "Warning": no action). ``restore_on_close``: when the backend closes with the vehicle disarmed, put the
    vehicle's previous fence items and parameters back (default: the fence stays, as a fence should)."""

    upload: bool = True
    action: Literal["rtl", "land", "hold", "report"] = "rtl"
    max_altitude: bool = True
    home_radius_m: float | None = Field(default=None, gt=0, le=10_000.0, description="metres")
    restore_on_close: bool = False


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
    target_system: int | Literal["auto"] | None = Field(
        default=None, description="the vehicle's MAVLink system id (1-255) on this connection; 'auto': the lowest id "
        "seen on the link that no other robot of the run claimed (after 1.5 s of discovery); unset: the first "
        "autopilot heard that no other robot claimed")
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
    #: what the mission does when the autopilot enters a failsafe mode by itself (ArduCopter RTL/SMART_RTL/LAND/
    #: BRAKE, PX4 AUTO.RTL/AUTO.LAND, not asked by us: lost datalink or RC, battery, geofence action, EKF, or a
    #: pilot's switch). ``end`` (default): the mission ends, the autopilot's failsafe flies on (RTL/LAND to the
    #: ground; after BRAKE the vehicle lands where it is), the outcome is ``failsafe``. ``hold``: the mission pauses
    #: with the vehicle left in the failsafe mode until an operator resumes it (HITL ``resume``). ``resume``: once
    #: the link is up, the mission goes on in GUIDED/OFFBOARD (overriding the failsafe: only when the operator
    #: knows why it triggered). docs/operations.md links the autopilots' failsafe documentation.
    on_failsafe: Literal["end", "hold", "resume"] = "end"
    #: the autopilot's own geofence: uploaded from the robot's safety.geofence (see MavlinkFenceConfig)
    fence: MavlinkFenceConfig = Field(default_factory=MavlinkFenceConfig)

    @model_validator(mode="after")
    def _check_target(self) -> "MavlinkConfig":
        t = self.target_system
        if isinstance(t, int) and (isinstance(t, bool) or not 1 <= t <= 255):
            raise ValueError(f"target_system: a MAVLink system id is 1-255 (or 'auto'), got {t!r}")
        return self

    def link_key(self) -> str:
        """The endpoint this connection string names, so that two spellings of one socket are one link:
        ``udp:``/``udpin:`` -> ``udpin:PORT`` (one port whatever the bound address), ``udpout:``/``tcp:`` ->
        ``KIND:HOST:PORT`` (``localhost`` as 127.0.0.1), anything else (a serial device) as written."""
        parts = self.connection.strip().split(":")
        kind = parts[0].lower()
        if len(parts) == 3 and kind in ("udp", "udpin", "udpout", "udpbcast", "tcp", "tcpin"):
            host = "127.0.0.1" if parts[1].lower() == "localhost" else parts[1]
            if kind in ("udp", "udpin"):
                return f"udpin:{parts[2]}"
            return f"{kind}:{host}:{parts[2]}"
        return self.connection.strip()


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


class HoldConfig(_Cfg):
    """How a waypoint's hover (``hover_duration`` > 0) is held. The hold starts once the vehicle is within the
    waypoint's acceptance radius AND its horizontal speed is at most ``settle_speed`` (m/s): passing through at
    speed is not holding. Only time within the radius counts towards the hover time. A hold that has not gathered
    ``hover_duration`` within the radius after ``max_time_factor`` x ``hover_duration`` + ``grace_s`` seconds
    (vehicle time) since it started ends the waypoint as ``hold_failed`` (an event with its figures), never as
    reached: the mission is then ``incomplete``."""

    settle_speed: float = Field(default=0.3, gt=0, le=MAX_SPEED_MPS, description="m/s, horizontal")
    max_time_factor: float = Field(default=2.0, ge=1.0, le=100.0)
    grace_s: float = Field(default=5.0, ge=0, le=MAX_DURATION_S, description="seconds")


class ProgressConfig(_Cfg):
    """How long a waypoint may go without the vehicle getting closer (``progress``; vehicle seconds). Flying towards a
    waypoint, the distance to it must shrink by ``min_progress_m`` metres within ``stall_s`` seconds (longer for a
    slow leg: at least the time ``min_progress_m`` takes at a quarter of the leg's speed), or the vehicle be inside
    the acceptance radius; else a ``navigation_stalled`` event (an autopilot that refuses a target, for its own
    fence or limits, keeps flying to its previous one without a word). After ``abandon_s`` seconds without progress
    the waypoint ends as not reached (``waypoint_abandoned``, listed in the summary): the mission is then
    ``incomplete`` and the drone goes on with what is queued next."""

    min_progress_m: float = Field(default=0.5, gt=0, le=100.0, description="metres")
    stall_s: float = Field(default=15.0, gt=0, le=MAX_DURATION_S, description="vehicle seconds")
    abandon_s: float = Field(default=60.0, gt=0, le=MAX_DURATION_S, description="vehicle seconds")

    @model_validator(mode="after")
    def _order(self) -> "ProgressConfig":
        if self.abandon_s < self.stall_s:
            raise ValueError(f"abandon_s ({self.abandon_s:g} s) must be at least stall_s ({self.stall_s:g} s)")
        return self


class RobotConfig(_Cfg):
    """A robot (drone). ``backend`` selects the driver: ``sim`` (the embedded simulator), ``mavlink`` (ArduPilot or
    PX4, settings in ``mavlink``), ``tello`` (DJI Tello, settings in ``tello``) or ``replay`` (a recorded flight,
    settings in ``replay``; not navigable)."""

    id: RobotId
    backend: str = Field(default="sim", min_length=1, description="sim, mavlink, tello, replay, or a backend "
                         "plug-in: a registered name (decorator, installed entry point of group aerodaas.backends) "
                         "or 'module.path:ClassName'")
    backend_config: dict[str, Any] = Field(default_factory=dict, description="a backend plug-in's own settings, "
                                           "validated against its Config model")
    mavlink: MavlinkConfig | None = None
    tello: TelloConfig | None = None
    replay: ReplayConfig | None = None
    home: GeoPoint = Field(default_factory=lambda: GeoPoint(lat=47.3977, lon=8.5456, alt=488.0))
    limits: Limits = Field(default_factory=Limits)
    battery: BatteryConfig = Field(default_factory=BatteryConfig)
    noise: NoiseConfig = Field(default_factory=NoiseConfig)
    safety: SafetyConfig = Field(default_factory=SafetyConfig)
    hold: HoldConfig = Field(default_factory=HoldConfig)
    progress: ProgressConfig = Field(default_factory=ProgressConfig)
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

    @model_validator(mode="before")
    @classmethod
    def _sensor_properties(cls, data: Any) -> Any:
        """Each sensor's ``properties`` checked against its type's ``Config`` with the robot named in the error
        (``sensors.<j>.properties.<name> ... (robot 'd1', sensor 'cam')``)."""
        if not isinstance(data, dict) or not isinstance(data.get("sensors"), list):
            return data
        for j, s in enumerate(data["sensors"]):
            if isinstance(s, dict) and isinstance(s.get("type"), str) and isinstance(s.get("properties", {}), dict):
                try:
                    check_sensor_properties(s["type"], dict(s.get("properties") or {}))
                except ValueError as e:
                    raise ValueError(f"sensors.{j}.{e} (robot {data.get('id')!r}, sensor {s.get('id')!r})") from None
        return data

    @field_validator("backend")
    @classmethod
    def _known_backend(cls, v: str, info) -> str:
        if v not in BUILTIN_BACKENDS:
            from aerodaas.plugins import registry

            try:
                registry.get("backend", v)
            except registry.UnknownPlugin as e:
                rid = info.data.get("id")
                raise ValueError(f"robot {rid!r}: {e}" if rid else str(e)) from None
        return v

    @model_validator(mode="after")
    def _unique_sensors(self) -> "RobotConfig":
        check_unique([s.id for s in self.sensors], "sensors")
        status = SensorDelivery.MISSION_STATUS
        if not any(getattr(_known_sensor(s.type), "delivery", None) is status for s in self.sensors):
            self.sensors.append(SensorConfig(id=StatStreamSensor.default_id, type=StatStreamSensor.name))
        check_plugin_backend(self)
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
        check_plugin_sensors(self.sensors, f"robot {self.id!r}", "sensors")
        for j, s in enumerate(self.sensors):
            sensor_class(s.type).check_for_robot(s.properties, self, f"sensors.{j}")
        return self


def check_plugin_sensors(sensors: list[SensorConfig], owner: str, field: str) -> None:
    """Resolve every sensor's ``type`` through the plug-in registry (:mod:`aerodaas.plugins.registry`, kind
    ``sensor``: the built-ins of :mod:`aerodaas.plugins.builtin_sensors` and plug-ins alike; their ``properties``
    were validated against the class's ``Config`` with the sensor). Raises ValueError naming ``owner`` (the robot),
    the sensor id, its type and every available sensor type with its origin, or a class that is not a
    SensorPlugin."""
    from aerodaas.plugins import registry

    for j, s in enumerate(sensors):
        try:
            cls = sensor_class(s.type)
        except registry.UnknownPlugin as e:
            raise ValueError(f"{field}.{j}.type: {owner}, sensor {s.id!r}: {e}") from None
        if not hasattr(cls, "validate_properties"):
            raise ValueError(f"{field}.{j}.type: {owner}, sensor {s.id!r}: {s.type!r} resolves to {cls.__name__}, "
                             f"which is not a SensorPlugin (aerodaas.plugins.sensor)")


BUILTIN_BACKENDS = ("sim", "mavlink", "tello", "replay")


def check_plugin_backend(robot: "RobotConfig") -> None:
    """A ``backend`` that is not built in is resolved through the plug-in registry (kind ``backend``) and its
    ``backend_config`` validated against the plug-in's ``Config``. Raises ValueError naming the robot, the backend
    and the available backends with their origins, or the wrong setting."""
    if robot.backend in BUILTIN_BACKENDS:
        if robot.backend_config:
            raise ValueError(f"backend_config: robot {robot.id!r}: backend {robot.backend!r} takes its settings in "
                             f"'{robot.backend}', not backend_config")
        return
    from pydantic import ValidationError

    from aerodaas.plugins import registry

    try:
        cls = registry.get("backend", robot.backend)
    except registry.UnknownPlugin as e:
        raise ValueError(f"backend: robot {robot.id!r}: {e}") from None
    if not hasattr(cls, "options"):
        raise ValueError(f"backend: robot {robot.id!r}: {robot.backend!r} resolves to {cls.__name__}, which is not a "
                         f"VehicleBackend (aerodaas.backends.base)")
    try:
        opts = cls.options(robot)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise ValueError(f"backend_config.{loc}: robot {robot.id!r} ({robot.backend}): {err['msg']}, got "
                         f"{err.get('input')!r}") from None
    if opts is not None:
        robot.backend_config = opts.model_dump(mode="json")


def check_autopilot_fence(robot: "RobotConfig", where: str) -> None:
    """A robot whose MAVLink backend uploads its geofence (``mavlink.fence.upload``) must get an autopilot fence that
    accepts the same points as its safety gate. Checked here, before any actor starts, where the configuration
    alone decides it: a PX4 vehicle (``mavlink.autopilot: px4``) with two or more inclusion zones
    (:func:`aerodaas.navigation.geofence.autopilot_disagreement`), and a ``mavlink.fence.home_radius_m`` below
    ``safety.max_distance`` (both autopilots refuse a target beyond that circle, ArduPilot silently). A robot without
    a geofence leaves the vehicle's fence alone and is not checked. A vehicle identified on connect
    (``autopilot: auto``) is checked by the backend then, before it uploads anything.
    Raises ConfigError naming ``where`` (the robot's path) and the field."""
    from aerodaas.config.base import ConfigError
    from aerodaas.navigation.geofence import autopilot_disagreement

    mc = robot.mavlink
    if robot.backend != "mavlink" or mc is None or not mc.fence.upload or robot.safety.geofence.is_empty:
        return  # the backend leaves the vehicle's fence as it is
    radius = mc.fence.home_radius_m
    if radius is not None and radius < robot.safety.max_distance:
        raise ConfigError(f"{where}.mavlink.fence.home_radius_m: {radius:g} m is below safety.max_distance "
                          f"({robot.safety.max_distance:g} m): the autopilot would refuse targets beyond {radius:g} m "
                          f"from home that the safety gate accepts; set safety.max_distance to at most {radius:g} m")
    if mc.autopilot == "auto":
        return
    why = autopilot_disagreement(robot.safety.geofence, mc.autopilot)
    if why is not None:
        raise ConfigError(f"{where}.safety.geofence: robot {robot.id!r} uploads its geofence to a {mc.autopilot} "
                          f"vehicle (mavlink.fence.upload): {why}")
