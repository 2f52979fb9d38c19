"""A robot's configuration (``robots[]`` of ``environment.json``): its limits (m/s, metres, degrees/s), battery,
sensor noise, safety rules, sensors, backend (the simulator, a MAVLink autopilot, a Tello, a replayed log) and the
backend's own settings."""
from __future__ import annotations

from typing import Any, Literal

from pydantic import ConfigDict, Field, ValidationError, field_validator, model_validator

from aerodaas.navigation.geofence import GeofenceConfig
from aerodaas.navigation.gimbal import GimbalLimits
from aerodaas.model.types import MAX_LOCAL_M, GeoPoint
from aerodaas.model.ids import Identifier, RobotId, check_topic_name, check_unique
from aerodaas.plugins import registry
from aerodaas.plugins.builtin_sensors import StatStreamSensor
from aerodaas.plugins.sensor import Delivery
from aerodaas.recording.health import DEFAULT_MAX_FAILURE_FRACTION
from aerodaas.config.backends import (MavlinkConfig, ReplayConfig, TelloConfig, add_section_schemas,
                                      backend_settings_into_config)
from aerodaas.config.deadlines import PhaseDeadlinesConfig
from aerodaas.config.base import _Cfg, did_you_mean, plugin_config_error
from aerodaas.model.bounds import (DEFAULT_MAX_DISTANCE_M, HOME_ALT_RANGE_M, MAX_ACCEL_MPS2, MAX_ALTITUDE_M,
                                   MAX_BATTERY_WH, MAX_DURATION_S, MAX_POWER_W, MAX_RATE_HZ, MAX_SPEED_MPS,
                                   MAX_LIST_ITEMS, MAX_YAW_RATE_DPS, MIN_CONTROL_HZ)


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
    Voltage is linear between ``voltage_empty`` and ``voltage_full`` in state of charge (a simple LiPo model);
    ``voltage_empty`` must be below ``voltage_full`` (else the voltage rises as the battery drains)."""

    capacity_wh: float = Field(default=60.0, gt=0, le=MAX_BATTERY_WH)
    hover_power_w: float = Field(default=180.0, ge=0, le=MAX_POWER_W)
    speed_power_w_per_mps: float = Field(default=10.0, ge=0, le=MAX_POWER_W)
    voltage_full: float = Field(default=16.8, gt=0, le=1000)
    voltage_empty: float = Field(default=13.2, gt=0, le=1000)
    initial_pct: float = Field(default=100.0, ge=0, le=100)

    @model_validator(mode="after")
    def _voltages(self) -> "BatteryConfig":
        if self.voltage_empty >= self.voltage_full:
            raise ValueError(f"voltage_empty ({self.voltage_empty:g} V) must be below voltage_full "
                             f"({self.voltage_full:g} V)")
        return self


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
    try:
        cls = sensor_class(type_)
    except registry.UnknownPlugin:
        return None
    return cls if hasattr(cls, "validate_properties") else None


def _delivers(cls: Any, delivery: Delivery) -> bool:
    """Whether sensor class ``cls`` delivers its data by ``delivery`` (False for None: an unknown sensor type)."""
    return getattr(cls, "delivery", None) is delivery


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
    except Exception as e:  # noqa: BLE001 - the plug-in's own validator failed otherwise: its configuration error
        raise ValueError(plugin_config_error(f"properties (sensor type {type_!r})", cls, e)) from None


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
    ``first_frame_timeout_s`` (default 10) and ``stall_timeout_s`` (default 2): docs/video.md.

    ``max_failure_fraction`` (a plug-in sensor's): the run is ``degraded`` when more than this fraction of its
    readings raised (:mod:`aerodaas.recording.health`; default 0.2, 0 = any failure, 1 = never)."""

    id: Identifier
    type: str = Field(min_length=1, description="camera, odometry, stat_stream, or a sensor plug-in: a registered "
                      "name (decorator, installed entry point of group aerodaas.sensors) or 'module.path:ClassName'")
    properties: dict[str, Any] = Field(default_factory=dict)
    buffer: int = Field(default=1, ge=1, le=100_000)
    max_failure_fraction: float = Field(default=DEFAULT_MAX_FAILURE_FRACTION, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _check_props(self) -> "SensorConfig":
        cls = _known_sensor(self.type)
        if cls is None or getattr(cls, "own_topic", True):
            check_topic_name(self.id, f"sensor id (a {self.type!r} sensor records on /<robot>/<id>)")
        props = check_sensor_properties(self.type, self.properties)
        if props is not None:
            self.properties = props
        return self


class HoldConfig(_Cfg):
    """How a waypoint's hover (``hover_duration`` > 0) is held. The hold starts once the vehicle is within the
    waypoint's acceptance radius AND its horizontal speed is at most ``settle_speed`` (m/s): passing through at
    speed is not holding. Only time within the radius counts towards the hover time. A hold that has not gathered
    ``hover_duration`` within the radius after ``max_time_factor`` x ``hover_duration`` + ``grace_s`` seconds
    (vehicle time) since it started ends the waypoint as ``hold_failed`` (an event with its figures), never as
    reached: the mission is then ``incomplete``.

    ``radius_from_vehicle`` (default True): the radius a waypoint is reached and held within is at least the
    vehicle's reported horizontal position accuracy (``VehicleState.position_accuracy_m``: a MAVLink vehicle's
    GNSS ``GPS_RAW_INT.h_acc``; 0 on the simulator): a smaller ``acceptance_radius`` asks for a hold the vehicle
    cannot know it keeps, so it is widened to the accuracy and said (``radius_widened`` in the ``waypoint_reached``
    and ``hold_failed`` events). Measured on SITL with stock parameters (2026-11-26): ArduCopter ``h_acc`` 0.30 m,
    PX4 SIH 0.90 m (its ``ESTIMATOR_STATUS.pos_horiz_accuracy`` about 0.28 m; the autopilots' own acceptance radii,
    ArduCopter ``WPNAV_RADIUS`` 200 cm and PX4 ``NAV_ACC_RAD`` 2 m, judge their own missions' arrivals and are not
    used here: they would let a 10 m survey's holds wander 2 m). False: the waypoint's radius as given."""

    settle_speed: float = Field(default=0.3, gt=0, le=MAX_SPEED_MPS, description="m/s, horizontal")
    max_time_factor: float = Field(default=2.0, ge=1.0, le=100.0)
    grace_s: float = Field(default=5.0, ge=0, le=MAX_DURATION_S, description="seconds")
    radius_from_vehicle: bool = True

    def radius(self, acceptance_radius: float, position_accuracy_m: float) -> float:
        """The radius (m) a waypoint of ``acceptance_radius`` m is reached and held within on a vehicle whose
        reported horizontal position accuracy is ``position_accuracy_m`` m (0: exact or unknown): the larger of
        the two with ``radius_from_vehicle``, else ``acceptance_radius``."""
        if self.radius_from_vehicle and position_accuracy_m > acceptance_radius:
            return float(position_accuracy_m)
        return float(acceptance_radius)


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
    PX4), ``tello`` (DJI Tello), ``replay`` (a recorded flight; not navigable) or a backend plug-in. The backend's
    settings are ``backend_config``, validated against the backend class's ``Config`` (built-ins and plug-ins
    alike, :mod:`aerodaas.config.backends`); a built-in's section named after it (``mavlink``, ``tello``,
    ``replay``: the backend's ``config_section``) is accepted as an alias of ``backend_config``. The validated
    settings: :meth:`backend_settings`."""

    model_config = ConfigDict(**_Cfg.model_config, json_schema_extra=add_section_schemas)

    id: RobotId
    backend: str = Field(default="sim", min_length=1, description="sim, mavlink, tello, replay, or a backend "
                         "plug-in: a registered name (decorator, installed entry point of group aerodaas.backends) "
                         "or 'module.path:ClassName'")
    backend_config: dict[str, Any] = Field(default_factory=dict, description="the backend's own settings, "
                                           "validated against its class's Config model (a built-in's section, e.g. "
                                           "'mavlink', is an alias)")
    home: GeoPoint = Field(default_factory=lambda: GeoPoint(lat=47.3977, lon=8.5456, alt=488.0))
    limits: Limits = Field(default_factory=Limits)
    battery: BatteryConfig = Field(default_factory=BatteryConfig)
    noise: NoiseConfig = Field(default_factory=NoiseConfig)
    safety: SafetyConfig = Field(default_factory=SafetyConfig)
    hold: HoldConfig = Field(default_factory=HoldConfig)
    progress: ProgressConfig = Field(default_factory=ProgressConfig)
    deadlines: PhaseDeadlinesConfig = Field(default_factory=PhaseDeadlinesConfig, description="how long take-off, "
                                            "landing and the return to launch may take (vehicle seconds) and what "
                                            "follows an overrun (aerodaas.config.deadlines)")
    takeoff_altitude: float = Field(default=1.5, gt=0, le=MAX_ALTITUDE_M, description="metres above home; within "
                                    "[safety.min_altitude, max_altitude]")
    control_rate_hz: float = Field(default=10.0, ge=MIN_CONTROL_HZ, le=MAX_RATE_HZ, description="the drone's control "
                                   "loop (Hz): failsafes, geofence and queue are checked at every tick")
    idle_land_s: float = Field(default=10.0, gt=0, le=MAX_DURATION_S, description="land after this many seconds (sim time) with "
                               "nothing queued, once some navigation has been flown")
    sensors: list[SensorConfig] = Field(default_factory=list, max_length=MAX_LIST_ITEMS)
    compute: str | None = Field(default=None, description="id of the edge compute resource this robot flies from "
                                "(its drone actor runs there); default: the environment's first edge compute")
    max_waypoints_per_request: int = Field(default=1000, ge=1, le=100_000, description="bounded work: items in one "
                                           "navigation added while flying (HITL request, analytics output)")
    max_queued_items: int = Field(default=5000, ge=1, le=1_000_000, description="bounded work: items queued in "
                                  "all missions of this robot; more are refused (HTTP 422 / navigation_refused)")
    gimbal: GimbalLimits | None = Field(default=None, description="the camera gimbal's limits (pitch/yaw min/max "
                                        "degrees, slew rate_deg_s); absent: the robot has no gimbal to point")

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

    @model_validator(mode="wrap")
    @classmethod
    def _backend_settings(cls, data: Any, handler: Any) -> "RobotConfig":
        """The backend's settings section (``backend_config``, or its alias) validated against its ``Config``
        (errors located at the section the file used: ``robots.0.mavlink.baud``)."""
        if isinstance(data, dict):
            data = backend_settings_into_config(data, set(cls.model_fields))
        return handler(data)

    @field_validator("backend")
    @classmethod
    def _known_backend(cls, v: str, info) -> str:
        try:
            registry.get("backend", v)
        except registry.UnknownPlugin as e:
            rid = info.data.get("id")
            raise ValueError(f"robot {rid!r}: {e}" if rid else str(e)) from None
        return v

    def backend_settings(self) -> Any:
        """The backend's settings: an instance of its class's ``Config`` (None when it declares none)."""
        return registry.get("backend", self.backend).options(self)

    def _settings_if(self, model: type) -> Any:
        got = self.backend_settings()
        return got if isinstance(got, model) else None

    # the sections of the built-in backends, read as before (None when the robot's backend takes other settings)
    mavlink = property(lambda self: self._settings_if(MavlinkConfig), doc="settings of a MAVLink backend, or None")
    tello = property(lambda self: self._settings_if(TelloConfig), doc="settings of a Tello backend, or None")
    replay = property(lambda self: self._settings_if(ReplayConfig), doc="settings of a replay backend, or None")

    @model_validator(mode="after")
    def _unique_sensors(self) -> "RobotConfig":
        check_unique([s.id for s in self.sensors], "sensors")
        if not any(_delivers(_known_sensor(s.type), Delivery.MISSION_STATUS) for s in self.sensors):
            self.sensors.append(SensorConfig(id=StatStreamSensor.default_id, type=StatStreamSensor.name))
        lo, hi = HOME_ALT_RANGE_M
        if not lo <= self.home.alt <= hi:
            raise ValueError(f"home.alt: {self.home.alt!r} m AMSL is outside [{lo:g}, {hi:g}] m")
        max_alt = self.safety.max_altitude if self.safety.max_altitude is not None else self.limits.max_altitude
        if self.takeoff_altitude > max_alt:
            which = "safety.max_altitude" if self.safety.max_altitude is not None else "limits.max_altitude"
            raise ValueError(f"takeoff_altitude: {self.takeoff_altitude:g} m is above {which} ({max_alt:g} m); the "
                             f"take-off target passes the same safety gate as every command")
        start, rtl = self.battery.initial_pct, self.safety.low_battery_rtl_pct
        if start <= rtl:
            raise ValueError(f"battery.initial_pct: a start at {start:g} % is at or below safety.low_battery_rtl_pct "
                             f"({rtl:g} %; critical_battery_pct {self.safety.critical_battery_pct:g} %): the drone "
                             f"would take off only to return (or land) at once")
        if self.takeoff_altitude < self.safety.min_altitude:
            raise ValueError(f"takeoff_altitude: {self.takeoff_altitude:g} m is below safety.min_altitude "
                             f"({self.safety.min_altitude:g} m); the drone would hover below the floor it must keep")
        check_plugin_sensors(self.sensors, f"robot {self.id!r}", "sensors")
        for j, s in enumerate(self.sensors):
            sensor_class(s.type).check_for_robot(s.properties, self, f"sensors.{j}")
        if self.gimbal is not None:
            _check_gimbal_backend(self)
        return self


def _check_gimbal_backend(robot: "RobotConfig") -> None:
    """A ``gimbal`` section needs a backend that declares one (``provides_gimbal``). Raises ValueError naming the
    robot and its backend."""
    try:
        cls = registry.get("backend", robot.backend)
    except registry.UnknownPlugin:
        return  # reported by the backend's own check
    if not getattr(cls, "provides_gimbal", False):
        raise ValueError(f"gimbal: robot {robot.id!r} has a gimbal section, but its backend {robot.backend!r} has no "
                         f"gimbal to point (provides_gimbal is False): remove the section or use the simulator or "
                         f"a MAVLink autopilot")


def check_plugin_sensors(sensors: list[SensorConfig], owner: str, field: str) -> None:
    """Resolve every sensor's ``type`` through the plug-in registry (:mod:`aerodaas.plugins.registry`, kind
    ``sensor``: the built-ins of :mod:`aerodaas.plugins.builtin_sensors` and plug-ins alike; their ``properties``
    were validated against the class's ``Config`` with the sensor). Raises ValueError naming ``owner`` (the robot),
    the sensor id, its type and every available sensor type with its origin, or a class that is not a
    SensorPlugin."""
    for j, s in enumerate(sensors):
        try:
            cls = sensor_class(s.type)
        except registry.UnknownPlugin as e:
            raise ValueError(f"{field}.{j}.type: {owner}, sensor {s.id!r}: {e}") from None
        if not hasattr(cls, "validate_properties"):
            raise ValueError(f"{field}.{j}.type: {owner}, sensor {s.id!r}: {s.type!r} resolves to {cls.__name__}, "
                             f"which is not a SensorPlugin (aerodaas.plugins.sensor)")
