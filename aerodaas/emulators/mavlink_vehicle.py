"""The embedded flight model exposed as a MAVLink vehicle that behaves like ArduPilot Copter or PX4 multicopter.

Written from the MAVLink common message set (mavlink.io: heartbeat, command, mission and offboard protocols)
and the autopilots' documented behaviour, *not* from :mod:`aerodaas.backends.mavlink`, so it tests the backend's
assumptions. Mode numbers come from ArduPilot's ``ArduCopter/mode.h`` (``Mode::Number``) and PX4's
``src/modules/commander/px4_custom_mode.h``; result codes from PX4 ``Commander::handle_command`` (refusals are
``MAV_RESULT_TEMPORARILY_REJECTED``) and ArduPilot ``GCS_MAVLINK`` (refusals are ``MAV_RESULT_FAILED``).

What differs between the two flavours (all emulated):

* HEARTBEAT ``autopilot`` (ARDUPILOTMEGA 3 / PX4 12) and ``custom_mode`` (ArduCopter mode number / PX4
  ``main_mode << 16 | sub_mode << 24``).
* Take-off: ArduPilot needs GUIDED and armed, ``param7`` is metres above home; PX4 switches to AUTO.TAKEOFF and
  ``param7`` is metres above mean sea level (NaN: ``MIS_TAKEOFF_ALT`` above home), then holds (AUTO.LOITER).
* Position/velocity targets: ArduPilot honours them in GUIDED (velocity targets stop after 3 s without a new
  one); PX4 only in OFFBOARD, which it refuses to enter without a setpoint stream and leaves (to AUTO.LOITER)
  when the stream stops for ``COM_OF_LOSS_T`` seconds.
* Missions: ArduPilot keeps home at sequence 0 (uploads carry a placeholder there, downloads return home);
  PX4 numbers the first item 0. ArduPilot's AUTO on the ground needs a NAV_TAKEOFF first and starts on
  MAV_CMD_MISSION_START; PX4 takes off by itself and holds (AUTO.LOITER) when the mission ends.
* Streams: ArduPilot sends nothing but HEARTBEAT until asked (SET_MESSAGE_INTERVAL or the legacy
  REQUEST_DATA_STREAM); PX4 streams its default set and ignores REQUEST_DATA_STREAM.
* Before its GPS fix ArduPilot sends GLOBAL_POSITION_INT with latitude/longitude 0; PX4 sends none.
* RTL: climb to ``RTL_ALT`` (cm, ArduPilot) / ``RTL_RETURN_ALT`` (m, PX4) when lower, fly home, land, disarm.
* Both auto-disarm on the ground ``DISARM_DELAY`` / ``COM_DISARM_PRFLT`` seconds after arming without a
  take-off, and after landing.

Time: the emulator has its own clock (``time_boot_ms`` starts at a non-zero boot time); ``speedup`` K runs physics,
streams, timeouts and the clock K times faster than real time. Test hooks: :meth:`set_blackhole` (link loss), :meth:`drop_next` (single lost packets),
:meth:`set_prearm_failure`, ``message_interval=False`` (old firmware that answers SET_MESSAGE_INTERVAL with
UNSUPPORTED), ``ignore_commands`` (commands never acknowledged), ``ack_only_commands`` (acknowledged ACCEPTED but
not carried out), ``in_progress_commands`` (answered MAV_RESULT_IN_PROGRESS forever), :meth:`reject_next`
(one-off refusals such as MAV_RESULT_TEMPORARILY_REJECTED), ``mission_int=False`` (firmware that speaks only the
float MISSION_REQUEST / MISSION_ITEM forms of the mission protocol), :meth:`send_status_text` (STATUSTEXT,
chunked as MAVLink 2 does when longer than 50 characters) and :meth:`inject` (raw bytes or a message on the
link, e.g. corrupt packets). :attr:`setpoint_log` and :attr:`mode_log` record every position/velocity target
and mode change in vehicle time.
"""
from __future__ import annotations

import ipaddress
import math
import selectors
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Literal

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from ..config import RobotConfig
from ..geo import enu_to_geodetic, geodetic_to_enu
from ..models import GeoPoint
from ..sim.vehicle import SimVehicle

__all__ = ["MavlinkVehicleEmulator", "ARDUCOPTER_MODES", "PX4_MODES", "parse_endpoint"]

M = mavlink

#: ArduCopter ``Mode::Number`` (ArduCopter/mode.h): name -> custom_mode.
ARDUCOPTER_MODES: dict[str, int] = {
    "STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "CIRCLE": 7,
    "LAND": 9, "DRIFT": 11, "SPORT": 13, "FLIP": 14, "AUTOTUNE": 15, "POSHOLD": 16, "BRAKE": 17, "THROW": 18,
    "AVOID_ADSB": 19, "GUIDED_NOGPS": 20, "SMART_RTL": 21,
}
#: PX4 px4_custom_mode.h: name -> (main_mode, sub_mode).
PX4_MODES: dict[str, tuple[int, int]] = {
    "MANUAL": (1, 0), "ALTCTL": (2, 0), "POSCTL": (3, 0), "AUTO.READY": (4, 1), "AUTO.TAKEOFF": (4, 2),
    "AUTO.LOITER": (4, 3), "AUTO.MISSION": (4, 4), "AUTO.RTL": (4, 5), "AUTO.LAND": (4, 6), "ACRO": (5, 0),
    "OFFBOARD": (6, 0), "STABILIZED": (7, 0),
}
_AP_NEEDS_POSITION = {"AUTO", "GUIDED", "LOITER", "RTL", "CIRCLE", "LAND", "POSHOLD", "BRAKE", "SMART_RTL", "DRIFT"}
_AP_ARMABLE = {"STABILIZE", "ACRO", "ALT_HOLD", "GUIDED", "LOITER", "POSHOLD", "DRIFT", "SPORT", "BRAKE", "GUIDED_NOGPS"}
_AP_HOLD_MODES = {"LOITER", "BRAKE", "POSHOLD", "CIRCLE", "STABILIZE", "ACRO", "ALT_HOLD", "DRIFT", "SPORT",
                  "GUIDED_NOGPS", "FLIP", "AUTOTUNE", "THROW", "AVOID_ADSB"}
_PX4_MANUAL = {"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED"}
_PX4_NEEDS_POSITION = {"POSCTL", "AUTO.LOITER", "AUTO.MISSION", "AUTO.RTL", "AUTO.TAKEOFF", "AUTO.LAND", "OFFBOARD"}

# SYS_STATUS sensor bits (MAV_SYS_STATUS_SENSOR)
_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
            | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS
            | M.MAV_SYS_STATUS_PREARM_CHECK)

#: Legacy REQUEST_DATA_STREAM groups -> message ids (ArduPilot's stream groups, GCS_Common.cpp).
_DATA_STREAMS: dict[int, tuple[int, ...]] = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT,
                                        M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE),
    M.MAV_DATA_STREAM_POSITION: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE,),
    M.MAV_DATA_STREAM_EXTRA2: (M.MAVLINK_MSG_ID_VFR_HUD,),
    M.MAV_DATA_STREAM_EXTRA3: (M.MAVLINK_MSG_ID_SYSTEM_TIME, M.MAVLINK_MSG_ID_BATTERY_STATUS),
}
#: PX4's default stream set (Hz, vehicle time) on a GCS link.
_PX4_DEFAULT_STREAMS: dict[int, float] = {
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0, M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 5.0, M.MAVLINK_MSG_ID_ATTITUDE: 10.0, M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0, M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0, M.MAVLINK_MSG_ID_VFR_HUD: 4.0,
}

#: messages the vehicle can stream (SET_MESSAGE_INTERVAL); others are DENIED
_STREAMABLE = {M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_SYSTEM_TIME,
               M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
               M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_VFR_HUD,
               M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_HOME_POSITION, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE}

