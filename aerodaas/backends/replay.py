"""Replay of recorded flights: a MAVLink telemetry log as a (non-navigable) vehicle, and an MCAP recording's camera
channel as a frame source, so that analytics and their schedulers can be re-run on a real or recorded flight.

:class:`ReplayBackend` plays a ``.tlog`` (pymavlink's reader; the format is each MAVLink packet prefixed by its
capture time, a big-endian uint64 of microseconds) at ``rate`` x real time:

* odometry from ``GLOBAL_POSITION_INT`` (lat/lon -> ENU about home with pymap3d, ``relative_alt`` as height above
  home, NED velocity -> ENU) and ``ATTITUDE`` (roll, pitch, yaw -> ENU yaw);
* battery from ``BATTERY_STATUS.battery_remaining`` (``SYS_STATUS`` when the log has no BATTERY_STATUS), voltage
  from ``SYS_STATUS.voltage_battery``;
* armed and flight mode from the vehicle's ``HEARTBEAT`` (``base_mode`` bit ``MAV_MODE_FLAG_SAFETY_ARMED``;
  PX4/ArduPilot custom modes decoded by ``pymavlink.mavutil.mode_string_v10``), in-air from
  ``EXTENDED_SYS_STATE.landed_state``;
* home from the first ``HOME_POSITION`` (else the first ``GLOBAL_POSITION_INT`` with a fix), updated when a later
  HOME_POSITION moves it.

A PX4 flight log (``.ulg``, read with pyulog) plays the same way: its uORB topics are turned into the MAVLink
messages above, in MAVLink units, by :func:`load_ulog` (see there). A ULog has no radio link, so link loss is never
reported for it.

Only the vehicle's own messages count (the autopilot: the first HEARTBEAT whose autopilot is not
``MAV_AUTOPILOT_INVALID``); a GCS's messages, unknown message ids and bad data are skipped. A log captured through
a router that forwards each packet on two links holds it twice: a packet is a duplicate when the same sender
(system, component) sent a packet with the same sequence number and message id within the last
:data:`DUPLICATE_WINDOW_PACKETS` packets of that sender and :data:`DUPLICATE_WINDOW_S` seconds (MAVLink's 8-bit
``seq`` counts per sender and link, so a window far shorter than its 256-packet wrap never mistakes a later packet,
and a genuinely repeated message — a STATUSTEXT sent twice — has its own sequence number and is kept).

A battery reported as unknown (``battery_remaining`` -1, MAVLink's "not available") stays unknown: ``battery_pct``
is None and the odometry records ``null``, never 100 %.
"""
from __future__ import annotations

import bisect
import math
import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import Attitude, GeoPoint, Odometry
from aerodaas.backends.base import BackendError, VehicleBackend
from aerodaas.config.backends import ReplayConfig

__all__ = ["ReplayBackend", "McapCameraReplay", "check_log", "load_tlog", "load_ulog", "LogMessage", "DUPLICATE_WINDOW_S"]

#: a packet repeating the (sequence number, message id) of one of its sender's last DUPLICATE_WINDOW_PACKETS packets,
#: seen less than DUPLICATE_WINDOW_S seconds before, is a duplicate from a second link
DUPLICATE_WINDOW_S = 0.5
DUPLICATE_WINDOW_PACKETS = 32
#: the link counts as lost after this many seconds of log time without a vehicle HEARTBEAT (as a GCS would)
HEARTBEAT_TIMEOUT_S = 3.0
#: MAVLink messages the replay uses
TLOG_TYPES = ("HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "BATTERY_STATUS", "SYS_STATUS", "HOME_POSITION",
              "EXTENDED_SYS_STATE", "STATUSTEXT", "MISSION_ITEM_REACHED")
_MAV_AUTOPILOT_INVALID = 8
_MAV_TYPE_GCS = 6
_MAV_MODE_FLAG_SAFETY_ARMED = 128
_MAV_LANDED_STATE_IN_AIR = (2, 3, 4)  # IN_AIR, TAKEOFF, LANDING


