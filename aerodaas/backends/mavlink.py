"""MAVLink autopilots (ArduPilot Copter, PX4 multicopter) as a vehicle backend, through pymavlink.

One background I/O thread reads every message (pymavlink parses; unknown ids, bad CRCs and duplicates from
several captured links are skipped, never raised), keeps the state, sends our GCS HEARTBEAT at 1 Hz, re-sends the
active position/velocity target at ``setpoint_rate_hz`` in the *vehicle's* time (so an emulator running K times
faster than real time still sees PX4's required > 2 Hz offboard stream) and watches the autopilot's HEARTBEAT for
link loss. The control thread sends commands and waits for their acknowledgements.

Protocols (mavlink.io): heartbeat/connection, command protocol (COMMAND_LONG -> COMMAND_ACK with retries and the
``confirmation`` counter), message intervals (MAV_CMD_SET_MESSAGE_INTERVAL, else the deprecated
REQUEST_DATA_STREAM), offboard control (SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED with
POSITION_TARGET_TYPEMASK), the mission protocol (MISSION_COUNT / MISSION_REQUEST_INT / MISSION_ITEM_INT /
MISSION_ACK, both directions). Mode numbers are pymavlink's tables (``mavutil.mode_mapping_byname`` for
ArduPilot, ``mavutil.px4_map`` for PX4 main/sub modes).

Flavour differences handled here: ArduPilot flies targets in GUIDED, PX4 in OFFBOARD (entered only after the
setpoint stream runs); MAV_CMD_NAV_TAKEOFF ``param7`` is metres above home on ArduPilot and metres above mean sea
level on PX4; ArduPilot missions carry home at sequence 0.
"""
from __future__ import annotations

import logging
import math
import queue
import struct
import threading
import time
from collections import deque
from typing import Any, Callable, Literal, Sequence

import numpy as np

from ..config import MavlinkConfig
from ..geo import enu_to_geodetic, geodetic_to_enu
from ..missionfile import MissionItem, MissionPlan, expand_items, navigation_to_plan
from ..models import ActionCommand, AeroNavigation, Attitude, GeoPoint, NavigationType, Odometry, SchedulingType, Waypoint
from .base import BackendError, CommandRefused, LinkLost, VehicleBackend

__all__ = ["MavlinkBackend", "CommandNotConfirmed"]

#: STATUSTEXT lines are logged here (``robot: text``), at the level of their MAV_SEVERITY
log = logging.getLogger("aerodaas.mavlink")

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M  # constants and enum names

#: MAV_TYPE values that are not vehicles (ground stations, companions, peripherals)
_NOT_VEHICLES = {M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_TYPE_GIMBAL, M.MAV_TYPE_ADSB,
                 M.MAV_TYPE_CAMERA, M.MAV_TYPE_CHARGING_STATION, M.MAV_TYPE_FLARM, M.MAV_TYPE_SERVO,
                 M.MAV_TYPE_ODID, M.MAV_TYPE_ANTENNA_TRACKER}
_MULTIROTORS = {M.MAV_TYPE_QUADROTOR, M.MAV_TYPE_COAXIAL, M.MAV_TYPE_HEXAROTOR, M.MAV_TYPE_OCTOROTOR,
                M.MAV_TYPE_TRICOPTER, M.MAV_TYPE_DODECAROTOR, M.MAV_TYPE_HELICOPTER, M.MAV_TYPE_DECAROTOR}
_AP_ARM_MODES = {"GUIDED", "LOITER", "STABILIZE", "ALT_HOLD", "POSHOLD", "BRAKE"}
_PX4_NO_ARM_MODES = {"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED", "RATTITUDE", "RTL", "LAND"}
# POSITION_TARGET_TYPEMASK: bits set = ignored
_IGNORE_POS = 0b111
_IGNORE_VEL = 0b111000
_IGNORE_ACC = 0b111000000
_IGNORE_YAW = 1024
_IGNORE_YAW_RATE = 2048
POSITION_ONLY_MASK = _IGNORE_VEL | _IGNORE_ACC | _IGNORE_YAW | _IGNORE_YAW_RATE
VELOCITY_ONLY_MASK = _IGNORE_POS | _IGNORE_ACC | _IGNORE_YAW  # yaw rate is used
POSITION_VELOCITY_MASK = _IGNORE_ACC | _IGNORE_YAW | _IGNORE_YAW_RATE  # velocity as feed-forward
_GLOBAL_FRAMES = {0, 3, 5, 6, 10, 11}
_TELEMETRY = ((M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, None), (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, None),
              (M.MAVLINK_MSG_ID_ATTITUDE, None), (M.MAVLINK_MSG_ID_SYS_STATUS, 2.0), (M.MAVLINK_MSG_ID_GPS_RAW_INT, 2.0),
              (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 2.0), (M.MAVLINK_MSG_ID_BATTERY_STATUS, 1.0),
              (M.MAVLINK_MSG_ID_HOME_POSITION, 0.5), (M.MAVLINK_MSG_ID_MISSION_CURRENT, 1.0),
              (M.MAVLINK_MSG_ID_SYSTEM_TIME, 1.0))
_LEGACY_STREAMS = ((M.MAV_DATA_STREAM_EXTENDED_STATUS, 2.0), (M.MAV_DATA_STREAM_POSITION, None),
                   (M.MAV_DATA_STREAM_EXTRA1, None), (M.MAV_DATA_STREAM_EXTRA3, 1.0))
#: STATUSTEXT.text is char[50]; a MAVLink 2 chunk shorter than that (NUL-terminated) ends a long text
_STATUSTEXT_LEN = 50
#: wall seconds after its first chunk that a long STATUSTEXT whose last chunk never came is emitted as it is
_STATUSTEXT_FLUSH_S = 0.5
#: wall seconds to wait before re-sending a command answered MAV_RESULT_TEMPORARILY_REJECTED (at most the timeout)
_REJECTED_BACKOFF_S = 0.5


class CommandNotConfirmed(BackendError):
    """The autopilot acknowledged a command (COMMAND_ACK MAV_RESULT_ACCEPTED) but no HEARTBEAT showed its effect
    (the requested mode, or the armed flag) within the bounded wait. ``expected`` is what was asked (e.g.
    ``"mode GUIDED"``, ``"armed"``), ``observed`` what the latest HEARTBEAT shows, ``waited_s`` the wait in wall
    seconds, ``status_text`` the autopilot's latest STATUSTEXT since the command (may be empty)."""

    def __init__(self, robot_id: str, command: str, expected: str, observed: str, waited_s: float,
                 status_text: str = "") -> None:
        self.robot_id, self.command, self.expected, self.observed = robot_id, command, expected, observed
        self.waited_s, self.status_text = waited_s, status_text
        why = f" ({status_text})" if status_text else ""
        super().__init__(f"robot {robot_id!r}: {command}: acknowledged (MAV_RESULT_ACCEPTED) but no HEARTBEAT showed "
                         f"{expected} within {waited_s:g} s; the HEARTBEAT shows {observed}{why}")

    def __reduce__(self):  # picklable across Ray workers
        return (CommandNotConfirmed, (self.robot_id, self.command, self.expected, self.observed, self.waited_s,
                                      self.status_text))


def _log_level(severity: int) -> int:
    """The :mod:`logging` level of a MAV_SEVERITY (0 EMERGENCY .. 7 DEBUG)."""
    if severity <= M.MAV_SEVERITY_CRITICAL:
        return logging.CRITICAL
    return {M.MAV_SEVERITY_ERROR: logging.ERROR, M.MAV_SEVERITY_WARNING: logging.WARNING,
            M.MAV_SEVERITY_DEBUG: logging.DEBUG}.get(severity, logging.INFO)


def _enum_name(enum: str, value: int) -> str:
    e = M.enums.get(enum, {}).get(value)
    return e.name if e is not None else f"{enum} {value}"


def _f32(v: float | None) -> float | None:
    """Round a parameter to what a float32 MAVLink field carries; NaN/None stay None."""
    if v is None or v != v:
        return None
    return struct.unpack("<f", struct.pack("<f", float(v)))[0]