_NAV_COMMANDS = {M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                 M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM}
_MISSION_COMMANDS = _NAV_COMMANDS | {M.MAV_CMD_DO_CHANGE_SPEED}
_GLOBAL_FRAMES = {M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_INT,
                  M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
_MISSION_FRAMES = _GLOBAL_FRAMES | {M.MAV_FRAME_MISSION}
_PROTOCOL_TIMEOUT_S = 1.5  # vehicle-time seconds before a mission transfer request is re-sent
_PROTOCOL_RETRIES = 5
_IN_PROGRESS_PERIOD_S = 0.5  # vehicle-time seconds between repeated MAV_RESULT_IN_PROGRESS acknowledgements
_STATUSTEXT_LEN = 50  # STATUSTEXT.text is char[50]


def parse_endpoint(address: str) -> tuple[str, str, int]:
    """``tcp:HOST:PORT`` / ``udpin:HOST:PORT`` / ``udpout:HOST:PORT`` -> (kind, host, port). Raises ValueError
    naming the address for anything else (port 0: any free port, for tcp and udpin)."""
    parts = address.split(":")
    if len(parts) != 3 or parts[0] not in ("tcp", "udpin", "udpout", "udp"):
        raise ValueError(f"--mavlink: expected tcp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT, got {address!r}")
    try:
        port = int(parts[2])
    except ValueError:
        raise ValueError(f"--mavlink: port must be an integer, got {parts[2]!r} in {address!r}") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"--mavlink: port must be within 0-65535, got {port} in {address!r}")
    kind = "udpin" if parts[0] == "udp" else parts[0]
    return kind, parts[1], port


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Link:
    """One peer: a TCP client, or a UDP peer address. Owns its MAVLink parser/encoder (sequence numbers)."""

    def __init__(self, emu: "MavlinkVehicleEmulator", sock: socket.socket, addr: Any, tcp: bool) -> None:
        self.emu, self.sock, self.addr, self.tcp = emu, sock, addr, tcp
        self.mav = mavlink.MAVLink(self, srcSystem=emu.system_id, srcComponent=emu.component_id)
        self.mav.robust_parsing = True
        self.outbuf = bytearray()
        self.closed = False

    def write(self, buf: bytes) -> None:  # called by MAVLink.send
        if self.emu._blackhole or self.closed:
            return
        if self.tcp:
            self.outbuf += buf
            if len(self.outbuf) > 4_000_000:  # a client that stopped reading
                self.closed = True
        else:
            try:
                self.sock.sendto(buf, self.addr)
            except OSError:
                pass

    def flush(self) -> None:
        if not self.tcp or not self.outbuf or self.closed:
            return
        try:
            n = self.sock.send(self.outbuf)
            del self.outbuf[:n]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self.closed = True


@dataclass
class _Transfer:
    """A mission upload in progress (vehicle side)."""

    link: _Link
    sysid: int
    compid: int
    count: int
    items: list = field(default_factory=list)
    deadline: float = 0.0
    retries: int = 0


