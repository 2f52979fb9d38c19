"""Flight logs read into the vehicle messages a replay plays: a MAVLink telemetry log (``.tlog``) and a PX4 flight
log (``.ulg``).

:func:`load_tlog` reads a ``.tlog`` (pymavlink's reader; the format is each MAVLink packet prefixed by its capture
time, a big-endian uint64 of microseconds); :func:`load_ulog` turns a ULog's uORB topics into the same MAVLink
messages, in MAVLink units. Both give :class:`LogMessage`\\ s in log order, which
:class:`aerodaas.backends.replay.ReplayBackend` plays; :func:`check_log` checks, before Ray starts, that a log can
be replayed.

Only the vehicle's own messages count (the autopilot: the first HEARTBEAT whose autopilot is not
``MAV_AUTOPILOT_INVALID``); a GCS's messages, unknown message ids and bad data are skipped. A log captured through
a router that forwards each packet on two links holds it twice: a packet is a duplicate when the same sender
(system, component) sent a packet with the same sequence number and message id within the last
:data:`DUPLICATE_WINDOW_PACKETS` packets of that sender and :data:`DUPLICATE_WINDOW_S` seconds (MAVLink's 8-bit
``seq`` counts per sender and link, so a window far shorter than its 256-packet wrap never mistakes a later packet,
and a genuinely repeated message — a STATUSTEXT sent twice — has its own sequence number and is kept).
"""
from __future__ import annotations

from collections import deque
import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aerodaas.backends.base import BackendError

__all__ = ["check_log", "load_tlog", "load_ulog", "LogMessage", "DUPLICATE_WINDOW_S"]

#: a packet repeating the (sequence number, message id) of one of its sender's last DUPLICATE_WINDOW_PACKETS packets,
#: seen less than DUPLICATE_WINDOW_S seconds before, is a duplicate from a second link
DUPLICATE_WINDOW_S = 0.5
DUPLICATE_WINDOW_PACKETS = 32
#: MAVLink messages the replay uses
TLOG_TYPES = ("HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "BATTERY_STATUS", "SYS_STATUS", "HOME_POSITION",
              "EXTENDED_SYS_STATE", "STATUSTEXT", "MISSION_ITEM_REACHED")
_MAV_AUTOPILOT_INVALID = 8
_MAV_TYPE_GCS = 6
#: HEARTBEAT ``base_mode`` bit of an armed vehicle
MAV_MODE_FLAG_SAFETY_ARMED = 128


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
    from pymavlink import mavutil  # lazy: heavy pymavlink

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
        from pyulog import ULog  # lazy: heavy pyulog
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
                    "HEARTBEAT", base_mode=MAV_MODE_FLAG_SAFETY_ARMED if now[0] else 0, mode_name=now[1]))]
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