@dataclass(frozen=True)
class LogMessage:
    """One vehicle message of a log: ``t`` seconds since the log's first record, MAVLink ``type`` name, and the
    decoded pymavlink message."""

    t: float
    type: str
    msg: Any


def load_tlog(path: str | os.PathLike) -> tuple[list[LogMessage], dict[str, Any]]:
    """Read the vehicle's :data:`TLOG_TYPES` messages from a MAVLink telemetry log, de-duplicated, in log order.

    Returns (messages, info) with info ``{"t0": unix seconds of the first record, "sysid", "compid",
    "duplicates": n dropped, "foreign": n from other systems}``. Raises BackendError when the file cannot be
    read or holds no vehicle HEARTBEAT."""
    from pymavlink import mavutil

    p = Path(path)
    try:
        with open(p, "rb") as f:
            head = f.read(8)
        if len(head) < 8:
            raise BackendError(f"replay.log: {str(p)!r} is empty or truncated (no tlog timestamp)")
        t0 = struct.unpack(">Q", head)[0] / 1e6
        conn = mavutil.mavlink_connection(str(p))
    except OSError as e:
        raise BackendError(f"replay.log: cannot read {str(p)!r}: {e}") from e
    from collections import deque

    raw: list[tuple[float, str, Any]] = []
    recent: dict[tuple[int, int], deque] = {}  # sender -> its last packets' (seq, msgid, time)
    dups = 0
    vehicle: tuple[int, int] | None = None
    try:
        while True:
            m = conn.recv_match(type=list(TLOG_TYPES))
            if m is None:
                break
            ts = float(getattr(m, "_timestamp", t0))
            window = recent.setdefault((m.get_srcSystem(), m.get_srcComponent()),
                                       deque(maxlen=DUPLICATE_WINDOW_PACKETS))
            key = (m.get_seq(), m.get_msgId())
            if any((sq, mid) == key and ts - t < DUPLICATE_WINDOW_S for sq, mid, t in window):
                dups += 1
                continue
            window.append((key[0], key[1], ts))
            mtype = m.get_type()
            if (vehicle is None and mtype == "HEARTBEAT" and m.autopilot != _MAV_AUTOPILOT_INVALID
                    and m.type != _MAV_TYPE_GCS):
                vehicle = (m.get_srcSystem(), m.get_srcComponent())
            raw.append((ts - t0, mtype, m))
    finally:
        conn.close()
    if vehicle is None:
        raise BackendError(f"replay.log: {str(p)!r} holds no autopilot HEARTBEAT; is it a MAVLink telemetry log?")
    msgs = [LogMessage(t, ty, m) for t, ty, m in raw if (m.get_srcSystem(), m.get_srcComponent()) == vehicle]
    return msgs, {"t0": t0, "sysid": vehicle[0], "compid": vehicle[1], "duplicates": dups,
                  "foreign": len(raw) - len(msgs)}


def check_log(path: str | os.PathLike) -> dict[str, Any]:
    """Read a replay log (``.tlog`` or ``.ulg``) as :class:`ReplayBackend` will and check that it can be replayed: a
    vehicle HEARTBEAT (tlog) and at least one position fix (``GLOBAL_POSITION_INT`` with a non-zero lat/lon, or a
    ULog's ``vehicle_global_position``). Called while the environment is validated, before Ray starts. Returns the
    loader's info; raises BackendError naming the file and what is missing."""
    p = Path(path)
    msgs, info = load_ulog(p) if p.suffix.lower() == ".ulg" else load_tlog(p)
    if not any(lm.type == "GLOBAL_POSITION_INT" and (lm.msg.lat, lm.msg.lon) != (0, 0) for lm in msgs):
        raise BackendError(f"{str(p)!r} holds no position fix (GLOBAL_POSITION_INT / vehicle_global_position): "
                           f"nothing to replay")
    return info