class MavlinkVehicleEmulator:
    """A simulated ArduPilot Copter or PX4 multicopter speaking MAVLink 2 over TCP (server) or UDP.

    ``autopilot``: ``"ardupilot"`` or ``"px4"``. ``robot``: limits, battery and home from a
    :class:`~aerodaas.config.RobotConfig` (defaults when None); ``home`` overrides its home (WGS-84 degrees,
    metres AMSL). ``speedup``: vehicle time runs this many times faster than real time. ``params``: overrides
    of the emulated parameters (ArduPilot ``RTL_ALT`` cm, ``LAND_SPEED`` cm/s, ``WPNAV_SPEED`` cm/s,
    ``WPNAV_RADIUS`` cm, ``DISARM_DELAY`` s; PX4 ``RTL_RETURN_ALT`` m, ``MPC_LAND_SPEED`` m/s,
    ``MIS_TAKEOFF_ALT`` m, ``COM_OF_LOSS_T`` s, ``COM_DISARM_PRFLT`` s, ``COM_DISARM_LAND`` s, ``NAV_ACC_RAD`` m,
    ``MPC_XY_CRUISE`` m/s), also settable with PARAM_SET. ``gps_lock_s``: vehicle seconds until the 3-D fix.
    ``message_interval``: False emulates firmware without MAV_CMD_SET_MESSAGE_INTERVAL (UNSUPPORTED).
    ``ignore_commands``: MAV_CMD numbers that are silently dropped (never acknowledged).
    ``ack_only_commands``: MAV_CMD numbers acknowledged MAV_RESULT_ACCEPTED but not carried out (a vehicle that
    says yes and does nothing: the HEARTBEAT never shows the new mode / armed state).
    ``in_progress_commands``: MAV_CMD numbers answered MAV_RESULT_IN_PROGRESS, repeated every 0.5 vehicle seconds,
    and never finished. ``mission_int``: False emulates older firmware that asks for mission items with
    MISSION_REQUEST and answers MISSION_REQUEST_INT with MISSION_ITEM (latitude/longitude as float degrees).

    Use :meth:`start` (returns the bound address), :meth:`stop`, :meth:`snapshot` for the state.
    """

    def __init__(self, autopilot: Literal["ardupilot", "px4"] = "ardupilot", *, robot: RobotConfig | None = None,
                 home: GeoPoint | None = None, speedup: float = 1.0, system_id: int = 1, component_id: int = 1,
                 params: dict[str, float] | None = None, gps_lock_s: float = 2.0, physics_hz: float = 50.0,
                 message_interval: bool = True, ignore_commands: set[int] | None = None,
                 ack_only_commands: set[int] | None = None, in_progress_commands: set[int] | None = None,
                 mission_int: bool = True) -> None:
        if autopilot not in ("ardupilot", "px4"):
            raise ValueError(f"autopilot must be 'ardupilot' or 'px4', got {autopilot!r}")
        if not (speedup > 0 and math.isfinite(speedup)):
            raise ValueError(f"speedup must be a positive number, got {speedup!r}")
        robot = robot or RobotConfig(id="mavlink_sim")
        self.autopilot = autopilot
        self.px4 = autopilot == "px4"
        self.speedup = float(speedup)
        self.system_id, self.component_id = system_id, component_id
        self.origin = home or robot.home  # EKF origin: the simulator's ENU frame
        self.limits = robot.limits
        self.veh = SimVehicle(robot.id, self.origin, robot.limits, robot.battery, robot.noise)
        self.physics_dt = 1.0 / physics_hz
        self.gps_lock_s = gps_lock_s
        self.message_interval_supported = message_interval
        self.ignore_commands = set(ignore_commands or ())
        self.ack_only_commands = set(ack_only_commands or ())
        self.in_progress_commands = set(in_progress_commands or ())
        self.mission_int = bool(mission_int)
        self._rejections: dict[int, list[int]] = {}  # MAV_CMD -> results still to answer (reject_next)
        self._in_progress: dict[int, tuple[_Link, int, int, float, int]] = {}  # cmd -> (link, sys, comp, next t, %)
        self._statustext_id = 0
        sp = robot.limits.max_speed
        if self.px4:
            self.params: dict[str, float] = {"RTL_RETURN_ALT": 60.0, "MPC_LAND_SPEED": 0.7, "MIS_TAKEOFF_ALT": 2.5,
                                             "COM_OF_LOSS_T": 1.0, "COM_DISARM_PRFLT": 10.0, "COM_DISARM_LAND": 2.0,
                                             "NAV_ACC_RAD": 2.0, "MPC_XY_CRUISE": sp, "MAV_SYS_ID": system_id}
        else:
            self.params = {"RTL_ALT": 1500.0, "LAND_SPEED": 50.0, "WPNAV_SPEED": sp * 100.0, "WPNAV_RADIUS": 200.0,
                           "DISARM_DELAY": 10.0, "SYSID_THISMAV": system_id}
        for k, v in (params or {}).items():
            if k not in self.params:
                raise ValueError(f"params: unknown {autopilot} parameter {k!r}; known: {sorted(self.params)}")
            self.params[k] = float(v)
        self._enc = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sel: selectors.BaseSelector | None = None
        self._links: list[_Link] = []
        self._udp_links: dict[Any, _Link] = {}
        self._listen: socket.socket | None = None
        self._udp: socket.socket | None = None
        self._udpout_addr: tuple[str, int] | None = None
        self.address: str | None = None
        self._blackhole = False
        self._blackhole_inbound = False
        self._drop_counts: dict[tuple[str, str], int] = {}  # (direction, message type) -> how many more to drop
        #: (direction "in"/"out", message type) of every message dropped by :meth:`drop_next`
        self.dropped: list[tuple[str, str]] = []
        #: (wall monotonic s, message type) of every message that arrived while the inbound link was cut
        self.blackholed_inbound: list[tuple[float, str]] = []
        self.prearm_failure: str | None = None
        # vehicle state
        self.t = 0.0
        self.boot_ms0 = 73_421  # the autopilot booted a while before we count
        self.mode = "MANUAL" if self.px4 else "STABILIZE"
        self.home: GeoPoint | None = None
        self.home_enu = np.zeros(3)
        self.armed_at = 0.0
        self.landed_at: float | None = None
        self.took_off = False
        self.speed: float | None = None  # DO_CHANGE_SPEED, m/s
        self.phase = ""  # RTL phase: climb / return / land
        self.last_setpoint_t = -1e9
        #: vehicle time (s) of every position/velocity target received (the most recent 100 000)
        self.setpoint_log: deque[float] = deque(maxlen=100_000)
        #: (vehicle time s, mode name) of every mode change (the most recent 10 000)
        self.mode_log: deque[tuple[float, str]] = deque(maxlen=10_000)
        self.velocity_deadline: float | None = None  # ArduPilot GUIDED velocity timeout
        self._last_target: tuple | None = None  # last position/velocity target (PX4 acts on it in OFFBOARD)
        self.posvel: tuple | None = None  # active position + velocity feed-forward target (ENU m, m/s)
        self.takeoff_alt: float | None = None
        self.mission: list[Any] = []  # MISSION_ITEM_INT-like messages, wire sequence
        self.mission_seq = 0
        self.mission_state = "idle"  # idle / wait_start / running / holding / done
        self.item_reached_at: float | None = None
        self.item_started = False
        self.reached_log: list[int] = []
        self._transfer: _Transfer | None = None
        # message id -> interval in vehicle seconds
        self._intervals: dict[int, float] = {m: 1.0 / hz for m, hz in _PX4_DEFAULT_STREAMS.items()} if self.px4 else {}
        self._next_due: dict[int, float] = {}
        self._next_hb = 0.0
        self.statustexts: list[str] = []
        self.commands_seen: list[int] = []
        self.bad_packets = 0

    # ------------------------------------------------------------------ lifecycle
    def start(self, address: str = "tcp:127.0.0.1:0", allow_remote: bool = False) -> str:
        """Listen (tcp, udpin) or send (udpout) on ``address`` and start the vehicle thread. Returns the address
        actually bound (port 0 -> the chosen port). Raises ValueError for a non-loopback address unless
        ``allow_remote``, OSError when the port cannot be bound."""
        kind, host, port = parse_endpoint(address)
        if not allow_remote and not _is_loopback(host):
            raise ValueError(f"--mavlink: {host!r} is not a loopback address; the emulated vehicle accepts commands "
                             "from anyone who can reach it, so pass --allow-remote to expose it beyond this machine")
        self._sel = selectors.DefaultSelector()
        if kind == "tcp":
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
            s.listen(8)
            s.setblocking(False)
            self._listen = s
            self._sel.register(s, selectors.EVENT_READ, "accept")
            self.address = f"tcp:{host}:{s.getsockname()[1]}"
        else:
            u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if kind == "udpin":
                u.bind((host, port))
                self.address = f"udpin:{host}:{u.getsockname()[1]}"
            else:
                u.bind(("127.0.0.1" if _is_loopback(host) else "0.0.0.0", 0))
                self._udpout_addr = (host, port)
                self.address = f"udpout:{host}:{port}"
            u.setblocking(False)
            self._udp = u
            self._sel.register(u, selectors.EVENT_READ, "udp")
            if self._udpout_addr:
                self._udp_link(self._udpout_addr)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"mavlink-{self.autopilot}-emulator", daemon=True)
        self._thread.start()
        return self.address

    def stop(self) -> None:
        """Stop the vehicle thread and close every socket (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        for link in list(self._links):
            if link.tcp:
                try:
                    link.sock.close()
                except OSError:
                    pass
        self._links.clear()
        self._udp_links.clear()
        for s in (self._listen, self._udp):
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
        self._listen = self._udp = None
        if self._sel is not None:
            self._sel.close()
            self._sel = None

    def __enter__(self) -> "MavlinkVehicleEmulator":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ test hooks and state
    def set_blackhole(self, on: bool, inbound: bool = True) -> None:
        """Drop everything the vehicle sends (and, with ``inbound``, everything it receives, logging its type and
        wall time in :attr:`blackholed_inbound`), like a radio out of range; the vehicle keeps flying on its own.
        ``False`` restores the link."""
        with self._lock:
            self._blackhole = bool(on)
            self._blackhole_inbound = bool(on and inbound)

    def drop_next(self, msg_type: str, direction: Literal["in", "out"] = "out", count: int = 1) -> None:
        """Lose exactly the next ``count`` messages of type ``msg_type`` (e.g. ``"COMMAND_ACK"``,
        ``"MISSION_COUNT"``) that the vehicle sends (``"out"``) or receives (``"in"``), like single lost radio
        packets; each loss is logged in :attr:`dropped`. Raises ValueError for another direction or count < 1."""
        if direction not in ("in", "out") or count < 1:
            raise ValueError(f"drop_next: direction must be 'in' or 'out' and count >= 1, got {direction!r}, {count!r}")
        with self._lock:
            key = (direction, msg_type.upper())
            self._drop_counts[key] = self._drop_counts.get(key, 0) + int(count)

    def _dropping(self, direction: str, msg_type: str) -> bool:
        key = (direction, msg_type)
        if self._drop_counts.get(key, 0) <= 0:
            return False
        self._drop_counts[key] -= 1
        self.dropped.append(key)
        return True

    def set_prearm_failure(self, text: str | None) -> None:
        """Make pre-arm checks fail with ``text`` (e.g. ``"Compass not calibrated"``); None clears it."""
        with self._lock:
            self.prearm_failure = text

    def reject_next(self, command: int, count: int = 1,
                    result: int = M.MAV_RESULT_TEMPORARILY_REJECTED) -> None:
        """Answer the next ``count`` COMMAND_LONG/COMMAND_INT ``command`` (MAV_CMD number) with ``result``
        (MAV_RESULT, default TEMPORARILY_REJECTED: "try again later") without carrying it out. Raises ValueError
        for count < 1 or MAV_RESULT_ACCEPTED / IN_PROGRESS (see ``ack_only_commands`` / ``in_progress_commands``)."""
        if count < 1 or result in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS, M.MAV_RESULT_ENUM_END) \
                or result not in M.enums["MAV_RESULT"]:
            raise ValueError(f"reject_next: count must be >= 1 and result a refusing MAV_RESULT, got {count!r}, "
                             f"{result!r}")
        with self._lock:
            self._rejections.setdefault(int(command), []).extend([int(result)] * int(count))

    def send_status_text(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        """Send STATUSTEXT ``text`` (ASCII) to every peer; longer than 50 characters it goes out in chunks as
        MAVLink 2 specifies (same non-zero ``id``, ``chunk_seq`` from 0, the last chunk NUL-terminated)."""
        with self._lock:
            self._text(severity, text)

    def inject(self, data: bytes | Any) -> None:
        """Put ``data`` on the link to every peer as if the vehicle had sent it: raw bytes (garbage, a corrupt
        frame) are written unchanged between two packets; a pymavlink message is packed with each link's
        sequence number."""
        with self._lock:
            for link in list(self._links):
                if isinstance(data, (bytes, bytearray)):
                    link.write(bytes(data))
                else:
                    self._send(data, link)

    def set_param(self, name: str, value: float) -> None:
        """Set an emulated parameter (see the class docstring). Raises KeyError for an unknown name."""
        with self._lock:
            if name not in self.params:
                raise KeyError(f"unknown {self.autopilot} parameter {name!r}")
            self.params[name] = float(value)

    def snapshot(self) -> dict[str, Any]:
        """The vehicle's state: ``t`` (vehicle seconds), ``mode``, ``armed``, ``in_air``, ``position`` (ENU metres
        from the *current* home), ``position_origin`` (ENU from the EKF origin), ``home`` (GeoPoint or None),
        ``gps_fix``, ``mission_seq``, ``mission_len`` (wire items), ``reached`` (MISSION_ITEM_REACHED seqs),
        ``links`` (connected peers), ``statustexts``, ``commands_seen``."""
        with self._lock:
            s = self.veh.state
            return {"t": self.t, "mode": self.mode, "armed": s.armed, "in_air": s.in_air,
                    "position": tuple(float(v) for v in s.position - self.home_enu),
                    "position_origin": tuple(float(v) for v in s.position), "home": self.home,
                    "gps_fix": self._fix_type(), "mission_seq": self.mission_seq, "mission_len": len(self.mission),
                    "reached": list(self.reached_log), "links": len(self._links),
                    "statustexts": list(self.statustexts), "commands_seen": list(self.commands_seen),
                    "battery_pct": self.veh.battery_pct}

    # ------------------------------------------------------------------ I/O loop
    def _udp_link(self, addr: Any) -> _Link:
        link = self._udp_links.get(addr)
        if link is None:
            link = _Link(self, self._udp, addr, tcp=False)
            self._udp_links[addr] = link
            self._links.append(link)
        return link

    def _run(self) -> None:
        last = time.monotonic()
        while not self._stop.is_set():
            sel = self._sel
            if sel is None:
                break
            try:
                ready = sel.select(0.004)
            except (OSError, ValueError):
                break
            with self._lock:
                for key, _ in ready:
                    try:
                        self._on_ready(key)
                    except OSError:
                        pass
                now = time.monotonic()
                elapsed = min(now - last, 0.5) * self.speedup  # a stalled thread does not teleport the vehicle
                last = now
                while elapsed > 1e-9:
                    dt = min(self.physics_dt, elapsed)
                    elapsed -= dt
                    self._tick(dt)
                for link in list(self._links):
                    link.flush()
                    if link.closed:
                        self._drop(link)

    def _on_ready(self, key: selectors.SelectorKey) -> None:
        if key.data == "accept":
            conn, addr = self._listen.accept()
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            link = _Link(self, conn, addr, tcp=True)
            self._links.append(link)
            self._sel.register(conn, selectors.EVENT_READ, link)
        elif key.data == "udp":
            while True:
                try:
                    data, addr = self._udp.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    return
                self._feed(self._udp_link(addr), data)
        else:
            link: _Link = key.data
            try:
                data = link.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._drop(link)
                return
            self._feed(link, data)

    def _drop(self, link: _Link) -> None:
        if link in self._links:
            self._links.remove(link)
        if link.tcp:
            try:
                self._sel.unregister(link.sock)
            except (KeyError, ValueError):
                pass
            try:
                link.sock.close()
            except OSError:
                pass

    def _feed(self, link: _Link, data: bytes) -> None:
        try:
            msgs = link.mav.parse_buffer(data) or []
        except Exception:  # a malformed stream must never stop the vehicle
            self.bad_packets += 1
            return
        if self._blackhole_inbound:  # out of range: parsed only to log what the ground station still sent
            now = time.monotonic()
            self.blackholed_inbound.extend((now, m.get_type()) for m in msgs)
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            if self._drop_counts and self._dropping("in", msg.get_type()):
                continue
            try:
                self._handle(link, msg)
            except Exception as e:  # noqa: BLE001 - report, keep flying
                self._text(M.MAV_SEVERITY_ERROR, f"emulator: {msg.get_type()} handling failed: {e}")

    def _send(self, msg: Any, link: _Link | None = None) -> None:
        if self._drop_counts and self._dropping("out", msg.get_type()):
            return
        for lk in ([link] if link is not None else list(self._links)):
            try:
                lk.mav.send(msg)
            except Exception:  # noqa: BLE001
                lk.closed = True

    def _text(self, severity: int, text: str) -> None:
        """STATUSTEXT: one message up to 50 characters (``id`` 0); longer ones in chunks of 50 with a shared
        non-zero ``id`` and ``chunk_seq`` 0, 1, ...; the last chunk is shorter than 50 (NUL-padded on the wire),
        an empty one when the text fills the previous chunks exactly. Texts are cut at 200 characters."""
        self.statustexts.append(text)
        data = text.encode("ascii", "replace")[:200]
        if len(data) <= _STATUSTEXT_LEN:
            self._send(self._enc.statustext_encode(severity, data, 0, 0))
            return
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        chunks = [data[i:i + _STATUSTEXT_LEN] for i in range(0, len(data), _STATUSTEXT_LEN)]
        if len(chunks[-1]) == _STATUSTEXT_LEN:
            chunks.append(b"")
        for seq, chunk in enumerate(chunks):
            self._send(self._enc.statustext_encode(severity, chunk, self._statustext_id, seq))

    # ------------------------------------------------------------------ geometry helpers
    def _fix_type(self) -> int:
        return M.GPS_FIX_TYPE_3D_FIX if self.t >= self.gps_lock_s else M.GPS_FIX_TYPE_NO_FIX

    def _geo(self) -> GeoPoint:
        p = self.veh.state.position
        return enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)

    def _rel(self) -> np.ndarray:
        return self.veh.state.position - self.home_enu

    def _set_home_here(self) -> None:
        p = self.veh.state.position.copy()
        p[2] = min(p[2], 0.0) if not self.veh.state.in_air else p[2]
        self.home_enu = p
        self.home = enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)
        self._emit(M.MAVLINK_MSG_ID_HOME_POSITION)

    def _global_to_enu(self, lat: float, lon: float, alt: float, frame: int) -> np.ndarray:
        """Global position (deg, deg, m in ``frame``) -> ENU metres in the simulator's (EKF origin) frame."""
        e, n, _ = geodetic_to_enu(lat, lon, self.origin.alt, self.origin)
        home_alt = self.home.alt if self.home is not None else self.origin.alt
        if frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            up = alt - self.origin.alt
        else:  # relative to home
            up = alt + (home_alt - self.origin.alt)
        return np.array([e, n, up])

    # ------------------------------------------------------------------ physics and autopilot logic
    def _tick(self, dt: float) -> None:
        self.t += dt
        veh, s = self.veh, self.veh.state
        if self.home is None and self._fix_type() >= 3:
            self._set_home_here()
            self._text(M.MAV_SEVERITY_INFO, "EKF3 IMU0 origin set" if not self.px4 else "home set")
        was_in_air = s.in_air
        if s.armed:
            veh.step(dt)
        if s.in_air:
            self.took_off = True
        if was_in_air and not s.in_air:
            self.landed_at = self.t
        self._autopilot_logic()
        self._stream()

    def _autopilot_logic(self) -> None:
        s = self.veh.state
        mode = self.mode
        # auto-disarm: on the ground after arming without a take-off, and after landing
        if s.armed and not s.in_air:
            delay = self.params["COM_DISARM_PRFLT" if self.px4 else "DISARM_DELAY"]
            if not self.took_off and delay > 0 and self.t - self.armed_at > delay and not self._climbing():
                self._disarm("auto disarm (no take-off)")
            elif self.took_off and self.landed_at is not None:
                after = self.params["COM_DISARM_LAND"] if self.px4 else 1.0
                if self.t - self.landed_at > after:
                    self._disarm("landed")
        if self.posvel is not None:
            if mode in ("GUIDED", "OFFBOARD") and s.armed and s.in_air:
                self._track_posvel()
            else:
                self.posvel = None
        # ArduPilot GUIDED velocity targets time out after 3 s
        if self.velocity_deadline is not None and self.t > self.velocity_deadline:
            self.velocity_deadline = None
            if s.in_air:
                self.veh.hold()
        # PX4 offboard loss
        if self.px4 and mode == "OFFBOARD" and self.t - self.last_setpoint_t > self.params["COM_OF_LOSS_T"]:
            self._text(M.MAV_SEVERITY_WARNING, "Failsafe activated: offboard control lost, holding")
            self._enter("AUTO.LOITER")
        # take-off completion
        if self.takeoff_alt is not None and s.armed:
            if abs(self._rel()[2] - self.takeoff_alt) < 0.1:
                self.takeoff_alt = None
                if self.px4 and mode == "AUTO.TAKEOFF":
                    self._enter("AUTO.LOITER")
        if mode in ("RTL", "AUTO.RTL") or (mode in ("AUTO", "AUTO.MISSION") and self.phase):
            self._rtl_logic()
        elif mode in ("AUTO", "AUTO.MISSION"):
            self._mission_logic()

    def _climbing(self) -> bool:
        return self.takeoff_alt is not None or self.mission_state == "running"

    def _disarm(self, why: str) -> None:
        s = self.veh.state
        s.armed = False
        s.velocity[:] = 0.0
        self.veh.setpoint.mode = "idle"
        self.takeoff_alt = None
        self.phase = ""
        self.landed_at = None
        self._text(M.MAV_SEVERITY_INFO, f"Disarming motors ({why})" if not self.px4 else f"Disarmed by {why}")

    def _land_speed(self) -> float:
        return self.params["MPC_LAND_SPEED"] if self.px4 else self.params["LAND_SPEED"] / 100.0

    def _start_land(self) -> None:
        self.veh.land()
        self.veh.setpoint.land_speed = self._land_speed()
        self.takeoff_alt = None

    def _rtl_logic(self) -> None:
        s = self.veh.state
        if not s.armed or not s.in_air:
            return
        rel = self._rel()
        rtl_alt = self.params["RTL_RETURN_ALT"] if self.px4 else self.params["RTL_ALT"] / 100.0
        if self.phase == "climb":
            alt = max(rtl_alt, rel[2])
            if rel[2] >= alt - 0.2:
                self.phase = "return"
                self._goto_enu(np.array([self.home_enu[0], self.home_enu[1], self.home_enu[2] + rel[2]]))
            else:
                self._goto_enu(np.array([s.position[0], s.position[1], self.home_enu[2] + alt]))
        elif self.phase == "return":
            if math.hypot(*(s.position[:2] - self.home_enu[:2])) < 0.5 and float(np.linalg.norm(s.velocity)) < 0.3:
                self.phase = "land"
                self._start_land()

    def _goto_enu(self, target: np.ndarray) -> None:
        sp = self.veh.setpoint
        t = tuple(float(v) for v in target)
        # PX4 flies OFFBOARD position setpoints at its velocity limit: DO_CHANGE_SPEED is for navigator modes
        speed = None if self.px4 and self.mode == "OFFBOARD" else self.speed
        if sp.mode == "position" and sp.target == t and sp.speed == speed:
            return
        self.veh.goto(t, speed)

    # ------------------------------------------------------------------ modes
    def _mode_number(self) -> tuple[int, int]:
        """(base_mode, custom_mode) for HEARTBEAT."""
        s = self.veh.state
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if s.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self.px4:
            main, sub = PX4_MODES[self.mode]
            if self.mode in _PX4_MANUAL:
                base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            else:
                base |= M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            return base, (main << 16) | (sub << 24)
        base |= M.MAV_MODE_FLAG_STABILIZE_ENABLED | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if self.mode in ("AUTO", "RTL", "LOITER", "GUIDED", "CIRCLE", "POSHOLD", "BRAKE", "SMART_RTL"):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        return base, ARDUCOPTER_MODES[self.mode]

    def _mode_from_custom(self, custom_main: int, custom_sub: int = 0) -> str | None:
        if self.px4:
            for name, (m_, s_) in PX4_MODES.items():
                if m_ == custom_main and (s_ == custom_sub or (m_ != 4 and s_ == 0)):
                    return name
            if custom_main == 4 and custom_sub == 0:
                return "AUTO.MISSION"
            return None
        for name, num in ARDUCOPTER_MODES.items():
            if num == custom_main:
                return name
        return None

    def _reject_mode(self, name: str, why: str) -> int:
        if self.px4:
            self._text(M.MAV_SEVERITY_CRITICAL, f"Switching to {name} is currently not available")
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        self._text(M.MAV_SEVERITY_WARNING, f"Mode change to {name} failed: {why}")
        return M.MAV_RESULT_FAILED

    def _request_mode(self, name: str | None) -> int:
        """Validate and enter a mode; returns the MAV_RESULT."""
        if name is None:
            if not self.px4:
                self._text(M.MAV_SEVERITY_WARNING, "Flight mode change failed")
            return M.MAV_RESULT_FAILED if not self.px4 else M.MAV_RESULT_TEMPORARILY_REJECTED
        s = self.veh.state
        needs_pos = _PX4_NEEDS_POSITION if self.px4 else _AP_NEEDS_POSITION
        if name in needs_pos and self._fix_type() < 3:
            return self._reject_mode(name, "requires position")
        if self.px4 and name == "OFFBOARD" and not self._offboard_stream_ok():
            return self._reject_mode(name, "no setpoint stream")
        if name in ("AUTO", "AUTO.MISSION"):
            if not self._mission_nav_items():
                if self.px4:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                return self._reject_mode(name, "no mission")
            if not self.px4 and s.armed and not s.in_air and not self._starts_with_takeoff():
                self._text(M.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
                return M.MAV_RESULT_FAILED
        self._enter(name)
        return M.MAV_RESULT_ACCEPTED

    def _offboard_stream_ok(self) -> bool:
        """PX4 enters OFFBOARD only with a live setpoint stream: the last one within COM_OF_LOSS_T and at least
        two in the last vehicle second."""
        log = self.setpoint_log
        recent = len(log) >= 2 and self.t - log[-2] <= 1.0
        return self.t - self.last_setpoint_t <= self.params["COM_OF_LOSS_T"] and recent

    def _enter(self, name: str) -> None:
        if name == self.mode and name not in ("AUTO", "AUTO.MISSION"):
            return
        s = self.veh.state
        prev = self.mode
        self.mode = name
        self.mode_log.append((self.t, name))
        self.phase = ""
        self.posvel = None
        self.velocity_deadline = None
        if name in ("AUTO", "AUTO.MISSION") and prev not in ("AUTO", "AUTO.MISSION"):
            if not self.px4 and s.armed and not s.in_air:
                self.mission_state = "wait_start"  # ArduPilot: MAV_CMD_MISSION_START (or throttle) starts it
            else:
                self._begin_mission()
        if not s.armed or (not s.in_air and name not in ("AUTO.TAKEOFF", "AUTO", "AUTO.MISSION", "OFFBOARD")):
            if name in ("LAND", "AUTO.LAND", "RTL", "AUTO.RTL"):
                return
        if name in ("LAND", "AUTO.LAND"):
            if s.in_air:
                self._start_land()
        elif name in ("RTL", "AUTO.RTL", "SMART_RTL"):
            if s.in_air:
                self.phase = "climb"
        elif name == "AUTO.TAKEOFF":
            if s.armed and not s.in_air:
                self._start_takeoff(self.params["MIS_TAKEOFF_ALT"])
            elif s.in_air:
                self.veh.hold()
        elif name == "OFFBOARD" and self._last_target is not None:
            self._apply_target(*self._last_target, note=False)
        elif name in ("GUIDED", "OFFBOARD"):
            if s.in_air and self.takeoff_alt is None:
                self.veh.hold()
        elif name in ("AUTO", "AUTO.MISSION"):
            pass
        else:  # LOITER, AUTO.LOITER, BRAKE, POSHOLD, manual modes without RC: hold position
            if s.in_air:
                self.veh.hold()

    def _begin_mission(self) -> None:
        """Run the mission from the current item; PX4 on the ground takes off to MIS_TAKEOFF_ALT first unless
        the mission starts with a take-off item."""
        s = self.veh.state
        self.item_started = False
        self.item_reached_at = None
        self.mission_state = "running"
        if self.px4 and s.armed and not s.in_air and not self._starts_with_takeoff():
            self._start_takeoff(self.params["MIS_TAKEOFF_ALT"])

    def _start_takeoff(self, rel_alt: float) -> None:
        s = self.veh.state
        self.takeoff_alt = float(rel_alt)
        self._goto_enu(np.array([s.position[0], s.position[1], self.home_enu[2] + self.takeoff_alt]))

    # ------------------------------------------------------------------ arming
    def _prearm(self) -> str | None:
        """The first failing pre-arm check, in the autopilot's words, or None."""
        if self.prearm_failure:
            return self.prearm_failure
        if self._fix_type() < 3:
            return "Need 3D Fix" if not self.px4 else "GPS fix too low"
        if self.home is None:
            return "Need Position Estimate" if not self.px4 else "Home position invalid"
        return None

    def _arm(self, force: bool) -> int:
        s = self.veh.state
        if s.armed:
            return M.MAV_RESULT_ACCEPTED
        if not force:
            if self.px4:
                why = self._prearm()  # health checks first (PX4 reports every failing check; we send the first)
                if why:
                    self._text(M.MAV_SEVERITY_CRITICAL, f"Preflight Fail: {why}")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode in _PX4_MANUAL:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Preflight Fail: No manual control input")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode in ("AUTO.RTL", "AUTO.LAND"):
                    self._text(M.MAV_SEVERITY_CRITICAL, f"Arming denied: {self.mode} mode not armable")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode == "OFFBOARD" and not self._offboard_stream_ok():
                    self._text(M.MAV_SEVERITY_CRITICAL, "Preflight Fail: offboard control signal lost")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
            else:
                if self.mode not in _AP_ARMABLE:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable")
                    return M.MAV_RESULT_FAILED
                why = self._prearm()
                if why:
                    self._text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {why}")
                    return M.MAV_RESULT_FAILED
        self.veh.arm()
        self.armed_at = self.t
        self.took_off = False
        self.landed_at = None
        if self._fix_type() >= 3:
            self._set_home_here()  # both autopilots reset home to where they arm
        self._text(M.MAV_SEVERITY_INFO, "Arming motors" if not self.px4 else "Armed by external command")
        return M.MAV_RESULT_ACCEPTED

    # ------------------------------------------------------------------ message handling
    def _for_us(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self.system_id) and tc in (0, self.component_id)

    def _handle(self, link: _Link, msg: Any) -> None:
        mtype = msg.get_type()
        handler: Callable | None = getattr(self, f"_on_{mtype.lower()}", None)
        if handler is None:
            return
        if mtype not in ("HEARTBEAT", "REQUEST_DATA_STREAM") and not self._for_us(msg):
            return
        handler(link, msg)

    def _on_command_long(self, link: _Link, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        self._command(link, msg, msg.command, p)

    def _on_command_int(self, link: _Link, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x / 1e7, msg.y / 1e7, msg.z]
        self._command(link, msg, msg.command, p, frame=msg.frame)

    def _command(self, link: _Link, msg: Any, cmd: int, p: list[float], frame: int | None = None) -> None:
        self.commands_seen.append(cmd)
        if cmd in self.ignore_commands:
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if cmd in self.in_progress_commands:  # repeated by _stream until the end of time
            prev = self._in_progress.get(cmd)
            self._in_progress[cmd] = (link, *src, self.t + _IN_PROGRESS_PERIOD_S, prev[4] if prev else 0)
            result = M.MAV_RESULT_IN_PROGRESS
        elif self._rejections.get(cmd):
            result = self._rejections[cmd].pop(0)
            if result == M.MAV_RESULT_TEMPORARILY_REJECTED:
                self._text(M.MAV_SEVERITY_WARNING, "Command temporarily rejected: busy")
        elif cmd in self.ack_only_commands:
            result = M.MAV_RESULT_ACCEPTED
        else:
            result = self._execute(link, cmd, p, frame)
        if result is None:
            return
        self._send(self._enc.command_ack_encode(cmd, result, 0, 0, *src), link)

    def _execute(self, link: _Link, cmd: int, p: list[float], frame: int | None) -> int | None:
        s = self.veh.state
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            force = int(round(p[1])) == 21196
            if p[0] >= 0.5:
                return self._arm(force)
            if s.armed and s.in_air and not force:
                if self.px4:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                self._text(M.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying")
                return M.MAV_RESULT_FAILED
            if s.armed:
                s.in_air = False
                self._disarm("external command")
            return M.MAV_RESULT_ACCEPTED
        if cmd == M.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return M.MAV_RESULT_UNSUPPORTED if self.px4 else M.MAV_RESULT_FAILED
            return self._request_mode(self._mode_from_custom(int(p[1]), int(p[2])))
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff_command(p)
        if cmd == M.MAV_CMD_NAV_LAND:
            return self._request_mode("AUTO.LAND" if self.px4 else "LAND")
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._request_mode("AUTO.RTL" if self.px4 else "RTL")
        if cmd == M.MAV_CMD_DO_CHANGE_SPEED:
            if p[1] == -2:
                self.speed = None
            elif p[1] > 0:
                self.speed = float(p[1])
            elif p[1] != -1:
                return M.MAV_RESULT_DENIED
            sp = self.veh.setpoint
            if sp.mode == "position":  # the leg being flown changes speed too
                sp.speed = None if self.px4 and self.mode == "OFFBOARD" else self.speed
            return M.MAV_RESULT_ACCEPTED
        if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not self.message_interval_supported:
                return M.MAV_RESULT_UNSUPPORTED
            msg_id, interval = int(p[0]), p[1]
            if msg_id not in _STREAMABLE:
                return M.MAV_RESULT_DENIED
            if interval == -1:
                self._intervals.pop(msg_id, None)
            elif interval == 0:
                default = _PX4_DEFAULT_STREAMS.get(msg_id) if self.px4 else None
                if default:
                    self._intervals[msg_id] = 1.0 / default
                else:
                    self._intervals.pop(msg_id, None)
            elif interval > 0:
                self._intervals[msg_id] = interval / 1e6  # µs -> vehicle seconds
                self._next_due[msg_id] = self.t
            else:
                return M.MAV_RESULT_DENIED
            return M.MAV_RESULT_ACCEPTED
        if cmd in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = {M.MAV_CMD_GET_HOME_POSITION: M.MAVLINK_MSG_ID_HOME_POSITION,
                      M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: M.MAVLINK_MSG_ID_AUTOPILOT_VERSION}.get(cmd, int(p[0]))
            out = self._build(msg_id)
            if out is None:
                return M.MAV_RESULT_FAILED if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION else M.MAV_RESULT_DENIED
            self._send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_ACCEPTED, 0, 0, 0, 0), link)
            self._send(out, link)
            return None
        if cmd == M.MAV_CMD_MISSION_START:
            return self._mission_start(int(p[0]) if p[0] == p[0] else 0)
        if cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = int(p[0])
            if not 0 <= seq < len(self.mission):
                return M.MAV_RESULT_DENIED
            self._set_current(seq)
            return M.MAV_RESULT_ACCEPTED
        return M.MAV_RESULT_UNSUPPORTED

    def _takeoff_command(self, p: list[float]) -> int:
        s = self.veh.state
        if self.px4:
            if self._fix_type() < 3 or self.home is None:
                return self._reject_mode("AUTO.TAKEOFF", "requires position")
            alt_amsl = p[6]
            rel = self.params["MIS_TAKEOFF_ALT"] if alt_amsl != alt_amsl else alt_amsl - self.home.alt
            if self.mode != "AUTO.TAKEOFF":
                self.mode = "AUTO.TAKEOFF"
                self.mode_log.append((self.t, self.mode))
            self.phase = ""
            if s.armed and not s.in_air:
                self._start_takeoff(rel)
            return M.MAV_RESULT_ACCEPTED
        if self.mode != "GUIDED" or not s.armed or s.in_air:
            why = "not in GUIDED" if self.mode != "GUIDED" else "not armed" if not s.armed else "already flying"
            self._text(M.MAV_SEVERITY_WARNING, f"Takeoff refused: {why}")
            return M.MAV_RESULT_FAILED
        self._start_takeoff(p[6])
        return M.MAV_RESULT_ACCEPTED

    def _on_set_mode(self, link: _Link, msg: Any) -> None:
        if msg.target_system not in (0, self.system_id) or not msg.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return
        cm = msg.custom_mode
        if self.px4:
            self._request_mode(self._mode_from_custom((cm >> 16) & 0xFF, (cm >> 24) & 0xFF))
        else:
            self._request_mode(self._mode_from_custom(cm))

    def _on_request_data_stream(self, link: _Link, msg: Any) -> None:
        if self.px4 or msg.target_system not in (0, self.system_id):
            return  # PX4 does not implement the deprecated stream groups
        groups = list(_DATA_STREAMS) if msg.req_stream_id == M.MAV_DATA_STREAM_ALL else [msg.req_stream_id]
        for g in groups:
            for mid in _DATA_STREAMS.get(g, ()):
                if msg.start_stop and msg.req_message_rate > 0:
                    self._intervals[mid] = 1.0 / msg.req_message_rate
                    self._next_due[mid] = self.t
                else:
                    self._intervals.pop(mid, None)

    # position targets (MAVLink offboard / guided protocol: POSITION_TARGET_TYPEMASK)
    def _target_allowed(self) -> bool:
        if self.px4:
            return True  # PX4 records every setpoint; it acts on them in OFFBOARD only
        return self.mode == "GUIDED"

    def _note_setpoint(self) -> None:
        self.last_setpoint_t = self.t
        self.setpoint_log.append(self.t)

    def _apply_target(self, pos_enu: np.ndarray | None, vel_enu: np.ndarray | None, yaw_rate_dps: float | None,
                      note: bool = True) -> None:
        if note:
            self._note_setpoint()
            self._last_target = (pos_enu, vel_enu, yaw_rate_dps)
        if not self._target_allowed():
            return
        s = self.veh.state
        if self.px4 and self.mode != "OFFBOARD":
            return
        if not s.armed:
            return
        if not self.px4 and not s.in_air and self.takeoff_alt is None:
            return  # ArduPilot ignores guided targets until it has taken off
        self.posvel = None
        if pos_enu is not None and vel_enu is not None:  # position with velocity feed-forward
            self.velocity_deadline = None
            self.takeoff_alt = None
            self.posvel = (np.asarray(pos_enu, float), np.asarray(vel_enu, float))
            self._track_posvel()
        elif pos_enu is not None:
            self.velocity_deadline = None
            self.takeoff_alt = None
            self._goto_enu(pos_enu)
        elif vel_enu is not None:
            self.takeoff_alt = None
            self.veh.set_velocity(tuple(float(v) for v in vel_enu), float(yaw_rate_dps or 0.0))
            if not self.px4:
                self.velocity_deadline = self.t + 3.0

    def _track_posvel(self) -> None:
        """Position + velocity target: the autopilots' position loop, v = v_ff + Kp (p_sp - p) (PX4 MPC_XY_P
        0.95, ArduPilot PSC_POSXY_P 1.0), re-evaluated every physics step."""
        pos, vel = self.posvel
        kp = 0.95 if self.px4 else 1.0
        v = vel + kp * (pos - self.veh.state.position)
        self.veh.set_velocity(tuple(float(c) for c in v), 0.0)

    def _decode_target(self, msg: Any, pos_fn: Callable[[], np.ndarray]) -> None:
        tm = msg.type_mask
        pos_ign = (tm & 0b111) == 0b111
        vel_ign = (tm & 0b111000) == 0b111000
        yaw_rate = None if tm & M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE else -math.degrees(msg.yaw_rate)
        if not pos_ign:
            vel = None if vel_ign else np.array([msg.vy, msg.vx, -msg.vz])
            self._apply_target(pos_fn(), vel, yaw_rate)
        elif not vel_ign:
            self._apply_target(None, np.array([msg.vy, msg.vx, -msg.vz]), yaw_rate)
        else:
            self._note_setpoint()

    def _on_set_position_target_global_int(self, link: _Link, msg: Any) -> None:
        frame = msg.coordinate_frame
        if frame not in _GLOBAL_FRAMES:
            return
        self._decode_target(msg, lambda: self._global_to_enu(msg.lat_int / 1e7, msg.lon_int / 1e7, msg.alt, frame))

    def _on_set_position_target_local_ned(self, link: _Link, msg: Any) -> None:
        if msg.coordinate_frame not in (M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED):
            return
        if msg.coordinate_frame == M.MAV_FRAME_LOCAL_NED:
            pos = lambda: np.array([msg.y, msg.x, -msg.z])  # noqa: E731 - NED from the EKF origin
        else:
            pos = lambda: self.veh.state.position + np.array([msg.y, msg.x, -msg.z])  # noqa: E731
        self._decode_target(msg, pos)

    # parameters
    def _param_msg(self, name: str) -> Any:
        names = list(self.params)
        return self._enc.param_value_encode(name.encode(), float(self.params[name]), M.MAV_PARAM_TYPE_REAL32,
                                            len(names), names.index(name))

    def _on_param_request_list(self, link: _Link, msg: Any) -> None:
        for name in self.params:
            self._send(self._param_msg(name), link)

    def _on_param_request_read(self, link: _Link, msg: Any) -> None:
        names = list(self.params)
        name = msg.param_id if msg.param_index < 0 else (names[msg.param_index] if msg.param_index < len(names) else "")
        if isinstance(name, bytes):
            name = name.decode(errors="replace")
        name = name.rstrip("\x00")
        if name in self.params:
            self._send(self._param_msg(name), link)

    def _on_param_set(self, link: _Link, msg: Any) -> None:
        name = msg.param_id.decode(errors="replace") if isinstance(msg.param_id, bytes) else msg.param_id
        name = name.rstrip("\x00")
        if name in self.params and math.isfinite(msg.param_value):
            self.params[name] = float(msg.param_value)
            self._send(self._param_msg(name))

    # ------------------------------------------------------------------ mission protocol (vehicle side)
    def _mission_nav_items(self) -> list[int]:
        first = 0 if self.px4 else 1
        return [i for i in range(first, len(self.mission)) if self.mission[i].command in _NAV_COMMANDS]

    def _starts_with_takeoff(self) -> bool:
        nav = self._mission_nav_items()
        return bool(nav) and self.mission[nav[0]].command == M.MAV_CMD_NAV_TAKEOFF

    def _home_item(self) -> Any:
        h = self.home or self.origin
        return self._enc.mission_item_int_encode(0, 0, 0, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                 int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), float(h.alt), 0)

    def _mission_ack(self, link: _Link, sysid: int, compid: int, result: int, mission_type: int = 0) -> None:
        self._send(self._enc.mission_ack_encode(sysid, compid, result, mission_type), link)

    def _on_mission_count(self, link: _Link, msg: Any) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if getattr(msg, "mission_type", 0) != M.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, *src, M.MAV_MISSION_UNSUPPORTED, msg.mission_type)
            return
        if msg.count == 0:
            self.mission = []
            self._transfer = None
            self._mission_ack(link, *src, M.MAV_MISSION_ACCEPTED)
            return
        if msg.count > 700:
            self._mission_ack(link, *src, M.MAV_MISSION_NO_SPACE)
            return
        self._transfer = _Transfer(link, src[0], src[1], msg.count)
        self._request_next()

    def _request_next(self) -> None:
        tr = self._transfer
        seq = len(tr.items)
        tr.deadline = self.t + _PROTOCOL_TIMEOUT_S
        request = self._enc.mission_request_int_encode if self.mission_int else self._enc.mission_request_encode
        self._send(request(tr.sysid, tr.compid, seq, 0), tr.link)

    def _check_item(self, msg: Any) -> int:
        if msg.command not in _MISSION_COMMANDS:
            return M.MAV_MISSION_UNSUPPORTED
        positional = msg.command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND,
                                     M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM)
        if msg.frame not in _MISSION_FRAMES or (positional and msg.frame == M.MAV_FRAME_MISSION
                                                and msg.command == M.MAV_CMD_NAV_WAYPOINT):
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        return M.MAV_MISSION_ACCEPTED

    def _store_item(self, link: _Link, msg: Any, is_int: bool) -> None:
        tr = self._transfer
        if tr is None or link is not tr.link:
            return
        if getattr(msg, "mission_type", 0) != M.MAV_MISSION_TYPE_MISSION:
            return
        expected = len(tr.items)
        if msg.seq != expected:
            if msg.seq > expected:  # out of order: ask again for the one we need
                self._request_next()
            return
        if not is_int:  # MISSION_ITEM (float): store as the INT form
            x, y = msg.x, msg.y
            if msg.frame in _GLOBAL_FRAMES:
                x, y = x * 1e7, y * 1e7
            msg = self._enc.mission_item_int_encode(0, 0, msg.seq, msg.frame, msg.command, msg.current,
                                                    msg.autocontinue, msg.param1, msg.param2, msg.param3, msg.param4,
                                                    int(round(x)), int(round(y)), msg.z, 0)
        if not (self.px4 is False and msg.seq == 0):  # ArduPilot's item 0 is home, whatever was sent
            res = self._check_item(msg)
            if res != M.MAV_MISSION_ACCEPTED:
                self._transfer = None
                self._mission_ack(link, tr.sysid, tr.compid, res)
                self._text(M.MAV_SEVERITY_WARNING, f"Mission item {msg.seq} rejected: command {msg.command}")
                return
        tr.items.append(msg)
        if len(tr.items) == tr.count:
            self.mission = tr.items
            if not self.px4:
                self.mission[0] = self._home_item()
            self.mission_seq = 0 if self.px4 else min(1, len(self.mission) - 1)
            self.mission_state = "idle"
            self._transfer = None
            self._mission_ack(link, tr.sysid, tr.compid, M.MAV_MISSION_ACCEPTED)
            self._text(M.MAV_SEVERITY_INFO, f"Flight plan received ({tr.count} items)")
            self._emit(M.MAVLINK_MSG_ID_MISSION_CURRENT)
        else:
            self._request_next()

    def _on_mission_item_int(self, link: _Link, msg: Any) -> None:
        self._store_item(link, msg, True)

    def _on_mission_item(self, link: _Link, msg: Any) -> None:
        self._store_item(link, msg, False)

    def _download_items(self) -> list[Any]:
        if not self.px4:
            return [self._home_item()] + list(self.mission[1:]) if self.mission else [self._home_item()]
        return list(self.mission)

    def _on_mission_request_list(self, link: _Link, msg: Any) -> None:
        if getattr(msg, "mission_type", 0) != M.MAV_MISSION_TYPE_MISSION:
            self._send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                      msg.mission_type), link)
            return
        self._send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                                  len(self._download_items()), 0), link)

    def _send_item(self, link: _Link, msg: Any, as_int: bool) -> None:
        items = self._download_items()
        if not 0 <= msg.seq < len(items):
            self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_INVALID_SEQUENCE)
            return
        it = items[msg.seq]
        cur = 1 if msg.seq == self.mission_seq else 0
        if as_int:
            out = self._enc.mission_item_int_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                    it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                    it.param4, it.x, it.y, it.z, 0)
        else:
            k = 1e-7 if it.frame in _GLOBAL_FRAMES else 1.0
            out = self._enc.mission_item_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                it.param4, it.x * k, it.y * k, it.z, 0)
        self._send(out, link)

    def _on_mission_request_int(self, link: _Link, msg: Any) -> None:
        if getattr(msg, "mission_type", 0) == M.MAV_MISSION_TYPE_MISSION:
            self._send_item(link, msg, self.mission_int)  # older firmware answers with MISSION_ITEM

    def _on_mission_request(self, link: _Link, msg: Any) -> None:
        if getattr(msg, "mission_type", 0) == M.MAV_MISSION_TYPE_MISSION:
            self._send_item(link, msg, False)

    def _on_mission_clear_all(self, link: _Link, msg: Any) -> None:
        self.mission = []
        self.mission_seq = 0
        self.mission_state = "idle"
        self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED,
                          getattr(msg, "mission_type", 0))

    def _on_mission_set_current(self, link: _Link, msg: Any) -> None:
        if 0 <= msg.seq < len(self.mission):
            self._set_current(msg.seq)

    def _set_current(self, seq: int) -> None:
        self.mission_seq = seq
        self.item_started = False
        self.item_reached_at = None
        self._emit(M.MAVLINK_MSG_ID_MISSION_CURRENT)

    def _mission_start(self, first: int) -> int:
        s = self.veh.state
        if not self._mission_nav_items():
            self._text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
            return M.MAV_RESULT_DENIED if self.px4 else M.MAV_RESULT_FAILED
        if self.px4:
            res = self._request_mode("AUTO.MISSION")  # PX4 arms for MISSION_START itself
            if res == M.MAV_RESULT_ACCEPTED and not s.armed:
                res = self._arm(False)
                if res == M.MAV_RESULT_ACCEPTED:
                    self._begin_mission()
            return res
        if not s.armed:
            self._text(M.MAV_SEVERITY_WARNING, "Mission start failed: not armed")
            return M.MAV_RESULT_FAILED
        res = self._request_mode("AUTO")
        if res != M.MAV_RESULT_ACCEPTED:
            return res
        if 0 < first < len(self.mission):
            self._set_current(first)
        self._begin_mission()
        return M.MAV_RESULT_ACCEPTED

    def _mission_logic(self) -> None:
        s = self.veh.state
        if self.mission_state != "running" or not s.armed:
            return
        if self.px4 and self.takeoff_alt is not None and not self._starts_with_takeoff():
            return  # implicit PX4 take-off first
        while self.mission_seq < len(self.mission):
            it = self.mission[self.mission_seq]
            if not self.px4 and self.mission_seq == 0:
                self._set_current(1)
                continue
            if it.command == M.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0:
                    self.speed = float(it.param2)
                elif it.param2 == -2:
                    self.speed = None
                self._advance()
                continue
            break
        if self.mission_seq >= len(self.mission):
            self._mission_done()
            return
        it = self.mission[self.mission_seq]
        cmd = it.command
        if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM):
            if it.x == 0 and it.y == 0:
                g = self._geo()
                lat, lon = g.lat, g.lon
            else:
                lat, lon = it.x / 1e7, it.y / 1e7
            target = self._global_to_enu(lat, lon, it.z, it.frame)
            if not self.item_started:
                self.item_started = True
                self._goto_enu(target)
            radius = self.params["NAV_ACC_RAD"] if self.px4 else self.params["WPNAV_RADIUS"] / 100.0
            if self.px4 and cmd == M.MAV_CMD_NAV_WAYPOINT and it.param2 > 0:
                radius = it.param2
            d_h = math.hypot(*(target[:2] - s.position[:2]))
            d_v = abs(target[2] - s.position[2])
            if self.item_reached_at is None and d_h <= radius and d_v <= 1.0:
                self.item_reached_at = self.t
                self._reached(self.mission_seq)
            if self.item_reached_at is not None:
                hold = it.param1 if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) else math.inf
                if self.t - self.item_reached_at >= hold:
                    self._advance()
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            alt = self._global_to_enu(self.origin.lat, self.origin.lon, it.z, it.frame)[2] - self.home_enu[2]
            if not self.item_started:
                self.item_started = True
                if self._rel()[2] < alt - 0.1:
                    self._start_takeoff(alt)
            if self.takeoff_alt is None or abs(self._rel()[2] - alt) < 0.1:
                self.takeoff_alt = None
                self._reached(self.mission_seq)
                self._advance()
        elif cmd == M.MAV_CMD_NAV_LAND:
            if not self.item_started:
                self.item_started = True
                if not (it.x == 0 and it.y == 0):
                    self.phase = ""
                    self._land_target = self._global_to_enu(it.x / 1e7, it.y / 1e7, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT)
                    self._land_target[2] = s.position[2]
                    self._goto_enu(self._land_target)
                else:
                    self._start_land()
            if self.veh.setpoint.mode == "position" and math.hypot(*(self.veh.setpoint.target[0] - s.position[0],
                                                                    self.veh.setpoint.target[1] - s.position[1])) < 0.3:
                self._start_land()
            if not s.in_air and self.took_off:
                self._reached(self.mission_seq)
                self._advance()
        elif cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._reached(self.mission_seq)
            self._advance()
            self._enter("AUTO.RTL" if self.px4 else "RTL")

    def _reached(self, seq: int) -> None:
        self.reached_log.append(seq)
        self._send(self._enc.mission_item_reached_encode(seq))

    def _advance(self) -> None:
        self._set_current(self.mission_seq + 1)

    def _mission_done(self) -> None:
        self.mission_state = "done"
        self._text(M.MAV_SEVERITY_INFO, "Mission: complete" if not self.px4 else "Mission finished")
        self.mission_seq = max(0, len(self.mission) - 1)
        if self.px4 and self.mode == "AUTO.MISSION" and self.veh.state.in_air:
            self._enter("AUTO.LOITER")
        elif self.veh.state.in_air:
            self.veh.hold()

    # ------------------------------------------------------------------ streams
    def _stream(self) -> None:
        if self.t >= self._next_hb:
            self._next_hb = self.t + 1.0
            self._emit(M.MAVLINK_MSG_ID_HEARTBEAT)
        for cmd, (link, sysid, compid, due, pct) in list(self._in_progress.items()):
            if link not in self._links:
                del self._in_progress[cmd]
            elif self.t >= due:  # COMMAND_ACK.progress creeps towards 99 %, never done
                pct = min(99, pct + 1)
                self._in_progress[cmd] = (link, sysid, compid, self.t + _IN_PROGRESS_PERIOD_S, pct)
                self._send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_IN_PROGRESS, pct, 0, sysid, compid), link)
        if self._transfer is not None and self.t > self._transfer.deadline:
            tr = self._transfer
            tr.retries += 1
            if tr.retries > _PROTOCOL_RETRIES or tr.link not in self._links:
                self._transfer = None
                self._mission_ack(tr.link, tr.sysid, tr.compid, M.MAV_MISSION_OPERATION_CANCELLED)
            else:
                self._request_next()
        for mid, interval in list(self._intervals.items()):
            due = self._next_due.get(mid, 0.0)
            if self.t >= due:
                self._next_due[mid] = max(due + interval, self.t)
                self._emit(mid)

    def _emit(self, msg_id: int) -> None:
        msg = self._build(msg_id)
        if msg is not None:
            self._send(msg)

    def _build(self, msg_id: int) -> Any | None:
        """The message ``msg_id`` for the current state, or None when the vehicle has none to send."""
        e, s = self._enc, self.veh.state
        boot_ms = int(self.boot_ms0 + self.t * 1000.0) & 0xFFFFFFFF
        fix = self._fix_type()
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            base, custom = self._mode_number()
            if self.px4:
                status = M.MAV_STATE_ACTIVE if s.armed else M.MAV_STATE_STANDBY
            else:
                status = M.MAV_STATE_ACTIVE if s.in_air else M.MAV_STATE_STANDBY
            ap = M.MAV_AUTOPILOT_PX4 if self.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
            return e.heartbeat_encode(M.MAV_TYPE_QUADROTOR, ap, base, custom, status, 3)
        if msg_id == M.MAVLINK_MSG_ID_SYS_STATUS:
            health = _SENSORS
            if fix < 3:
                health &= ~(M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS)
            if self._prearm() is not None:
                health &= ~M.MAV_SYS_STATUS_PREARM_CHECK
            return e.sys_status_encode(_SENSORS, _SENSORS, health, 250, int(self.veh.battery_voltage * 1000), -1,
                                       int(round(self.veh.battery_pct)), 0, 0, 0, 0, 0, 0)
        if msg_id == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return e.system_time_encode(int((1.7e9 + self.t) * 1e6), boot_ms)
        if msg_id == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            g = self._geo()
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            lat, lon = (int(round(g.lat * 1e7)), int(round(g.lon * 1e7))) if fix >= 3 else (0, 0)
            return e.gps_raw_int_encode(int(self.t * 1e6), fix, lat, lon, int(g.alt * 1000), 80 if fix >= 3 else 9999,
                                        120 if fix >= 3 else 9999, int(v * 100), 0, 12 if fix >= 3 else 3)
        if msg_id == M.MAVLINK_MSG_ID_ATTITUDE:
            return e.attitude_encode(boot_ms, 0.0, float(np.clip(s.velocity[1] * 0.05, -0.4, 0.4)),
                                     math.radians(self._heading()) if self._heading() <= 180 else
                                     math.radians(self._heading() - 360.0), 0.0, 0.0, 0.0)
        if msg_id == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            if fix < 3:
                if self.px4:
                    return None
                return e.global_position_int_encode(boot_ms, 0, 0, 0, 0, 0, 0, 0, 65535)  # ArduPilot: stale zeros
            g, rel = self._geo(), self._rel()
            vn, ve, vd = s.velocity[1], s.velocity[0], -s.velocity[2]
            return e.global_position_int_encode(boot_ms, int(round(g.lat * 1e7)), int(round(g.lon * 1e7)),
                                                int(round(g.alt * 1000)), int(round(rel[2] * 1000)), int(vn * 100),
                                                int(ve * 100), int(vd * 100), int(self._heading() * 100) % 36000)
        if msg_id == M.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            if fix < 3:
                return None
            p, v = s.position, s.velocity
            return e.local_position_ned_encode(boot_ms, float(p[1]), float(p[0]), float(-p[2]), float(v[1]),
                                               float(v[0]), float(-v[2]))
        if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION:
            if self.home is None:
                return None
            h = self.home
            hx = self.home_enu
            return e.home_position_encode(int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), int(round(h.alt * 1000)),
                                          float(hx[1]), float(hx[0]), float(-hx[2]), [1, 0, 0, 0], 0, 0, 0,
                                          int(self.t * 1e6))
        if msg_id == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            if not s.in_air:
                landed = M.MAV_LANDED_STATE_ON_GROUND
            elif self.veh.setpoint.mode == "land":
                landed = M.MAV_LANDED_STATE_LANDING
            elif self.takeoff_alt is not None:
                landed = M.MAV_LANDED_STATE_TAKEOFF
            else:
                landed = M.MAV_LANDED_STATE_IN_AIR
            return e.extended_sys_state_encode(M.MAV_VTOL_STATE_UNDEFINED, landed)
        if msg_id == M.MAVLINK_MSG_ID_BATTERY_STATUS:
            mv = int(self.veh.battery_voltage * 1000)
            cells = [mv] + [65535] * 9
            return e.battery_status_encode(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, cells, -1, -1,
                                           -1, int(round(self.veh.battery_pct)))
        if msg_id == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            return e.mission_current_encode(self.mission_seq, len(self.mission), 0, 0)
        if msg_id == M.MAVLINK_MSG_ID_VFR_HUD:
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            return e.vfr_hud_encode(v, v, int(self._heading()), 50 if s.in_air else 0, float(self._geo().alt),
                                    float(s.velocity[2]))
        if msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            caps = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
            version = (1 << 24) | (15 << 16) if self.px4 else (4 << 24) | (5 << 16)
            return e.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)
        return None

    def _heading(self) -> float:
        """Compass heading in degrees (clockwise from north) from the simulator's ENU yaw."""
        return (90.0 - self.veh.state.yaw) % 360.0
