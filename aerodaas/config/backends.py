"""The settings of the built-in vehicle backends, each the ``Config`` of its backend class (the same contract as a
backend plug-in's: :class:`aerodaas.backends.base.VehicleBackend`), and how a robot's settings section is read:
``robots[].backend_config``, or the section named after a built-in backend (``mavlink``, ``tello``, ``replay``; the
class's ``config_section``), kept as an alias so that every existing environment file loads unchanged.

Strict and bounded: a string or a boolean is not a number, and every rate, size and duration has both bounds
(:mod:`aerodaas.config.base`). Durations in seconds, rates in Hz, ports 0-65535."""
from __future__ import annotations

import ipaddress
import json
import re
from typing import Any, Literal

from pydantic import BaseModel, Field, ValidationError, field_validator, model_validator

from aerodaas.config.base import _Cfg, plugin_config_error
from aerodaas.model.bounds import MAX_DURATION_S, MAX_RATE_HZ, MAX_SPEEDUP
from aerodaas.plugins import registry

__all__ = ["SimConfig", "MavlinkFenceConfig", "MavlinkConfig", "TelloConfig", "ReplayConfig",
           "backend_settings_into_config", "add_section_schemas"]


class SimConfig(_Cfg):
    """The embedded simulator has no settings of its own: its vehicle is the robot's ``limits``, ``battery`` and
    ``noise`` (an empty ``backend_config``)."""