class _UlogMsg:
    """A MAVLink-shaped message made from a ULog sample (the fields :class:`ReplayBackend` reads, in MAVLink units)."""

    def __init__(self, mtype: str, **fields: Any) -> None:
        self._type = mtype
        self.__dict__.update(fields)

    def get_type(self) -> str:
        return self._type


#: PX4 ``vehicle_status.nav_state`` -> the flight-mode name pymavlink gives the same mode in a .tlog
PX4_NAV_STATE_MODES = {0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "MISSION", 4: "LOITER", 5: "RTL", 6: "POSCTL",
                       10: "ACRO", 12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STABILIZED",
                       17: "TAKEOFF", 18: "LAND", 19: "FOLLOWME", 20: "PRECLAND", 21: "ORBIT", 22: "TAKEOFF"}
_PX4_ARMING_STATE_ARMED = 2
#: uORB topics :func:`load_ulog` reads (instance 0 of each)
ULOG_TOPICS = ("vehicle_global_position", "vehicle_local_position", "vehicle_attitude", "battery_status",
               "vehicle_status", "vehicle_land_detected", "home_position", "mission_result")


def _euler_from_quaternion(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians, ZYX order, from PX4's attitude quaternion (body FRD to NED, Hamilton, w first)."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def load_ulog(path: str | os.PathLike) -> tuple[list[LogMessage], dict[str, Any]]:
    """Read a PX4 ULog (``.ulg``; format: docs.px4.io "ULog File Format") with pyulog into the messages a ``.tlog``
    replay uses, in log order, ``t`` in seconds since the log's start:

    * ``vehicle_global_position`` (lat/lon deg, alt m AMSL) -> GLOBAL_POSITION_INT (1e7 deg, mm), with
      ``relative_alt`` = alt - home altitude and the velocity of the latest ``vehicle_local_position`` (NED m/s ->
      cm/s);
    * ``vehicle_attitude.q`` -> ATTITUDE (roll, pitch, yaw rad); ``battery_status`` (``remaining`` 0-1,
      ``voltage_v``) -> BATTERY_STATUS and SYS_STATUS;
    * ``vehicle_status`` -> HEARTBEAT (armed when ``arming_state`` is ARMED = 2; the mode named from ``nav_state`` as
      pymavlink names PX4 modes, :data:`PX4_NAV_STATE_MODES`), on change only;
    * ``vehicle_land_detected.landed`` -> EXTENDED_SYS_STATE (ON_GROUND / IN_AIR); ``home_position`` ->
      HOME_POSITION; ``mission_result.seq_reached`` -> MISSION_ITEM_REACHED; the log's text messages -> STATUSTEXT
      (severity = the ULog log level).

    Returns (messages, info) with info ``{"t0": None (a ULog's clock is the autopilot's boot time), "format":
    "ulog", "topics": [topics found], "dropouts": n}``. Raises BackendError when pyulog is missing, the file cannot
    be parsed, or it has no ``vehicle_global_position`` samples."""
    try:
        from pyulog import ULog
    except ImportError as e:  # pragma: no cover - a dependency; only a broken install lacks it
        raise BackendError("replay.log: reading a PX4 .ulg needs pyulog (pip install pyulog)") from e
    p = Path(path)
    try:
        ulog = ULog(str(p), list(ULOG_TOPICS))
    except Exception as e:  # noqa: BLE001 - pyulog raises bare Exceptions / struct errors on bad files
        raise BackendError(f"replay.log: {str(p)!r} is not a readable ULog: {type(e).__name__}: {e}") from e
    rows, found = _ulog_rows(ulog, p)
    conv = _UlogConverter()
    out: list[LogMessage] = []
    for ts, _, topic, f in rows:
        out.extend(conv.convert((ts - ulog.start_timestamp) / 1e6, topic, f))
    return out, {"t0": None, "format": "ulog", "topics": sorted(set(found)), "dropouts": len(ulog.dropouts)}


def _ulog_rows(ulog: Any, p: Path) -> tuple[list[tuple[int, int, str, dict[str, Any]]], list[str]]:
    """The samples of :data:`ULOG_TOPICS` (first instance) and the log's text messages (topic ``"log"``), as
    (timestamp us, topic order, topic, sample) sorted by time then topic, and the topics found. Raises BackendError
    when there is no ``vehicle_global_position``."""
    rows: list[tuple[int, int, str, dict[str, Any]]] = []
    found = []
    for d in ulog.data_list:
        if d.multi_id != 0 or d.name not in ULOG_TOPICS:
            continue
        found.append(d.name)
        cols = {k: v for k, v in d.data.items()}
        order = ULOG_TOPICS.index(d.name)
        for i in range(len(cols["timestamp"])):
            rows.append((int(cols["timestamp"][i]), order, d.name, {k: v[i].item() for k, v in cols.items()}))
    if "vehicle_global_position" not in found:
        raise BackendError(f"replay.log: {str(p)!r} has no vehicle_global_position samples (no position to replay)")
    for m in ulog.logged_messages:  # the level is an ASCII digit, '0' (emergency) to '7' (debug): MAV_SEVERITY's scale
        level = int(m.log_level) - ord("0")
        rows.append((int(m.timestamp), len(ULOG_TOPICS), "log",
                     {"level": level if 0 <= level <= 7 else 6, "text": m.message}))
    rows.sort(key=lambda r: (r[0], r[1]))
    return rows, found


class _UlogConverter:
    """One ULog sample at a time into the MAVLink-like messages of a replay (see :func:`load_ulog`), with what it
    carries over: the latest NED velocity (m/s), the home altitude (m AMSL), the armed state and mode, the landed
    state and the last reached mission item (HEARTBEAT, EXTENDED_SYS_STATE and MISSION_ITEM_REACHED on change)."""

    def __init__(self) -> None:
        self.vel_ned = (0.0, 0.0, 0.0)
        self.home_alt: float | None = None
        self.status: tuple[bool, str] | None = None
        self.landed: bool | None = None
        self.reached = -1

    def convert(self, t: float, topic: str, f: dict[str, Any]) -> list[LogMessage]:
        """The messages of sample ``f`` of ``topic`` at ``t`` seconds since the log's start."""
        if topic == "vehicle_local_position":
            self.vel_ned = (f.get("vx", 0.0), f.get("vy", 0.0), f.get("vz", 0.0))
        elif topic == "vehicle_global_position":
            return self._position(t, f)
        elif topic == "home_position":
            if math.isfinite(f["lat"]) and math.isfinite(f["lon"]):
                self.home_alt = f["alt"]
                return [LogMessage(t, "HOME_POSITION", _UlogMsg(
                    "HOME_POSITION", latitude=round(f["lat"] * 1e7), longitude=round(f["lon"] * 1e7),
                    altitude=round(f["alt"] * 1000)))]
        elif topic == "vehicle_attitude":
            roll, pitch, yaw = _euler_from_quaternion(f["q[0]"], f["q[1]"], f["q[2]"], f["q[3]"])
            return [LogMessage(t, "ATTITUDE", _UlogMsg("ATTITUDE", roll=roll, pitch=pitch, yaw=yaw))]
        elif topic == "battery_status":
            rem = f.get("remaining", -1.0)
            pct = round(rem * 100) if 0.0 <= rem <= 1.0 else -1
            return [LogMessage(t, "BATTERY_STATUS", _UlogMsg("BATTERY_STATUS", battery_remaining=pct)),
                    LogMessage(t, "SYS_STATUS", _UlogMsg(
                        "SYS_STATUS", voltage_battery=round(f.get("voltage_v", 0.0) * 1000), battery_remaining=pct))]
        elif topic == "log":
            return [LogMessage(t, "STATUSTEXT", _UlogMsg("STATUSTEXT", severity=f["level"], text=f["text"]))]
        else:
            return self._on_change(t, topic, f)
        return []

    def _position(self, t: float, f: dict[str, Any]) -> list[LogMessage]:
        if not (math.isfinite(f["lat"]) and math.isfinite(f["lon"]) and math.isfinite(f["alt"])):
            return []
        if self.home_alt is None:
            self.home_alt = f["alt"]
        v = self.vel_ned
        return [LogMessage(t, "GLOBAL_POSITION_INT", _UlogMsg(
            "GLOBAL_POSITION_INT", lat=round(f["lat"] * 1e7), lon=round(f["lon"] * 1e7), alt=round(f["alt"] * 1000),
            relative_alt=round((f["alt"] - self.home_alt) * 1000), vx=round(v[0] * 100), vy=round(v[1] * 100),
            vz=round(v[2] * 100)))]

    def _on_change(self, t: float, topic: str, f: dict[str, Any]) -> list[LogMessage]:
        """vehicle_status, vehicle_land_detected, mission_result: a message when what they say changed."""
        if topic == "vehicle_status":
            now = (int(f["arming_state"]) == _PX4_ARMING_STATE_ARMED,
                   PX4_NAV_STATE_MODES.get(int(f["nav_state"]), f"NAV_STATE_{int(f['nav_state'])}"))
            if now != self.status:
                self.status = now
                return [LogMessage(t, "HEARTBEAT", _UlogMsg(
                    "HEARTBEAT", base_mode=_MAV_MODE_FLAG_SAFETY_ARMED if now[0] else 0, mode_name=now[1]))]
        elif topic == "vehicle_land_detected":
            if bool(f["landed"]) != self.landed:
                self.landed = bool(f["landed"])
                return [LogMessage(t, "EXTENDED_SYS_STATE", _UlogMsg(
                    "EXTENDED_SYS_STATE", landed_state=1 if self.landed else 2))]
        elif topic == "mission_result":
            seq = int(f.get("seq_reached", -1))
            if seq >= 0 and seq != self.reached:
                self.reached = seq
                return [LogMessage(t, "MISSION_ITEM_REACHED", _UlogMsg("MISSION_ITEM_REACHED", seq=seq))]
        return []


def _home_of(m: Any) -> GeoPoint | None:
    """Home from a HOME_POSITION (or a GLOBAL_POSITION_INT with a fix); None without one."""
    if m.get_type() == "HOME_POSITION":
        return GeoPoint(lat=m.latitude / 1e7, lon=m.longitude / 1e7, alt=m.altitude / 1000.0)
    if m.lat == 0 and m.lon == 0:
        return None
    return GeoPoint(lat=m.lat / 1e7, lon=m.lon / 1e7, alt=(m.alt - m.relative_alt) / 1000.0)


class ReplayBackend(VehicleBackend):
    """A recorded flight played back as a vehicle that reports but cannot be commanded (see the module docstring).

    Clock ``"vehicle"``: :attr:`t` is log time (seconds since the log's first record) = ``rate`` x wall seconds
    since the first :meth:`step` (0 until then); :meth:`step` applies every message up to :attr:`t` and never
    blocks. Odometry's ``t`` is the log time up to which messages have been applied. Events (:meth:`drain_events`, each with its log time
    ``t``): ``mode`` (name), ``armed``, ``disarmed``, ``status_text`` (severity, text),
    ``mission_item_reached`` (seq; PX4 repeats the message for about a second, reported once per item),
    ``home`` (lat, lon, alt), ``link_lost``/``link_regained`` (gaps of HEARTBEAT_TIMEOUT_S in the log's
    heartbeats), and ``replay_finished`` after the last message (then :attr:`finished` is True).

    Every navigation method raises :class:`~aerodaas.backends.base.NotNavigable`.
    """

    kind = "replay"
    clock = "vehicle"
    navigable = False
    Config = ReplayConfig
    config_section = "replay"

    @classmethod
    def resolve_files(cls, robot: Any, resolve: Any, where: str) -> None:
        """The log (``replay.log``), resolved like every file of the environment and checked to hold a flight
        (:func:`check_log`): a missing or empty log fails before Ray starts. Raises ConfigError naming the field."""
        from aerodaas.config.base import ConfigError

        field = f"{where}.{cls.config_section}.log"
        robot.backend_config["log"] = log = str(resolve(cls.options(robot).log, field))
        try:
            check_log(log)
        except BackendError as e:
            raise ConfigError(f"{field}: {e}") from None

    @classmethod
    def clock_rate(cls, robot: Any) -> float | None:
        """``replay.rate``: log seconds per wall second."""
        return float(cls.options(robot).rate)

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig (settings: ReplayConfig)
        super().__init__(cfg.id, cfg.home)
        settings = self.options(cfg)
        self.log_path = str(settings.log)
        self.rate = float(settings.rate)
        self.info: dict[str, Any] = {}
        self._msgs: list[LogMessage] = []
        self._i = 0
        self._t_wall0: float | None = None
        self._t_applied = 0.0
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._att = Attitude()
        self._geo: GeoPoint | None = None
        self._bat: float | None = None  # unknown until the log reports it (battery_remaining -1 = unknown)
        self._volt = 0.0
        self._have_battery_status = False
        self._armed = False
        self._landed_state: int | None = None
        self.mode = ""
        self._last_reached: int | None = None
        self._last_hb: float | None = None
        self._link_ok = True
        self.finished = False
        self._link_monitor = True
        self._events: list[dict[str, Any]] = []
        self._clock_started = False  # the replay clock runs from the first step (see connect)

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float = 30.0) -> None:
        """Read the log (``.tlog`` or PX4 ``.ulg``) and start the replay clock. Raises BackendError for a missing, unreadable or
        unsupported log (the message names ``replay.log`` and the path)."""
        suffix = Path(self.log_path).suffix.lower()
        if not Path(self.log_path).is_file():
            raise BackendError(f"robot {self.robot_id!r}: replay.log {self.log_path!r}: file not found")
        if suffix == ".ulg":
            self._msgs, self.info = load_ulog(self.log_path)
            self._link_monitor = False  # an onboard log has no radio link to lose
        else:
            self._msgs, self.info = load_tlog(self.log_path)
        self.info["duration_s"] = self._msgs[-1].t if self._msgs else 0.0
        home = next((h for lm in self._msgs if lm.type == "HOME_POSITION" for h in [_home_of(lm.msg)] if h), None)
        home = home or next((h for lm in self._msgs if lm.type == "GLOBAL_POSITION_INT"
                             for h in [_home_of(lm.msg)] if h), None)
        if home is not None:
            self.home = home
        # the replay clock starts at the first step of the flight, not here: the actors still set up after connect
        # (a second on a loaded machine, a minute of a 60x replay's log)
        self._t_wall0 = None
        self._clock_started = False

    def close(self) -> None:
        self._t_wall0 = None
        self._clock_started = True  # stopped for good: a later step does not start it again

    @property
    def duration_s(self) -> float:
        """Log time of the last vehicle message, seconds."""
        return float(self.info.get("duration_s", 0.0))

    # ------------------------------------------------------------------ time and state
    @property
    def t(self) -> float:
        if self._t_wall0 is None:
            return self._t_applied
        return (time.monotonic() - self._t_wall0) * self.rate

    def step(self, dt: float) -> None:
        """Apply every log message with log time <= :attr:`t` (``dt`` is ignored: the log has its own clock, started
        by the first call)."""
        if not self._clock_started:
            self._clock_started = True
            self._t_wall0 = time.monotonic() - self._t_applied / self.rate
        now = self.t
        msgs = self._msgs
        while self._i < len(msgs) and msgs[self._i].t <= now:
            lm = msgs[self._i]
            self._i += 1
            self._apply(lm)
        self._t_applied = now
        if self._link_monitor and not self.finished and self._last_hb is not None:
            ok = now - self._last_hb < HEARTBEAT_TIMEOUT_S
            if ok != self._link_ok and self._i < len(msgs):
                self._link_ok = ok
                self._event("link_regained" if ok else "link_lost", now)
        if self._i >= len(msgs) and not self.finished:
            self.finished = True
            self._event("replay_finished", now, messages=len(msgs))

    def _apply(self, lm: LogMessage) -> None:
        m, t = lm.msg, lm.t
        ty = lm.type
        if ty == "GLOBAL_POSITION_INT":
            if m.lat == 0 and m.lon == 0:
                return
            e, n, _ = geodetic_to_enu(m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0, self.home)
            self._pos = np.array([e, n, m.relative_alt / 1000.0])
            self._vel = self.ned_to_enu((m.vx / 100.0, m.vy / 100.0, m.vz / 100.0))
            self._geo = GeoPoint(lat=m.lat / 1e7, lon=m.lon / 1e7, alt=m.alt / 1000.0)
        elif ty == "ATTITUDE":
            self._att = Attitude(roll=math.degrees(m.roll), pitch=math.degrees(m.pitch),
                                 yaw=self.enu_yaw_from_heading(math.degrees(m.yaw)))
        elif ty == "BATTERY_STATUS":
            if m.battery_remaining >= 0:
                self._bat, self._have_battery_status = float(m.battery_remaining), True
        elif ty == "SYS_STATUS":
            if m.voltage_battery not in (0, 65535):
                self._volt = m.voltage_battery / 1000.0
            if not self._have_battery_status and m.battery_remaining >= 0:
                self._bat = float(m.battery_remaining)
        elif ty == "HEARTBEAT":
            self._heartbeat(m, t)
        elif ty == "EXTENDED_SYS_STATE":
            self._landed_state = int(m.landed_state)
        elif ty == "HOME_POSITION":
            home = _home_of(m)
            if home is not None and (home.lat, home.lon, home.alt) != (self.home.lat, self.home.lon, self.home.alt):
                self.home = home
                self._event("home", t, lat=home.lat, lon=home.lon, alt=home.alt)
        elif ty == "STATUSTEXT":
            text = m.text if isinstance(m.text, str) else bytes(m.text).decode("utf-8", "replace")
            self._event("status_text", t, severity=int(m.severity), text=text.rstrip("\x00").strip())
        elif ty == "MISSION_ITEM_REACHED":
            if m.seq != self._last_reached:
                self._last_reached = int(m.seq)
                self._event("mission_item_reached", t, seq=int(m.seq))

    def _heartbeat(self, m: Any, t: float) -> None:
        from pymavlink import mavutil

        self._last_hb = t
        armed = bool(m.base_mode & _MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != self._armed:
            self._armed = armed
            self._event("armed" if armed else "disarmed", t)
        mode = getattr(m, "mode_name", None) or mavutil.mode_string_v10(m)
        if mode != self.mode:
            self.mode = mode
            self._event("mode", t, name=mode)

    def _event(self, kind: str, t: float, **kw: Any) -> None:
        self._events.append({"event": kind, "t": t, **kw})

    def drain_events(self) -> list[dict[str, Any]]:
        out, self._events = self._events, []
        return out

    @property
    def link_ok(self) -> bool:
        return self._link_ok

    @property
    def position(self) -> np.ndarray:
        return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        return self._vel.copy()

    @property
    def yaw(self) -> float:
        return float(self._att.yaw)

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def in_air(self) -> bool:
        if self._landed_state is not None:
            return self._landed_state in _MAV_LANDED_STATE_IN_AIR
        return self._armed and self._pos[2] > 0.5

    @property
    def battery_pct(self) -> float | None:
        """Percent from the log, or None while the log has not reported it (or reports it unknown)."""
        return self._bat

    def odometry(self) -> Odometry:
        geo = self._geo or self.home
        return Odometry(robot_id=self.robot_id, t=self._t_applied, position=tuple(float(v) for v in self._pos),
                        geodetic=geo, velocity=tuple(float(v) for v in self._vel), attitude=self._att,
                        battery_pct=None if self._bat is None else min(max(self._bat, 0.0), 100.0),
                        battery_voltage=self._volt,
                        armed=self._armed, in_air=self.in_air)

    # ------------------------------------------------------------------ control: a recording cannot be flown
    def arm(self) -> None:
        self._require_navigable("arm")

    def disarm(self) -> None:
        self._require_navigable("disarm")

    def takeoff(self, altitude_m: float) -> None:
        self._require_navigable("takeoff")

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        self._require_navigable("goto")

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        self._require_navigable("set_velocity")

    def hold(self) -> None:
        self._require_navigable("hold")

    def land(self) -> None:
        self._require_navigable("land")

    def return_to_launch(self) -> bool:
        self._require_navigable("return_to_launch")
        return False


class McapCameraReplay:
    """A camera channel of an MCAP recording (``foxglove.CompressedImage``, JPEG or PNG) as a frame source.

    ``path``: the recording; ``topic``: e.g. ``/drone1/camera/cam0`` (AeroDaaS records cameras on
    ``/<robot>/camera/<sensor>``). Frame times ``t`` are seconds since ``start_ns`` (default: the recording's
    first message on any topic, which for AeroDaaS recordings is mission time 0). Frames are decoded lazily with
    ``cv2.imdecode`` to ``(H, W, 3) uint8 BGR``; only the compressed bytes are kept in memory.

    Raises FileNotFoundError / ValueError (not an MCAP file, ``topic`` absent or not a CompressedImage channel,
    naming the topics that are there)."""

    def __init__(self, path: str | os.PathLike, topic: str, start_ns: int | None = None) -> None:
        from aerodaas.recording.writer import read_messages, summarize_mcap

        self.path, self.topic = str(path), topic
        summary = summarize_mcap(self.path)
        self.start_ns = int(summary["start_ns"] or 0) if start_ns is None else int(start_ns)
        times: list[int] = []
        self._data: list[bytes] = []
        for _, schema, t_ns, msg in read_messages(self.path, topics=[topic]):
            if schema != "foxglove.CompressedImage":
                raise ValueError(f"topic {topic!r} in {self.path!r} carries {schema!r}, not foxglove.CompressedImage")
            times.append(t_ns)
            self._data.append(bytes(msg.data))
        if not times:
            topics = [c["topic"] for c in summary["channels"]]
            raise ValueError(f"topic {topic!r} not found (or empty) in {self.path!r}; topics there: {topics}")
        order = np.argsort(np.asarray(times, np.int64), kind="stable")
        self._data = [self._data[i] for i in order]
        self.times_ns = [times[i] for i in order]
        #: frame times, seconds since ``start_ns``
        self.times = [(t - self.start_ns) / 1e9 for t in self.times_ns]

    def __len__(self) -> int:
        return len(self._data)

    def frame(self, i: int) -> np.ndarray:
        """Frame ``i`` decoded, ``(H, W, 3) uint8 BGR``. Raises IndexError / ValueError (undecodable bytes)."""
        import cv2

        img = cv2.imdecode(np.frombuffer(self._data[i], np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"{self.path!r} {self.topic!r}: frame {i} is not a decodable image")
        return img

    def frame_at(self, t: float) -> tuple[np.ndarray, float] | None:
        """The newest frame at or before ``t`` seconds and its time; None before the first frame."""
        i = bisect.bisect_right(self.times, t) - 1
        return None if i < 0 else (self.frame(i), self.times[i])

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        """``(t, frame)`` in time order."""
        for i, t in enumerate(self.times):
            yield t, self.frame(i)