class MavlinkBackend(VehicleBackend):
    """An ArduPilot Copter or PX4 multicopter reached over MAVLink (settings: :class:`~aerodaas.config.MavlinkConfig`).

    ``clock == "vehicle"``: :attr:`t` is the autopilot's ``time_boot_ms`` (seconds since :meth:`connect`), wall time
    until a timestamped message arrives; while the link is lost it runs on from the last sample at the measured
    vehicle/wall rate (so the runtime's control ticks, and its LINK_LOST state, go on). Positions are ENU metres from the vehicle's HOME_POSITION (the configured
    home until the vehicle reports one). Besides the :class:`VehicleBackend` contract it offers
    :meth:`upload_mission`, :meth:`download_mission`, :meth:`start_mission`, :meth:`clear_mission`,
    :meth:`set_mode` and the attributes :attr:`autopilot` (``"ardupilot"``/``"px4"``), :attr:`mode`,
    :attr:`gps_fix_type`, :attr:`command_rtt_ms` (acknowledged command round trips, wall milliseconds).
    Every STATUSTEXT becomes a ``status_text`` event and a log line on the ``aerodaas.mavlink`` logger
    (``"<robot>: <text>"``; MAV_SEVERITY EMERGENCY-CRITICAL -> CRITICAL, ERROR, WARNING, NOTICE/INFO -> INFO,
    DEBUG).

    Raises :class:`BackendError` (connection, protocol timeouts), :class:`CommandRefused` (MAV_RESULT /
    MAV_MISSION_RESULT name and the autopilot's latest STATUSTEXT), :class:`CommandNotConfirmed` (a mode change or
    arming acknowledged but never shown by the HEARTBEAT) and :class:`LinkLost` (no HEARTBEAT for
    ``heartbeat_timeout_s``: commands fail at once instead of blocking).
    """

    kind = "mavlink"
    clock = "vehicle"

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        super().__init__(cfg.id, cfg.home)
        self.cfg: MavlinkConfig = cfg.mavlink or MavlinkConfig()
        self.config_home: GeoPoint = cfg.home
        self.autopilot: Literal["ardupilot", "px4"] | None = None
        self.vehicle_type: str = ""
        self.command_rtt_ms: list[float] = []
        #: every message the receive path saw, unknown and malformed ones included
        self.messages_received = 0
        self._conn: Any = None
        self._sysid = self._compid = 0
        self._lock = threading.RLock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._io: threading.Thread | None = None
        self._io_error: BaseException | None = None
        self._events: deque[dict[str, Any]] = deque(maxlen=2000)
        self._acks: queue.Queue = queue.Queue()
        self._mission_q: queue.Queue = queue.Queue()
        self._mission_active = False
        self._recent: deque[tuple] = deque(maxlen=32)  # (sys, comp, seq, msgid, crc) for duplicate packets
        self._texts: deque[tuple[float, int, str]] = deque(maxlen=50)
        #: long STATUSTEXTs being reassembled: (component, id) -> {"t": first chunk, "severity", "parts": {seq: text}}
        self._chunks: dict[tuple[int, int], dict[str, Any]] = {}
        self._ap_modes: dict[str, int] = {}
        # state (guarded by _lock)
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._att = (0.0, 0.0, 90.0)  # roll, pitch deg; yaw ENU deg
        self._geo: GeoPoint | None = None
        self._rel_alt = 0.0
        self._has_global = False
        self._local_ned: tuple[float, ...] | None = None
        self._local_wall = 0.0
        self._armed = False
        self._mode = ""
        self._system_status = 0
        self._landed_state = 0
        self._landed_wall = 0.0
        self._battery: float | None = None
        self._battery_v = 0.0
        self._gps_fix = -1
        self._sensors: tuple[int, int, int] | None = None
        self._home_received = False
        self._mission_seq = -1
        self._last_reached: tuple[int, float] = (-1, 0.0)
        self._link_ok = False
        self._last_hb = 0.0
        self._wall0 = time.monotonic()
        self._boot_ref: tuple[int, float] | None = None  # (time_boot_ms, vehicle seconds at that sample)
        self._boot_last = 0
        self._boot_wall = 0.0  # wall (monotonic) time of the latest time_boot_ms sample
        self._t_connect = 0.0
        self._ratio = 1.0
        self._clock_samples: deque[tuple[float, int]] = deque()
        self._t_max = 0.0
        # outgoing
        self._setpoint: tuple | None = None
        self._sp_sent = 0
        self._sp_next = 0.0
        self._hb_next = 0.0
        self._speed_cmd: float | None = None
        self._stream_legacy = False
        self._ever_linked = False
        self._resume_streams = False
        self._att_wall = 0.0

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float | None = None) -> None:
        """Open ``mavlink.connection``, wait for the autopilot's HEARTBEAT (GCS and peripheral heartbeats are
        ignored), identify it, start the I/O thread, request the telemetry streams and HOME_POSITION, and wait
        for the first SYS_STATUS. Raises :class:`BackendError` after ``timeout_s`` (default
        ``connect_timeout_s``) seconds, naming the connection string; ValueError for a vehicle that is not a
        multirotor or an autopilot that cannot be identified."""
        timeout = self.cfg.connect_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        where = f"robot {self.robot_id!r}: mavlink connection {self.cfg.connection!r}"
        last_err: Exception | None = None
        while self._conn is None:
            try:
                self._conn = mavutil.mavlink_connection(
                    self.cfg.connection, baud=self.cfg.baud, source_system=self.cfg.source_system,
                    source_component=self.cfg.source_component, dialect="ardupilotmega", autoreconnect=True,
                    retries=0 if self.cfg.connection.startswith("tcp:") else 3)
            except Exception as e:  # noqa: BLE001 - refused, no such device: retry until the deadline
                last_err = e
                if time.monotonic() > deadline:
                    raise BackendError(f"{where}: cannot open it within {timeout:g} s: {e}") from None
                time.sleep(0.2)
        hb = None
        next_hb = 0.0
        while hb is None:
            now = time.monotonic()
            if now > deadline:
                self.close()
                raise BackendError(f"{where}: no autopilot HEARTBEAT within {timeout:g} s"
                                   + (f" (last error: {last_err})" if last_err else ""))
            if now >= next_hb:  # udpout: the vehicle learns our address from what we send
                self._send_gcs_heartbeat()
                next_hb = now + 1.0
            try:
                msg = self._conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
            except Exception as e:  # noqa: BLE001
                last_err = e
                time.sleep(0.05)
                continue
            if msg is not None and self._is_autopilot_heartbeat(msg):
                hb = msg
        self._identify(hb)
        self._conn.target_system, self._conn.target_component = self._sysid, self._compid
        self._on_heartbeat(hb, time.monotonic())
        self._stop.clear()
        self._io = threading.Thread(target=self._io_loop, name=f"mavlink-{self.robot_id}", daemon=True)
        self._io.start()
        self._request_streams()
        self._request_home()
        while True:
            with self._lock:
                ready = self._sensors is not None
            if ready:
                break
            if time.monotonic() > deadline:
                self.close()
                raise BackendError(f"{where}: the autopilot sent HEARTBEAT but no SYS_STATUS within {timeout:g} s "
                                   "(telemetry streams not configured?)")
            time.sleep(0.01)
        with self._lock:
            self._t_connect = self._raw_t()
            self._t_max = 0.0

    def close(self) -> None:
        """Stop the I/O thread and close the link (idempotent, never raises)."""
        self._stop.set()
        if self._io is not None and self._io is not threading.current_thread():
            self._io.join(timeout=2)
        self._io = None
        if self._conn is not None:
            try:
                self._conn.close()
            except Exception:  # noqa: BLE001
                pass
            self._conn = None

    def _is_autopilot_heartbeat(self, msg: Any) -> bool:
        if msg.get_srcSystem() == self.cfg.source_system and msg.get_srcComponent() == self.cfg.source_component:
            return False
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.type in _NOT_VEHICLES:
            return False
        return self.cfg.target_system is None or msg.get_srcSystem() == self.cfg.target_system

    def _identify(self, hb: Any) -> None:
        found = {M.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot", M.MAV_AUTOPILOT_PX4: "px4"}.get(hb.autopilot)
        flavour = found if self.cfg.autopilot == "auto" else self.cfg.autopilot
        self.vehicle_type = _enum_name("MAV_TYPE", hb.type)
        if flavour is None:
            self.close()
            raise ValueError(f"robot {self.robot_id!r}: mavlink.autopilot is 'auto' but the HEARTBEAT says "
                             f"{_enum_name('MAV_AUTOPILOT', hb.autopilot)}; set mavlink.autopilot to 'ardupilot' "
                             "or 'px4'")
        if hb.type not in _MULTIROTORS:
            self.close()
            raise ValueError(f"robot {self.robot_id!r}: the vehicle is a {self.vehicle_type}; the MAVLink backend "
                             "flies multirotors only (mode numbers and guidance differ for planes and rovers)")
        if found is not None and found != flavour:
            self._event("autopilot_mismatch", configured=flavour, heartbeat=found)
        self.autopilot = flavour
        self._sysid, self._compid = hb.get_srcSystem(), hb.get_srcComponent()
        if flavour == "ardupilot":
            self._ap_modes = mavutil.mode_mapping_byname(hb.type) or dict(
                (v, k) for k, v in mavutil.mode_mapping_acm.items())
        self._event("connected", autopilot=flavour, vehicle_type=self.vehicle_type, system=self._sysid,
                    component=self._compid)

    # ------------------------------------------------------------------ I/O thread
    def _io_loop(self) -> None:
        conn = self._conn
        while not self._stop.is_set():
            try:
                msg = conn.recv_msg()
            except Exception:  # noqa: BLE001 - a broken packet or a socket hiccup: keep going
                msg = None
                time.sleep(0.01)
            now = time.monotonic()
            if msg is not None:
                try:
                    self._dispatch(msg, now)
                except Exception as e:  # noqa: BLE001 - a malformed message must never stop telemetry
                    self._event("receive_error", message=msg.get_type(), error=str(e))
            try:
                self._periodic(now)
            except Exception as e:  # noqa: BLE001
                self._io_error = e
            if msg is None:
                try:
                    conn.select(0.005)
                except Exception:  # noqa: BLE001
                    time.sleep(0.005)

    def _dispatch(self, msg: Any, now: float) -> None:
        mtype = msg.get_type()
        self.messages_received += 1
        if mtype == "BAD_DATA" or mtype.startswith("UNKNOWN_"):
            return
        key = (msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq(), msg.get_msgId(), getattr(msg, "_crc", 0))
        if key in self._recent:
            return  # the same packet again (captured on two links)
        self._recent.append(key)
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        if self._sysid and src_sys != self._sysid:
            return
        if mtype == "HEARTBEAT":
            if src_comp == self._compid and self._is_autopilot_heartbeat(msg):
                self._on_heartbeat(msg, now)
            return
        if mtype == "STATUSTEXT":
            self._on_statustext(msg, now)
            return
        if self._compid and src_comp != self._compid:
            return
        if mtype == "COMMAND_ACK":
            if getattr(msg, "target_system", 0) in (0, self.cfg.source_system):
                self._acks.put((now, msg))
            return
        if mtype in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT", "MISSION_ITEM_INT",
                     "MISSION_ITEM"):
            if self._mission_active and getattr(msg, "target_system", 0) in (0, self.cfg.source_system):
                self._mission_q.put(msg)
            return
        handler = getattr(self, f"_on_{mtype.lower()}", None)
        if handler is not None:
            with self._lock:
                handler(msg)

    def _on_statustext(self, msg: Any, now: float) -> None:
        """STATUSTEXT (common.xml): ``id`` 0 is a complete text; a non-zero ``id`` marks chunks of one long text
        (MAVLink 2 extensions ``id``, ``chunk_seq`` from 0), ended by a chunk shorter than the 50-byte field
        (pymavlink cuts the text at its NUL) or, if that one is lost, by :data:`_STATUSTEXT_FLUSH_S`. Chunks are
        joined as bytes and decoded (UTF-8) once whole, so a character split across two chunks survives."""
        raw = msg.text if isinstance(msg.text, bytes) else str(msg.text).encode("utf-8", errors="replace")
        raw = raw.split(b"\x00", 1)[0]
        sid = getattr(msg, "id", 0) or 0
        if not sid:
            self._emit_text(now, msg.severity, raw.decode("utf-8", errors="replace"))
            return
        key = (msg.get_srcComponent(), sid)
        buf = self._chunks.get(key)
        seq = getattr(msg, "chunk_seq", 0) or 0
        if buf is not None and seq in buf["parts"]:  # the id came round again: the old text lost its last chunk
            self._flush_text(key)
            buf = None
        if buf is None:
            buf = self._chunks[key] = {"t": now, "severity": msg.severity, "parts": {}}
        buf["parts"][seq] = raw
        if len(raw) < _STATUSTEXT_LEN:
            self._flush_text(key)

    def _flush_text(self, key: tuple[int, int]) -> None:
        buf = self._chunks.pop(key, None)
        if buf is not None:
            whole = b"".join(buf["parts"][k] for k in sorted(buf["parts"]))
            self._emit_text(buf["t"], buf["severity"], whole.decode("utf-8", errors="replace"))

    def _emit_text(self, t: float, severity: int, text: str) -> None:
        """One whole status text: kept for :class:`CommandRefused`, a ``status_text`` event and a log line."""
        text = text.strip()
        self._texts.append((t, severity, text))
        self._event("status_text", severity=_enum_name("MAV_SEVERITY", severity), text=text)
        log.log(_log_level(severity), "%s: %s", self.robot_id, text)

    def _on_heartbeat(self, msg: Any, now: float) -> None:
        with self._lock:
            self._last_hb = now
            if not self._link_ok:
                self._link_ok = True
                if self._ever_linked:
                    self._event("link_regained")
                    self._resume_streams = True
                self._ever_linked = True
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            if armed != self._armed:
                self._armed = armed
                self._event("armed" if armed else "disarmed")
            mode = mavutil.mode_string_v10(msg)
            if mode != self._mode:
                self._mode = mode
                self._event("mode", name=mode)
            self._system_status = msg.system_status

    def _on_boot_ms(self, ms: int) -> None:
        now = time.monotonic()
        if self._boot_ref is None or ms + 5000 < self._boot_last:  # first sample, or the autopilot rebooted
            if self._boot_ref is not None:
                self._event("vehicle_rebooted")
            self._boot_ref = (ms, self._raw_t())
            self._clock_samples.clear()
        self._boot_last = max(ms, self._boot_last) if self._boot_ref[0] <= ms else ms
        self._boot_wall = now
        # vehicle seconds per wall second over the last few seconds (an emulator may run K times faster)
        samples = self._clock_samples
        samples.append((now, ms))
        while len(samples) > 2 and now - samples[0][0] > 5.0:
            samples.popleft()
        span = now - samples[0][0]
        if span >= 0.2:
            r = (ms - samples[0][1]) / 1000.0 / span
            if 0.05 < r < 200:
                self._ratio = r

    def _raw_t(self) -> float:
        if self._boot_ref is None:
            return time.monotonic() - self._wall0
        return self._boot_ref[1] + (self._boot_last - self._boot_ref[0]) / 1000.0

    def _on_global_position_int(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        if msg.lat == 0 and msg.lon == 0:
            return  # ArduPilot sends zeros before its position estimate exists
        lat, lon = msg.lat / 1e7, msg.lon / 1e7
        self._geo = GeoPoint(lat=lat, lon=lon, alt=msg.alt / 1000.0)
        self._rel_alt = msg.relative_alt / 1000.0
        e, n, _ = geodetic_to_enu(lat, lon, self.home.alt, self.home)
        self._pos = np.array([e, n, self._rel_alt])
        self._has_global = True
        if time.monotonic() - self._local_wall > 1.0:  # no fresher LOCAL_POSITION_NED velocity
            self._vel = self.ned_to_enu((msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0))
        if msg.hdg != 65535 and time.monotonic() - self._att_wall > 1.0:  # no ATTITUDE lately
            self._att = (self._att[0], self._att[1], self.enu_yaw_from_heading(msg.hdg / 100.0))

    def _on_local_position_ned(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._local_ned = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        self._local_wall = time.monotonic()
        self._vel = self.ned_to_enu((msg.vx, msg.vy, msg.vz))
        if not self._has_global:  # no global position (indoors): ENU from the EKF origin
            self._pos = self.ned_to_enu((msg.x, msg.y, msg.z))

    def _on_attitude(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._att = (math.degrees(msg.roll), math.degrees(msg.pitch), self.enu_yaw_from_heading(math.degrees(msg.yaw)))
        self._att_wall = time.monotonic()

    def _on_system_time(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)

    def _on_sys_status(self, msg: Any) -> None:
        self._sensors = (msg.onboard_control_sensors_present, msg.onboard_control_sensors_enabled,
                         msg.onboard_control_sensors_health)
        if msg.battery_remaining >= 0 and self._battery_from != "BATTERY_STATUS":
            self._battery = float(msg.battery_remaining)
            self._battery_from = "SYS_STATUS"
        if msg.voltage_battery not in (0, 65535):
            self._battery_v = msg.voltage_battery / 1000.0

    _battery_from = ""

    def _on_battery_status(self, msg: Any) -> None:
        if msg.id != 0:
            return
        if msg.battery_remaining >= 0:
            self._battery = float(msg.battery_remaining)
            self._battery_from = "BATTERY_STATUS"
        cells = [v for v in msg.voltages if v not in (65535, 0)]
        if cells and not self._battery_v:
            self._battery_v = sum(cells) / 1000.0

    def _on_gps_raw_int(self, msg: Any) -> None:
        self._gps_fix = msg.fix_type

    def _on_extended_sys_state(self, msg: Any) -> None:
        self._landed_state = msg.landed_state
        self._landed_wall = time.monotonic()

    def _on_home_position(self, msg: Any) -> None:
        home = GeoPoint(lat=msg.latitude / 1e7, lon=msg.longitude / 1e7, alt=msg.altitude / 1000.0)
        old = self.home
        moved = (not self._home_received or abs(home.lat - old.lat) > 1e-7 or abs(home.lon - old.lon) > 1e-7
                 or abs(home.alt - old.alt) > 0.01)
        if moved:
            self.home = home
            self._home_received = True
            if self._geo is not None:  # re-express the last fix in the new frame
                e, n, _ = geodetic_to_enu(self._geo.lat, self._geo.lon, home.alt, home)
                self._pos = np.array([e, n, self._rel_alt])
            self._event("home", lat=home.lat, lon=home.lon, alt=home.alt)

    def _on_mission_current(self, msg: Any) -> None:
        if msg.seq != self._mission_seq:
            self._mission_seq = msg.seq
            self._event("mission_current", seq=msg.seq, item=self._item_number(msg.seq))

    def _item_number(self, wire_seq: int) -> int:
        """The :class:`MissionItem` ``seq`` (from 1, as :meth:`upload_mission` returns) of a wire sequence number:
        ArduPilot's wire numbering already starts at 1 (home is 0), PX4's at 0."""
        return wire_seq if self.autopilot == "ardupilot" else wire_seq + 1

    def _on_mission_item_reached(self, msg: Any) -> None:
        now = time.monotonic()
        if self._last_reached[0] == msg.seq and now - self._last_reached[1] < 1.0:
            return
        self._last_reached = (msg.seq, now)
        self._event("mission_item_reached", seq=msg.seq, item=self._item_number(msg.seq))

    def _periodic(self, now: float) -> None:
        for key, buf in list(self._chunks.items()):
            if now - buf["t"] > _STATUSTEXT_FLUSH_S:
                self._flush_text(key)
        if now >= self._hb_next:
            self._hb_next = now + 1.0 / max(1.0, min(self._ratio, 20.0))
            self._send_gcs_heartbeat()
        with self._lock:
            if self._link_ok and now - self._last_hb > self.cfg.heartbeat_timeout_s:
                self._link_ok = False
                self._event("link_lost", silent_s=round(now - self._last_hb, 3))
            resume = self._resume_streams
            self._resume_streams = False
            sp = self._setpoint if self._link_ok else None
        if resume:
            self._request_streams(wait=False)
        if sp is not None and now >= self._sp_next:
            rate = self.cfg.setpoint_rate_hz if sp[0] == "vel" or self.autopilot == "px4" else 1.0
            self._sp_next = now + max(0.004, 1.0 / (rate * self._ratio))
            self._send_setpoint(sp)

    # ------------------------------------------------------------------ sending
    def _send(self, fn: Callable[[Any], None]) -> None:
        conn = self._conn
        if conn is None:
            raise LinkLost(f"robot {self.robot_id!r}: not connected")
        with self._send_lock:
            try:
                fn(conn.mav)
            except OSError as e:
                raise LinkLost(f"robot {self.robot_id!r}: send failed: {e}") from None

    def _send_gcs_heartbeat(self) -> None:
        try:
            self._send(lambda mav: mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                                      M.MAV_STATE_ACTIVE))
        except (LinkLost, Exception):  # noqa: BLE001 - the link may be down; the heartbeat watch reports it
            pass

    def _boot_ms_out(self) -> int:
        return int((time.monotonic() - self._wall0) * 1000) & 0xFFFFFFFF

    def _carrot(self, sp: tuple) -> tuple:
        """A speed-capped goto as the position setpoint to send now: ``("carrot", start_enu, target_enu, speed m/s,
        vehicle t0)`` moves from start towards target at ``speed`` metres per vehicle second."""
        _, start, target, speed, t0 = sp
        delta = target - start
        length = float(np.linalg.norm(delta))
        frac = 1.0 if length < 1e-6 else min(1.0, speed * max(0.0, self.t - t0) / length)
        p = start + delta * frac
        v = delta / length * speed if frac < 1.0 else np.zeros(3)  # velocity feed-forward, ENU
        g = enu_to_geodetic(float(p[0]), float(p[1]), 0.0, self.home)
        return ("posvel", int(round(g.lat * 1e7)), int(round(g.lon * 1e7)), float(p[2]), *self.enu_to_ned(v))

    def _send_setpoint(self, sp: tuple) -> None:
        try:
            if sp[0] == "carrot":
                sp = self._carrot(sp)
            if sp[0] == "pos":
                _, lat_i, lon_i, alt = sp
                self._send(lambda mav: mav.set_position_target_global_int_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    POSITION_ONLY_MASK, lat_i, lon_i, alt, 0, 0, 0, 0, 0, 0, 0, 0))
            elif sp[0] == "posvel":
                _, lat_i, lon_i, alt, vn, ve, vd = sp
                self._send(lambda mav: mav.set_position_target_global_int_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    POSITION_VELOCITY_MASK, lat_i, lon_i, alt, vn, ve, vd, 0, 0, 0, 0, 0))
            else:
                _, vn, ve, vd, yaw_rate = sp
                self._send(lambda mav: mav.set_position_target_local_ned_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_MASK,
                    0, 0, 0, vn, ve, vd, 0, 0, 0, 0, yaw_rate))
            self._sp_sent += 1
        except LinkLost:
            pass

    def _check_link(self, command: str) -> None:
        if self._conn is None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: not connected (call connect() first)")
        if self._io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: the MAVLink I/O thread failed: {self._io_error}")
        if not self._link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost (no HEARTBEAT for more than "
                           f"{self.cfg.heartbeat_timeout_s:g} s)")

    def _status_text_since(self, since: float, wait_s: float = 0.3) -> str:
        """The autopilot's latest STATUSTEXT sent since ``since`` (waiting up to ``wait_s`` for one, and up to
        :data:`_STATUSTEXT_FLUSH_S` longer while a chunked one begun since then is incomplete), else the latest of
        the 2 s before."""
        end = time.monotonic() + wait_s
        while True:
            texts = [t for t in list(self._texts) if t[0] >= since]
            pending = any(b["t"] >= since for b in list(self._chunks.values()))
            if (texts and not pending) or time.monotonic() >= end + (_STATUSTEXT_FLUSH_S if pending else 0.0):
                break
            time.sleep(0.01)
        if not texts:
            texts = [t for t in list(self._texts) if t[0] >= since - 2.0]
        return texts[-1][2] if texts else ""

    def command_long(self, name: str, command: int, *params: float, retries: int | None = None,
                     timeout_s: float | None = None) -> None:
        """Send COMMAND_LONG ``command`` (MAV_CMD number) with up to seven ``params`` and wait for its COMMAND_ACK
        (MAVLink command protocol). ``name`` is used in errors.

        Each try waits ``timeout_s`` (default ``command_timeout_s``) wall seconds for the ACK; without one the
        command is re-sent, up to ``retries`` (default ``command_retries``) times, with the ``confirmation``
        counter raised. MAV_RESULT_TEMPORARILY_REJECTED ("retrying later should work", MAV_RESULT) uses a try
        too: re-sent after min(``timeout_s``, 0.5) s. After MAV_RESULT_IN_PROGRESS (the command runs; progress
        ACKs follow) the command is not sent again (MAVLink command protocol): its final ACK is awaited until the
        overall deadline of (``retries`` + 1) x ``timeout_s`` from the first send, which bounds every case.

        Raises :class:`CommandRefused` (MAV_RESULT name, the autopilot's STATUSTEXT) for any final result but
        ACCEPTED, and for TEMPORARILY_REJECTED when the tries are used up; :class:`LinkLost` when the link is or
        goes down; :class:`BackendError` when no ACK comes, or the command is still IN_PROGRESS at the overall
        deadline."""
        self._check_link(name)
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        retries = self.cfg.command_retries if retries is None else retries
        timeout = self.cfg.command_timeout_s if timeout_s is None else timeout_s
        while True:  # drop acknowledgements nobody waited for
            try:
                self._acks.get_nowait()
            except queue.Empty:
                break
        started = time.monotonic()
        overall = started + (retries + 1) * timeout
        last: Any = None  # the latest non-final answer: IN_PROGRESS or TEMPORARILY_REJECTED
        for attempt in range(retries + 1):
            if time.monotonic() >= overall:
                break
            sent = time.monotonic()
            self._send(lambda mav: mav.command_long_send(self._sysid, self._compid, command, min(attempt, 255), *p))
            deadline = min(sent + timeout, overall)
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                try:
                    _, ack = self._acks.get(timeout=min(remaining, 0.05))
                except queue.Empty:
                    if not self._link_ok:
                        raise LinkLost(f"robot {self.robot_id!r}: {name}: link lost while waiting for COMMAND_ACK")
                    continue
                if ack.command != command:
                    continue
                if ack.result == M.MAV_RESULT_ACCEPTED:
                    self.command_rtt_ms.append((time.monotonic() - sent) * 1000.0)
                    return
                if ack.result == M.MAV_RESULT_IN_PROGRESS:  # it runs: wait for the final ACK, never re-send
                    last = ack
                    deadline = overall
                    continue
                if ack.result == M.MAV_RESULT_TEMPORARILY_REJECTED:
                    last = ack
                    if attempt == retries:
                        break  # no try left to wait for
                    deadline = min(deadline, time.monotonic() + min(timeout, _REJECTED_BACKOFF_S))
                    continue
                raise CommandRefused(self.robot_id, name, _enum_name("MAV_RESULT", ack.result),
                                     self._status_text_since(started))
            if last is not None and last.result == M.MAV_RESULT_IN_PROGRESS:
                break
        if not self._link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {name}: link lost while waiting for COMMAND_ACK")
        if last is not None and last.result == M.MAV_RESULT_TEMPORARILY_REJECTED:
            raise CommandRefused(self.robot_id, name, "MAV_RESULT_TEMPORARILY_REJECTED",
                                 self._status_text_since(started))
        if last is not None:
            progress = "" if last.progress in (0, 255) else f", progress {last.progress} %"
            raise BackendError(f"robot {self.robot_id!r}: {name}: {_enum_name('MAV_CMD', command)} still "
                               f"MAV_RESULT_IN_PROGRESS{progress} after {time.monotonic() - started:.1f} s (limit "
                               f"{retries + 1} x {timeout:g} s)")
        raise BackendError(f"robot {self.robot_id!r}: {name}: no COMMAND_ACK for {_enum_name('MAV_CMD', command)} "
                           f"after {retries + 1} tries of {timeout:g} s")

    # ------------------------------------------------------------------ streams and home
    def _request_streams(self, wait: bool = True) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL for each telemetry message (rates in the vehicle's time); on UNSUPPORTED or
        no acknowledgement fall back to REQUEST_DATA_STREAM. ``wait=False`` (from the I/O thread, after the link
        returns) re-sends the method chosen at connect without waiting for acknowledgements."""
        rate = self.cfg.stream_rate_hz
        if not wait:
            for msg_id, hz in _TELEMETRY if not self._stream_legacy else ():
                self._send(lambda mav, m=msg_id, h=hz: mav.command_long_send(
                    self._sysid, self._compid, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m, 1e6 / (h or rate), 0, 0, 0, 0, 0))
            if self._stream_legacy:
                self._legacy_streams(rate)
            return
        for msg_id, hz in _TELEMETRY:
            name = f"SET_MESSAGE_INTERVAL for message {msg_id}"
            try:
                self.command_long(name, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / (hz or rate), retries=1)
            except CommandRefused as e:
                if e.result == "MAV_RESULT_UNSUPPORTED":
                    self._stream_legacy = True
                    break
                self._event("stream_refused", message_id=msg_id, result=e.result)
            except LinkLost:
                raise
            except BackendError:
                self._stream_legacy = True
                break
        if self._stream_legacy:
            self._event("stream_fallback", method="REQUEST_DATA_STREAM")
            self._legacy_streams(rate)

    def _legacy_streams(self, rate: float) -> None:
        for _ in range(3):  # no acknowledgement exists for REQUEST_DATA_STREAM
            for stream, hz in _LEGACY_STREAMS:
                self._send(lambda mav, s=stream, h=hz: mav.request_data_stream_send(
                    self._sysid, self._compid, s, max(1, int(round(h or rate))), 1))

    def _request_home(self) -> None:
        try:
            self.command_long("request HOME_POSITION", M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION,
                              retries=1)
        except CommandRefused as e:
            if e.result == "MAV_RESULT_UNSUPPORTED":
                try:
                    self.command_long("request HOME_POSITION", M.MAV_CMD_GET_HOME_POSITION, retries=1)
                except BackendError:
                    pass
            # FAILED / DENIED: no home yet; it is sent when it is set
        except LinkLost:
            raise
        except BackendError:
            pass

    # ------------------------------------------------------------------ VehicleBackend: state
    @property
    def t(self) -> float:
        with self._lock:
            t = self._raw_t() - self._t_connect
            if not self._link_ok and self._boot_ref is not None:
                # nothing timestamped arrives while the link is down: the vehicle's clock goes on at its last rate
                t += (time.monotonic() - self._boot_wall) * self._ratio
            t = max(t, self._t_max)
            self._t_max = t
            return t

    def step(self, dt: float) -> None:
        """Telemetry arrives on the I/O thread; this only reports that thread's failure (BackendError)."""
        if self._io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: the MAVLink I/O thread failed: {self._io_error}")

    @property
    def position(self) -> np.ndarray:
        with self._lock:
            return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        with self._lock:
            return self._vel.copy()

    @property
    def yaw(self) -> float:
        return self._att[2]

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def in_air(self) -> bool:
        """From EXTENDED_SYS_STATE's landed state when the autopilot sends it, else armed and above 0.3 m."""
        with self._lock:
            if self._landed_state and time.monotonic() - self._landed_wall < 5.0:
                return self._landed_state in (M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF,
                                              M.MAV_LANDED_STATE_LANDING)
            return self._armed and self._rel_alt > 0.3

    @property
    def battery_pct(self) -> float:
        """BATTERY_STATUS (battery 0) remaining %, else SYS_STATUS; 100 while the autopilot reports none."""
        b = self._battery
        return 100.0 if b is None else max(0.0, min(100.0, b))

    @property
    def link_ok(self) -> bool:
        return self._link_ok

    @property
    def mode(self) -> str:
        """The flight mode from the latest HEARTBEAT, in pymavlink's names (``GUIDED``, ``OFFBOARD``, ``LOITER``...)."""
        return self._mode

    @property
    def gps_fix_type(self) -> int:
        """GPS_RAW_INT fix type (GPS_FIX_TYPE; 3 = 3-D), -1 before any report."""
        return self._gps_fix

    @property
    def home_received(self) -> bool:
        """True once HOME_POSITION replaced the configured home as ENU origin."""
        return self._home_received

    @property
    def clock_ratio(self) -> float:
        """Vehicle seconds per wall second, estimated from ``time_boot_ms`` (1 for a real vehicle)."""
        return self._ratio

    def odometry(self) -> Odometry:
        with self._lock:
            pos = tuple(float(v) for v in self._pos)
            geo = self._geo or enu_to_geodetic(pos[0], pos[1], pos[2], self.home)
            return Odometry(robot_id=self.robot_id, t=self.t, position=pos, geodetic=geo,
                            velocity=tuple(float(v) for v in self._vel),
                            attitude=Attitude(roll=self._att[0], pitch=self._att[1], yaw=self._att[2]),
                            battery_pct=self.battery_pct, battery_voltage=self._battery_v, armed=self._armed,
                            in_air=self.in_air)

    def drain_events(self) -> list[dict[str, Any]]:
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out

    def _event(self, event: str, **fields: Any) -> None:
        self._events.append({"event": event, "t": round(self.t, 3), **fields})  # extrapolated while the link is down

    # ------------------------------------------------------------------ modes
    def set_mode(self, name: str, confirm_s: float | None = None) -> None:
        """Switch to flight mode ``name`` (ArduPilot copter names ``GUIDED``, ``LAND``, ``RTL``, ``AUTO``,
        ``LOITER``...; PX4 names as pymavlink's ``px4_map``: ``OFFBOARD``, ``TAKEOFF``, ``LOITER``, ``MISSION``,
        ``RTL``, ``LAND``...) with MAV_CMD_DO_SET_MODE (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom main mode,
        PX4 sub mode), then wait up to ``confirm_s`` wall seconds (default the larger of ``command_timeout_s`` and
        ``heartbeat_timeout_s``) for a HEARTBEAT showing it. Raises ValueError for an unknown name,
        CommandRefused / LinkLost / BackendError as :meth:`command_long`, :class:`CommandNotConfirmed` (naming the
        mode asked for and the one the HEARTBEAT shows) when the vehicle acknowledged but never switched."""
        name = name.upper()
        sent = time.monotonic()
        if self.autopilot == "px4":
            if name not in mavutil.px4_map:
                raise ValueError(f"mode {name!r} is not a PX4 mode; choose from {sorted(mavutil.px4_map)}")
            _, main, sub = mavutil.px4_map[name]
            self.command_long(f"set mode {name}", M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)
        else:
            if name not in self._ap_modes:
                raise ValueError(f"mode {name!r} is not an ArduPilot {self.vehicle_type} mode; choose from "
                                 f"{sorted(self._ap_modes)}")
            self.command_long(f"set mode {name}", M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              self._ap_modes[name])
        self._await_heartbeat(f"set mode {name}", lambda: self._mode == name, f"mode {name}", confirm_s, sent)

    def _await_heartbeat(self, command: str, done: Callable[[], bool], expected: str, wait_s: float | None,
                         sent: float) -> None:
        """After ``command`` (sent at monotonic ``sent``) was accepted: wait until ``done()`` (the HEARTBEAT shows
        ``expected``) for ``wait_s`` wall seconds (None: the larger of ``command_timeout_s`` and
        ``heartbeat_timeout_s``: the autopilot's HEARTBEAT comes at least that often while the link is up).
        Raises LinkLost or CommandNotConfirmed."""
        wait = max(self.cfg.command_timeout_s, self.cfg.heartbeat_timeout_s) if wait_s is None else wait_s
        started = time.monotonic()
        while not done():
            if not self._link_ok:
                raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost before a HEARTBEAT showed {expected}")
            if time.monotonic() - started >= wait:
                observed = f"mode {self._mode or '(none)'}, {'armed' if self._armed else 'disarmed'}"
                raise CommandNotConfirmed(self.robot_id, command, expected, observed, wait,
                                          self._status_text_since(sent, wait_s=0.0))
            time.sleep(0.005)

    def _guided_mode(self) -> str:
        return "OFFBOARD" if self.autopilot == "px4" else "GUIDED"

    def _enter_guided(self, sp: tuple) -> None:
        """Make ``sp`` the active target and fly it: ArduPilot GUIDED (mode first, then the target), PX4 OFFBOARD
        (stream first, then the mode switch, which PX4 refuses without a stream)."""
        guided = self._guided_mode()
        if self.autopilot == "px4":
            with self._lock:
                self._setpoint = sp
                self._sp_next = 0.0
            self._send_setpoint(sp)
            if self._mode != guided:
                start, sent0 = time.monotonic(), self._sp_sent
                # PX4 wants the stream running before the switch: at least 3 setpoints and 0.3 s of vehicle time
                while (self._sp_sent - sent0 < 3 or (time.monotonic() - start) * self._ratio < 0.3) \
                        and time.monotonic() - start < 2.0:
                    time.sleep(0.005)
                self.set_mode(guided)
        else:
            if self._mode != guided:
                self.set_mode(guided)
            with self._lock:
                self._setpoint = sp
                self._sp_next = time.monotonic() + 1.0 / (self.cfg.setpoint_rate_hz * self._ratio)
            self._send_setpoint(sp)

    def _stop_setpoints(self) -> None:
        with self._lock:
            self._setpoint = None

    # ------------------------------------------------------------------ VehicleBackend: control
    def _armable(self) -> bool:
        with self._lock:
            if self._gps_fix >= 0 and self._gps_fix < M.GPS_FIX_TYPE_3D_FIX:
                return False
            if self._sensors is not None:
                present, _, health = self._sensors
                for bit in (M.MAV_SYS_STATUS_PREARM_CHECK, M.MAV_SYS_STATUS_AHRS):
                    if present & bit and not health & bit:
                        return False
            return True

    def arm(self) -> None:
        """Wait up to ``arm_timeout_s`` until the autopilot reports itself armable (3-D fix in GPS_RAW_INT,
        SYS_STATUS pre-arm and AHRS health bits when present), switch to a mode that can arm and take off
        (ArduPilot GUIDED, PX4 LOITER/Hold), then MAV_CMD_COMPONENT_ARM_DISARM. If it never becomes armable the
        arm command is sent anyway in the current mode, so the :class:`CommandRefused` carries the autopilot's
        reason (e.g. ``PreArm: ...``). Once acknowledged, waits (like :meth:`set_mode`) for a HEARTBEAT with the
        armed flag (MAV_MODE_FLAG_SAFETY_ARMED). Raises CommandRefused / LinkLost / BackendError as
        :meth:`command_long`, :class:`CommandNotConfirmed` when the vehicle acknowledged but never reported
        itself armed."""
        self._check_link("arm")
        end = time.monotonic() + self.cfg.arm_timeout_s
        while not self._armable() and time.monotonic() < end:
            self._check_link("arm")
            time.sleep(0.02)
        if self._armable():
            if self.autopilot == "ardupilot" and self._mode != "GUIDED":
                self.set_mode("GUIDED")
            elif self.autopilot == "px4" and self._mode in _PX4_NO_ARM_MODES:
                self.set_mode("LOITER")
        sent = time.monotonic()
        self.command_long("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        self._await_heartbeat("arm", lambda: self._armed, "armed", None, sent)

    def disarm(self) -> None:
        """MAV_CMD_COMPONENT_ARM_DISARM(0); autopilots refuse it in flight (CommandRefused)."""
        self._stop_setpoints()
        self.command_long("disarm", M.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    def takeoff(self, altitude_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF to ``altitude_m`` metres above home. ArduPilot: in GUIDED, ``param7`` relative;
        PX4: ``param7`` AMSL (home altitude from GLOBAL_POSITION_INT alt - relative_alt), position NaN = here;
        PX4 holds (LOITER) when it gets there. Raises ValueError for a non-positive or non-finite altitude."""
        self._require_navigable("takeoff")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude_m must be a positive number of metres, got {altitude_m!r}")
        self._check_link("takeoff")
        self._stop_setpoints()
        if self.autopilot == "px4":
            with self._lock:
                home_amsl = (self._geo.alt - self._rel_alt) if self._geo is not None else self.home.alt
            nan = float("nan")
            self.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, home_amsl + altitude_m)
        else:
            if self._mode != "GUIDED":
                self.set_mode("GUIDED")
            self.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude_m)

    def _change_speed(self, speed: float | None) -> None:
        if speed == self._speed_cmd:
            return
        self.command_long("change speed", M.MAV_CMD_DO_CHANGE_SPEED, 1, -2 if speed is None else speed, -1)
        self._speed_cmd = speed

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home) with SET_POSITION_TARGET_GLOBAL_INT
        (MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, position-only type mask), re-sent by the I/O thread. A ``speed`` cap
        (m/s): ArduPilot gets MAV_CMD_DO_CHANGE_SPEED (ground speed; GUIDED honours it); PX4 OFFBOARD flies
        position setpoints at its own velocity limit (DO_CHANGE_SPEED is a navigator/mission command), so the
        streamed setpoint itself moves from here towards the target at ``speed`` per vehicle second, with that
        velocity as feed-forward (position + velocity type mask).
        Raises ValueError for a non-finite target or a non-positive speed."""
        self._require_navigable("goto")
        x, y, z = (float(v) for v in target_enu)
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise ValueError(f"goto target_enu must be finite metres, got {tuple(target_enu)!r}")
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"goto speed must be a positive number of m/s or None, got {speed!r}")
        self._check_link("goto")
        if self.autopilot == "px4" and speed is not None:
            self._enter_guided(("carrot", self.position, np.array([x, y, z]), float(speed), self.t))
            return
        g = enu_to_geodetic(x, y, 0.0, self.home)
        sp = ("pos", int(round(g.lat * 1e7)), int(round(g.lon * 1e7)), z)
        if self.autopilot == "ardupilot":
            self._change_speed(speed)
        self._enter_guided(sp)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Hold ENU velocity ``v_enu`` (m/s) and yaw rate (deg/s, counter-clockwise) with
        SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED, velocity + yaw-rate type mask; NED = (v_north, v_east,
        -v_up), yaw rate clockwise rad/s), re-sent at ``setpoint_rate_hz`` vehicle time."""
        self._require_navigable("set_velocity")
        ve, vn, vu = (float(v) for v in v_enu)
        if not all(math.isfinite(v) for v in (ve, vn, vu, yaw_rate_dps)):
            raise ValueError(f"set_velocity needs finite m/s and deg/s, got {tuple(v_enu)!r}, {yaw_rate_dps!r}")
        self._check_link("set_velocity")
        self._enter_guided(("vel", vn, ve, -vu, -math.radians(yaw_rate_dps)))

    def hold(self) -> None:
        """Hover here: in GUIDED/OFFBOARD a position target at the current position; otherwise the autopilot's
        hold mode (ArduPilot LOITER, PX4 LOITER/Hold). On the ground it only stops the target stream."""
        self._require_navigable("hold")
        self._check_link("hold")
        if not self.in_air:
            self._stop_setpoints()
            return
        if self._mode == self._guided_mode():
            p = self.position
            self.goto((p[0], p[1], p[2]))
        else:
            self._autopilot_mode("LOITER")

    def land(self) -> None:
        """LAND mode (ArduPilot LAND, PX4 AUTO.LAND): descend and land here; both disarm once landed. Raises as
        :meth:`set_mode`."""
        self._require_navigable("land")
        self._autopilot_mode("LAND")

    def return_to_launch(self) -> bool:
        """RTL mode (ArduPilot RTL, PX4 AUTO.RTL): the autopilot climbs to its return altitude, flies home, lands
        and disarms. Returns True. Raises as :meth:`set_mode`."""
        self._require_navigable("return_to_launch")
        self._autopilot_mode("RTL")
        return True

    def _autopilot_mode(self, name: str) -> None:
        """Hand the vehicle to one of the autopilot's own modes and stop streaming our targets. A refused mode
        change keeps the stream (the vehicle stays where our last target holds it); one the autopilot accepted but
        whose HEARTBEAT has not shown it yet (CommandNotConfirmed) stops it too, so a late switch is not pulled
        back by our setpoints."""
        try:
            self.set_mode(name)
        except CommandNotConfirmed:
            self._stop_setpoints()
            raise
        self._stop_setpoints()

    # ------------------------------------------------------------------ missions
    def _mission_items(self, mission: Any, takeoff_altitude: float | None, final_action: str) -> list[MissionItem]:
        if isinstance(mission, MissionPlan):
            items = expand_items(mission)
        else:
            if isinstance(mission, AeroNavigation):
                nav = mission
            else:
                seq = list(mission)
                if seq and all(isinstance(i, MissionItem) for i in seq):
                    items = seq
                    nav = None
                elif all(isinstance(i, (Waypoint, ActionCommand)) for i in seq):
                    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, seq, SchedulingType.ORDERED)
                else:
                    bad = next(i for i in seq if not isinstance(i, (Waypoint, ActionCommand, MissionItem)))
                    raise TypeError(f"upload_mission: items must all be Waypoint/ActionCommand or all MissionItem, "
                                    f"got {type(bad).__name__}")
            if nav is not None:
                items = navigation_to_plan(nav, self.home, final_action, takeoff_altitude=takeoff_altitude).items
        for it in items:
            if it.is_complex:
                raise ValueError(f"upload_mission: {it.describe()} must be expanded first (pass the MissionPlan)")
        return items

    def upload_mission(self, mission: Any, *, takeoff_altitude: float | None = None,
                       final_action: Literal["land", "rtl", "hover"] = "hover") -> list[MissionItem]:
        """Upload a mission with the MISSION_ITEM_INT protocol (MISSION_COUNT, answering each MISSION_REQUEST_INT
        / MISSION_REQUEST, until MISSION_ACK).

        ``mission``: a list of :class:`~aerodaas.models.Waypoint` (ENU relative to :attr:`home`, or absolute) and
        optionally a final land/rtl :class:`~aerodaas.models.ActionCommand`, an :class:`AeroNavigation`, a
        :class:`~aerodaas.missionfile.MissionPlan` (e.g. an imported ``.plan``; ComplexItems expanded) or a list
        of :class:`~aerodaas.missionfile.MissionItem`. Waypoints become MAV_CMD_NAV_WAYPOINT items
        (``navigation_to_plan``: ``takeoff_altitude`` m prepends a NAV_TAKEOFF, ``final_action`` appends
        NAV_LAND / NAV_RETURN_TO_LAUNCH). ArduPilot gets its home placeholder at sequence 0.

        Returns the items as sent (``seq`` from 1; latitude/longitude rounded to 1e-7 degrees, params to float32),
        which :meth:`download_mission` returns unchanged. Raises CommandRefused (MAV_MISSION_RESULT name) when the
        autopilot rejects an item, BackendError after ``command_retries`` timeouts, LinkLost, TypeError/ValueError
        for bad input (nothing is sent then)."""
        items = self._mission_items(mission, takeoff_altitude, final_action)
        wire: list[tuple] = []
        sent_items: list[MissionItem] = []
        for k, it in enumerate(items):
            p = [_f32(v) for v in it.params[:4]]
            x, y = it.params[4], it.params[5]
            if it.frame in _GLOBAL_FRAMES:
                xi, yi = int(round((x or 0.0) * 1e7)), int(round((y or 0.0) * 1e7))
                xs, ys = xi / 1e7, yi / 1e7
            else:
                xi, yi = int(round(x or 0.0)), int(round(y or 0.0))
                xs, ys = float(xi), float(yi)
            z = _f32(it.params[6] if it.params[6] is not None else 0.0)
            wire.append((it.frame, it.command, 1 if it.autocontinue else 0,
                         *[float("nan") if v is None else v for v in p], xi, yi, z))
            sent_items.append(MissionItem(seq=k + 1, command=it.command, frame=it.frame, params=[*p, xs, ys, z],
                                          autocontinue=it.autocontinue))
        if self.autopilot == "ardupilot":
            h = self.home
            wire.insert(0, (0, M.MAV_CMD_NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, 0.0, int(round(h.lat * 1e7)),
                            int(round(h.lon * 1e7)), float(h.alt)))
        self._check_link("mission upload")
        n = len(wire)

        def send_item(seq: int, as_int: bool) -> None:
            frame, cmd, auto, p1, p2, p3, p4, xi, yi, z = wire[seq]
            if as_int:
                self._send(lambda mav: mav.mission_item_int_send(self._sysid, self._compid, seq, frame, cmd, 0, auto,
                                                                 p1, p2, p3, p4, xi, yi, z, 0))
            else:
                k = 1e-7 if frame in _GLOBAL_FRAMES else 1.0
                self._send(lambda mav: mav.mission_item_send(self._sysid, self._compid, seq, frame, cmd, 0, auto,
                                                             p1, p2, p3, p4, xi * k, yi * k, z, 0))

        def resend(last: Any) -> None:
            if last is None:
                self._send(lambda mav: mav.mission_count_send(self._sysid, self._compid, n, 0))
            else:
                send_item(*last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if t in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and getattr(msg, "mission_type", 0) == 0:
                if 0 <= msg.seq < n:
                    state["last"] = (msg.seq, t == "MISSION_REQUEST_INT")
                    state["max"] = max(state["max"], msg.seq)
                    send_item(*state["last"])
                return False
            if t == "MISSION_ACK" and getattr(msg, "mission_type", 0) == 0:
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission upload", _enum_name("MAV_MISSION_RESULT", msg.type),
                                         self._status_text_since(state["start"]))
                return state["max"] == n - 1 or n == 0
            return False

        self._transaction("mission upload", lambda: resend(None), resend, on_msg)
        self._event("mission_uploaded", count=len(sent_items))
        return sent_items

    def _transaction(self, name: str, begin: Callable[[], None], resend: Callable[[Any], None],
                     on_msg: Callable[[Any, dict], bool]) -> dict:
        """Run one mission-protocol exchange: ``begin()``, then feed every mission message to ``on_msg`` until it
        returns True; after ``command_timeout_s`` without progress ``resend(state["last"])`` up to
        ``command_retries`` times (only a message that advances the exchange, i.e. changes ``state``, resets the
        count, so a vehicle answering with something we do not use cannot keep it going for ever)."""
        while True:
            try:
                self._mission_q.get_nowait()
            except queue.Empty:
                break
        state: dict[str, Any] = {"last": None, "max": -1, "start": time.monotonic()}
        self._mission_active = True
        try:
            begin()
            retries = 0
            deadline = time.monotonic() + self.cfg.command_timeout_s
            while True:
                remaining = deadline - time.monotonic()
                msg = None
                if remaining > 0:
                    try:
                        msg = self._mission_q.get(timeout=remaining)
                    except queue.Empty:
                        pass
                if msg is None:
                    self._check_link(name)
                    retries += 1
                    if retries > self.cfg.command_retries:
                        raise BackendError(f"robot {self.robot_id!r}: {name}: no usable answer after {retries} "
                                           f"tries of {self.cfg.command_timeout_s:g} s")
                    resend(state["last"])
                    deadline = time.monotonic() + self.cfg.command_timeout_s
                    continue
                before = (state["last"], state["max"], state.get("count"))
                if on_msg(msg, state):
                    return state
                if (state["last"], state["max"], state.get("count")) != before:
                    retries = 0
                    deadline = time.monotonic() + self.cfg.command_timeout_s
        finally:
            self._mission_active = False

    def download_mission(self) -> MissionPlan:
        """Download the autopilot's mission (MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT for each
        item, answered with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM, whose float latitude/longitude
        degrees are rounded to the same 1e-7 degree grid; MISSION_ACK). Returns a
        :class:`~aerodaas.missionfile.MissionPlan` with ``home`` = the vehicle's home and ``items`` numbered from 1
        (ArduPilot's home item at sequence 0 is left out); turn it into waypoints with
        :func:`~aerodaas.missionfile.plan_to_flight`. Raises BackendError / LinkLost, CommandRefused (MISSION_ACK
        with an error)."""
        self._check_link("mission download")
        got: dict[int, Any] = {}

        def begin() -> None:
            self._send(lambda mav: mav.mission_request_list_send(self._sysid, self._compid, 0))

        def request(seq: int) -> None:
            self._send(lambda mav: mav.mission_request_int_send(self._sysid, self._compid, seq, 0))

        def resend(last: Any) -> None:
            begin() if last is None else request(last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if t == "MISSION_COUNT" and getattr(msg, "mission_type", 0) == 0 and "count" not in state:
                state["count"] = msg.count
                if msg.count == 0:
                    return True
                state["last"] = 0
                request(0)
            elif t in ("MISSION_ITEM_INT", "MISSION_ITEM") and "count" in state and msg.seq == state["last"]:
                got[msg.seq] = msg
                if msg.seq + 1 >= state["count"]:
                    return True
                state["last"] = msg.seq + 1
                request(msg.seq + 1)
            elif t == "MISSION_ACK" and msg.type != M.MAV_MISSION_ACCEPTED:
                raise CommandRefused(self.robot_id, "mission download", _enum_name("MAV_MISSION_RESULT", msg.type),
                                     self._status_text_since(state["start"]))
            return False

        self._transaction("mission download", begin, resend, on_msg)
        self._send(lambda mav: mav.mission_ack_send(self._sysid, self._compid, M.MAV_MISSION_ACCEPTED, 0))
        items = []
        first = 1 if self.autopilot == "ardupilot" else 0
        for seq in sorted(got):
            if seq < first:
                continue
            m = got[seq]
            if m.frame in _GLOBAL_FRAMES and m.get_type() == "MISSION_ITEM":  # float degrees (float32 on the wire)
                x, y = round(m.x * 1e7) / 1e7, round(m.y * 1e7) / 1e7
            elif m.frame in _GLOBAL_FRAMES:
                x, y = m.x / 1e7, m.y / 1e7
            else:
                x, y = float(m.x), float(m.y)
            items.append(MissionItem(seq=seq + 1 - first, command=m.command, frame=m.frame,
                                     params=[_f32(m.param1), _f32(m.param2), _f32(m.param3), _f32(m.param4), x, y,
                                             _f32(m.z)], autocontinue=bool(m.autocontinue)))
        return MissionPlan(home=self.home, items=items)

    def clear_mission(self) -> None:
        """MISSION_CLEAR_ALL; waits for MISSION_ACK. Raises CommandRefused / BackendError / LinkLost."""
        self._check_link("mission clear")

        def on_msg(msg: Any, state: dict) -> bool:
            if msg.get_type() == "MISSION_ACK":
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission clear", _enum_name("MAV_MISSION_RESULT", msg.type))
                return True
            return False

        clear = lambda *_: self._send(lambda mav: mav.mission_clear_all_send(self._sysid, self._compid, 0))  # noqa: E731
        self._transaction("mission clear", clear, clear, on_msg)

    def start_mission(self) -> None:
        """Fly the uploaded mission: in the air switch to AUTO (ArduPilot) / MISSION (PX4); on the ground (armed)
        MAV_CMD_MISSION_START, which starts it from the first item (ArduPilot needs a NAV_TAKEOFF first; PX4
        takes off by itself). Progress arrives as ``mission_current`` / ``mission_item_reached`` events."""
        self._require_navigable("start_mission")
        self._stop_setpoints()
        if self.in_air:
            self.set_mode("MISSION" if self.autopilot == "px4" else "AUTO")
        else:
            self.command_long("mission start", M.MAV_CMD_MISSION_START, 0, 0)