class MavlinkFenceConfig(_Cfg):
    """The autopilot's own geofence (``mavlink.fence``): the second line of defence, enforced by the firmware even
    when our process is gone; our :class:`~aerodaas.navigation.safety.SafetyGate` stays the first.

    ``upload``: on connect, when the robot has a geofence (``safety.geofence`` / ``safety.geofence_plan``), send its
    polygons and circles as the vehicle's fence (MAVLink mission protocol, ``MAV_MISSION_TYPE_FENCE``) and set the
    fence parameters (ArduPilot ``FENCE_ENABLE``/``FENCE_TYPE``/``FENCE_ALT_MAX``/``FENCE_ACTION``, PX4
    ``GF_ACTION``/``GF_MAX_VER_DIST``/``GF_MAX_HOR_DIST``), read everything back and refuse to fly on a mismatch.
    A robot without a geofence leaves the vehicle's fence as it is. The vehicle's fence accepts the points our gate
    does (ArduPilot ``FENCE_OPTIONS`` bit 1 for several inclusion zones; refused for PX4, which intersects them:
    :func:`aerodaas.backends.mavlink.preflight.check_autopilot_fence`). ``max_altitude``: also fence the altitude
    at the gate's ceiling, the lower of ``safety.max_altitude`` and ``limits.max_altitude`` (metres above home). ``home_radius_m``: also a circle of this
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


#: the network forms of a pymavlink connection string, ``SCHEME:HOST:PORT`` (pymavlink ``mavutil.
#: mavlink_connection``: ``tcp``/``tcpin`` -> mavtcp/mavtcpin, ``udpin``/``udp`` -> mavudp listening,
#: ``udpout``/``udpbcast`` -> mavudp sending)
MAVLINK_NET_SCHEMES = ("tcp", "tcpin", "udp", "udpin", "udpout", "udpbcast")
_HOST_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def check_mavlink_connection(conn: str) -> None:
    """Check a pymavlink connection string before anything connects: ``SCHEME:HOST:PORT`` with a scheme of
    :data:`MAVLINK_NET_SCHEMES`, a host that is an IPv4 address (four octets 0-255) or a host name (RFC 1123
    labels; not resolved here) and a port within [1, 65535]; or a serial device (a path such as ``/dev/ttyACM0``,
    or ``COM3``; it may appear later, so it need not exist yet). Raises ValueError naming the value and what is
    wrong (``tcp:999.1.1.1:99999`` reached the drone actor, after Ray had started)."""
    s = conn.strip()
    if s != conn or not s:
        raise ValueError(f"{conn!r}: a connection string without surrounding blanks")
    if s.startswith("/") or re.fullmatch(r"COM[0-9]{1,3}", s):
        return
    parts = s.split(":")
    forms = (f"a pymavlink connection string is SCHEME:HOST:PORT with SCHEME one of {list(MAVLINK_NET_SCHEMES)} "
             f"(e.g. udpin:0.0.0.0:14550, tcp:127.0.0.1:5760) or a serial device (/dev/ttyACM0, COM3)")
    if len(parts) != 3 or parts[0] not in MAVLINK_NET_SCHEMES:
        raise ValueError(f"{conn!r} is not a MAVLink connection: {forms}")
    scheme, host, port = parts
    if not re.fullmatch(r"[0-9]{1,5}", port) or not 1 <= int(port) <= 65535:
        raise ValueError(f"{conn!r}: port {port!r} is not within [1, 65535]")
    if re.fullmatch(r"[0-9.]+", host):
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise ValueError(f"{conn!r}: host {host!r} is not an IPv4 address (four numbers 0-255)") from None
    elif len(host) > 253 or not all(_HOST_LABEL.match(label) for label in host.rstrip(".").split(".")):
        raise ValueError(f"{conn!r}: host {host!r} is not an IPv4 address or a host name")


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
    #: MAVLink 2 message signing (docs/security.md): the file holding this vehicle's 32-byte secret key (64 hex
    #: characters, or 32 raw bytes; mode 0600), resolved like every file of the environment. Every message we send
    #: is signed with it; every message from the vehicle must be (aerodaas/backends/mavlink/signing.py). Unset: no
    #: signing. The key itself never goes in the environment file.
    signing_key_file: str | None = Field(default=None, min_length=1)

    @field_validator("connection")
    @classmethod
    def _check_connection(cls, v: str) -> str:
        check_mavlink_connection(v)
        return v

    @model_validator(mode="after")
    def _check_target(self) -> "MavlinkConfig":
        t = self.target_system
        if isinstance(t, int) and (isinstance(t, bool) or not 1 <= t <= 255):
            raise ValueError(f"target_system: a MAVLink system id is 1-255 (or 'auto'), got {t!r}")
        k = (self.signing_key_file or "").strip()
        if len(k) == 64 and all(c in "0123456789abcdefABCDEF" for c in k):  # never echoed: it may be a real key
            raise ValueError("signing_key_file: this looks like a signing key itself; put the key in a private file "
                             "(chmod 600) and name that file here")
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


def backend_settings_into_config(data: dict[str, Any], fields: set[str]) -> dict[str, Any]:
    """A robot's raw configuration (``data``, a ``robots[]`` item; ``fields``: RobotConfig's field names) with its
    backend's settings validated against the backend class's ``Config`` and stored, completed with the defaults,
    JSON-ready, in ``backend_config``; the class's ``config_section`` (``mavlink``, ...) is read as an alias.
    An unknown backend is left to the ``backend`` field's check. Raises pydantic's ValidationError located at the
    section the file used (``mavlink.baud``), or ValueError for settings given twice or a section of another
    backend (``mavlink: use_autopilot_mission: true needs backend 'mavlink' ..., but backend is 'sim'``)."""
    backend = data.get("backend", "sim")
    if not isinstance(backend, str):
        return data
    try:
        cls = registry.get("backend", backend)
    except registry.UnknownPlugin:
        return data
    data = dict(data)
    section = getattr(cls, "config_section", None)
    where = "backend_config"
    if section and section in data:
        if data.get("backend_config"):
            raise ValueError(f"backend_config: backend {backend!r} takes its settings in backend_config or in "
                             f"'{section}' (an alias), not both")
        where, raw = section, data.pop(section)
    else:
        raw = data.get("backend_config")
    strays = set(data) - fields
    if strays:
        _refuse_other_sections(strays, data, backend)
    if raw is None:
        raw = {}
    if isinstance(raw, BaseModel):  # a Python caller's settings object (RobotConfig(mavlink=MavlinkConfig(...)))
        raw = raw.model_dump()
    config = getattr(cls, "Config", None)
    if config is None:
        if not isinstance(raw, dict):
            raise ValueError(f"{where}: must be an object, got {raw!r}")
        data["backend_config"] = raw
        return data
    try:
        data["backend_config"] = config.model_validate(raw).model_dump(mode="json")
    except ValidationError as e:
        raise ValidationError.from_exception_data("RobotConfig", [
            {"type": er["type"], "loc": (where, *er["loc"]), "input": er.get("input"),
             **({"ctx": er["ctx"]} if "ctx" in er else {})} for er in e.errors()]) from None
    except Exception as e:  # noqa: BLE001 - the plug-in's own validator failed otherwise: its configuration error
        raise ValueError(plugin_config_error(f"{where} (backend {backend!r})", cls, e)) from None
    return data


def _refuse_other_sections(keys: set[str], data: dict[str, Any], backend: str) -> None:
    """A key that is another backend's settings section: refused naming the settings and both backends (before,
    a ``mavlink`` section beside ``backend: sim`` was read by nothing). Other unknown keys are left to the model."""
    for e in registry.entries("backend"):
        try:
            owner = e.load()
        except Exception:  # noqa: BLE001 - a backend that does not import has no section here
            continue
        section = getattr(owner, "config_section", None)
        if section in keys:
            given = data[section] if isinstance(data[section], dict) else {}
            what = ", ".join(f"{k}: {json.dumps(v, default=str)}" for k, v in given.items()) or "its settings"
            raise ValueError(f"{section}: {what} needs backend {e.name!r} (the '{section}' section configures "
                             f"it), but backend is {backend!r}")


def add_section_schemas(schema: dict[str, Any]) -> None:
    """Add the settings sections of the built-in backends (``mavlink``, ``tello``, ``replay``: each class's
    ``config_section``, with the JSON Schema of its ``Config``, references inlined) to ``schema``, the JSON Schema
    of a robot, so that ``aerodaas schema`` still describes them (pydantic ``json_schema_extra``)."""
    for e in registry.entries("backend"):
        if not e.builtin:
            continue
        cls = e.load()
        section, config = getattr(cls, "config_section", None), getattr(cls, "Config", None)
        if section and config is not None:
            js = config.model_json_schema()
            defs = js.pop("$defs", {})
            schema.setdefault("properties", {})[section] = _inline(js, defs)


def _inline(node: Any, defs: dict[str, Any]) -> Any:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            return _inline(defs[ref.split("/")[-1]], defs)
        return {k: _inline(v, defs) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline(v, defs) for v in node]
    return node
