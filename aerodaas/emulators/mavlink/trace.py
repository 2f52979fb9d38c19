"""A scripted ground-station sequence in raw pymavlink that records what a MAVLink vehicle does, as a normalised
trace (JSON): the yardstick for comparing our emulator with real ArduCopter and PX4 SITL firmware.

Independent of :mod:`aerodaas.backends.mavlink` and of the emulator: modes are decoded with pymavlink's own tables
(``mavutil.mode_string_v10``, ``mode_mapping_acm``, ``px4_map``), every rule comes from the MAVLink common message
set (command, mission, parameter protocols). The sequence, as a ground station flies it:

1. wait for a HEARTBEAT, request streams (MAV_CMD_SET_MESSAGE_INTERVAL, and REQUEST_DATA_STREAM for ArduPilot);
2. read the speed parameters (ArduCopter ``WPNAV_SPEED``/``WPNAV_SPEED_UP``/``WPNAV_SPEED_DN`` cm/s; PX4
   ``MPC_XY_CRUISE``/``MPC_XY_VEL_MAX``/``MPC_Z_VEL_MAX_UP``/``MPC_Z_VEL_MAX_DN`` m/s) with PARAM_REQUEST_READ;
3. switch to GUIDED (ArduPilot) / AUTO.LOITER (PX4), retried every vehicle second while refused;
4. arm from cold, retried every vehicle second, recording each refusal and the STATUSTEXT that explains it;
5. take off (MAV_CMD_NAV_TAKEOFF) to ``alt`` metres above home;
6. upload a 2-item AUTO mission (waypoints ``leg1`` m north, then ``leg2`` m east of it, each with ``hold`` s),
   answering whichever request form the vehicle sends with MISSION_ITEM_INT, and start it (AUTO / AUTO.MISSION);
7. on arrival at waypoint 1: MAV_CMD_DO_CHANGE_SPEED −2 ("default speed"), then PARAM_SET of the horizontal speed
   parameter to ``slow`` m/s (in the firmware's unit) so leg 2 shows whether the vehicle flies at it;
8. after the last waypoint: restore the parameter, MAV_CMD_NAV_RETURN_TO_LAUNCH, wait for the landing disarm.

Recorded: mode/arm/take-off/RTL COMMAND_ACK results, refusal texts, HEARTBEAT (mode, armed) transitions,
MISSION_ITEM_REACHED (every one, with its time relative to arrival within 1 m at the waypoint), mission request
forms, max horizontal speed per leg (GLOBAL_POSITION_INT vx/vy, m/s), HOME_POSITION altitudes before and after
take-off, PARAM_VALUE replies, EKF_STATUS_REPORT flags and SYS_STATUS health at each arm attempt. Times are
vehicle seconds (``time_boot_ms``) since the first HEARTBEAT-bearing clock message.

Run: ``python -m aerodaas.emulators.mavlink.trace udpin:127.0.0.1:14550 --autopilot ardupilot --out t.json``
(exit 0 when the sequence ended with the vehicle landed and disarmed, 1 otherwise; the trace is written either way).
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from typing import Any, Callable

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.emulators import free_udp_port

__all__ = ["run_trace", "trace_emulator", "summarise", "main"]

_AP_SPEED = "WPNAV_SPEED"
_PX4_SPEED = ("MPC_XY_CRUISE", "MPC_XY_VEL_MAX")
_PARAMS = {"ardupilot": ("WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN"),
           "px4": ("MPC_XY_CRUISE", "MPC_XY_VEL_MAX", "MPC_Z_VEL_MAX_UP", "MPC_Z_VEL_MAX_DN")}
#: mission uploads started again after the vehicle gave one up (:func:`_mission`)
MISSION_UPLOAD_TRIES = 3
_REFUSAL_WORDS = ("arm", "prearm", "preflight", "denied", "fail", "need", "not ")
_STREAMS_HZ = {M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0, M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
               M.MAVLINK_MSG_ID_HOME_POSITION: 1.0, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 2.0,
               M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0, M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
               M.MAVLINK_MSG_ID_SYSTEM_TIME: 2.0}
_AP_EKF_STATUS_REPORT = 193  # ardupilotmega.xml


def _bits(value: int, enum: str) -> list[str]:
    """Names of the bits set in ``value`` for the MAVLink enum ``enum``."""
    table = M.enums[enum]
    return sorted(e.name for k, e in table.items() if k and k & (k - 1) == 0 and value & k and not e.name.endswith("_END"))


class _Tracer:
    def __init__(self, conn: str, autopilot: str, wall_limit_s: float, alt: float) -> None:
        self.m = mavutil.mavlink_connection(conn, source_system=255, source_component=190, dialect="ardupilotmega")
        self.ap = autopilot
        self.px4 = autopilot == "px4"
        self.alt = alt
        self.wall_end = time.monotonic() + wall_limit_s
        self.t0: float | None = None  # vehicle seconds at the first clock message
        self.vt = 0.0  # vehicle seconds since t0
        self.mode: str | None = None
        self.armed: bool | None = None
        self.pos: Any = None  # last GLOBAL_POSITION_INT
        self.home_alts: list[tuple[float, float]] = []
        self.texts: list[tuple[float, str]] = []
        self.acks: list[tuple[float, int, int]] = []
        self.reached: list[tuple[float, int]] = []
        self.params: dict[str, dict] = {}
        self.requests: list[str] = []
        self.mission_acks: list[int] = []
        self.ekf_flags: int | None = None
        self.health: tuple[int, int, int] | None = None
        self.speed_log: list[tuple[float, float]] = []
        self.in_air_alt = False
        self.tr: dict[str, Any] = {"autopilot": autopilot, "transitions": [], "mode_acks": [], "arm_acks": [],
                                   "statustexts": []}
        self.sysid = 1
        self.compid = 1
        self.mission: list[tuple] = []  # (MAV_CMD, lat deg, lon deg, alt m, param1) per wire sequence
        self.wps: list[tuple[float, float]] = []  # the mission's waypoints (deg), for arrival times
        self.arrivals: dict[int, float] = {}  # waypoint index -> vehicle s of the first arrival within 1 m

    # -------------------------------------------------------------- receive
    def pump(self, wall_s: float = 0.02) -> None:
        end = time.monotonic() + wall_s
        while True:
            msg = self.m.recv_match(blocking=True, timeout=max(0.0, end - time.monotonic()))
            if msg is None:
                return
            self._on(msg)
            if time.monotonic() >= end:
                return

    def _on(self, msg: Any) -> None:
        t = msg.get_type()
        if t == "BAD_DATA":
            return
        if msg.get_srcSystem() == 255:
            return
        tb = getattr(msg, "time_boot_ms", None)
        if tb is not None and t in ("GLOBAL_POSITION_INT", "SYSTEM_TIME", "ATTITUDE", "LOCAL_POSITION_NED"):
            if self.t0 is None:
                self.t0 = tb / 1000.0
            self.vt = max(self.vt, tb / 1000.0 - self.t0)
        if t == "HEARTBEAT":
            if msg.type in (M.MAV_TYPE_GCS,) or msg.autopilot == M.MAV_AUTOPILOT_INVALID:
                return
            self.sysid, self.compid = msg.get_srcSystem(), msg.get_srcComponent()
            self.tr.setdefault("heartbeat", {"autopilot": msg.autopilot, "type": msg.type})
            mode = mavutil.mode_string_v10(msg)
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            if (mode, armed) != (self.mode, self.armed):
                self.mode, self.armed = mode, armed
                self.tr["transitions"].append({"t": round(self.vt, 2), "mode": mode, "armed": armed})
        elif t == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            text = text.rstrip("\x00")
            self.texts.append((self.vt, text))
            self.tr["statustexts"].append([round(self.vt, 2), msg.severity, text])
        elif t == "COMMAND_ACK":
            self.acks.append((self.vt, msg.command, msg.result))
        elif t == "GLOBAL_POSITION_INT":
            self.pos = msg
            if msg.lat or msg.lon:
                self.speed_log.append((self.vt, math.hypot(msg.vx, msg.vy) / 100.0))
                for k, (lat, lon) in enumerate(self.wps):  # first arrival within 1 m, in order
                    if k not in self.arrivals and (k == 0 or k - 1 in self.arrivals) and _dist(msg, lat, lon) < 1.0:
                        self.arrivals[k] = self.vt
        elif t == "HOME_POSITION":
            self.home_alts.append((self.vt, msg.altitude / 1000.0))
        elif t == "MISSION_ITEM_REACHED":
            self.reached.append((self.vt, msg.seq))
        elif t == "PARAM_VALUE":
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
            self.params.setdefault(name.rstrip("\x00"), {"value": msg.param_value, "type": msg.param_type,
                                                         "count": msg.param_count})
            self.params[name.rstrip("\x00")]["last"] = msg.param_value
        elif t in ("MISSION_REQUEST", "MISSION_REQUEST_INT"):
            self.requests.append(t)
            self._send_item(msg.seq)
        elif t == "MISSION_ACK":
            self.mission_acks.append(msg.type)
        elif t == "EKF_STATUS_REPORT":
            if msg.flags != self.ekf_flags:
                self.tr.setdefault("ekf_flag_changes", []).append([round(self.vt, 2), _bits(msg.flags, "EKF_STATUS_FLAGS")])
            self.ekf_flags = msg.flags
        elif t == "SYS_STATUS":
            h = (msg.onboard_control_sensors_present, msg.onboard_control_sensors_enabled,
                 msg.onboard_control_sensors_health)
            if h != self.health:
                self.tr.setdefault("sys_status_changes", []).append(
                    {"t": round(self.vt, 2), "present": _bits(h[0], "MAV_SYS_STATUS_SENSOR"),
                     "not_enabled": _bits(h[0] & ~h[1], "MAV_SYS_STATUS_SENSOR"),
                     "unhealthy": _bits(h[0] & ~h[2], "MAV_SYS_STATUS_SENSOR")})
            self.health = h

    def wait(self, pred: Callable[[], bool], vehicle_s: float) -> bool:
        start = self.vt
        while time.monotonic() < self.wall_end:
            if pred():
                return True
            if self.vt - start > vehicle_s:
                return False
            self.pump()
        return False

    def sleep(self, vehicle_s: float) -> None:
        self.wait(lambda: False, vehicle_s)

    # -------------------------------------------------------------- send
    def command(self, cmd: int, *p: float, vehicle_s: float = 3.0) -> int | None:
        """COMMAND_LONG, re-sent up to 4 times without an answer (a loaded machine loses UDP datagrams and PX4
        drops messages over its link's data rate); returns the final MAV_RESULT or None."""
        p = list(p) + [0.0] * (7 - len(p))
        for confirmation in range(4):
            n = len(self.acks)
            self.m.mav.command_long_send(self.sysid, self.compid, cmd, confirmation, *p)
            got = self.wait(lambda: any(a[1] == cmd and a[2] != M.MAV_RESULT_IN_PROGRESS for a in self.acks[n:]),
                            vehicle_s)
            if got:
                return next(a[2] for a in self.acks[n:] if a[1] == cmd and a[2] != M.MAV_RESULT_IN_PROGRESS)
        return None

    def mode_args(self, name: str) -> tuple[float, float, float]:
        if self.px4:
            base, main, sub = mavutil.px4_map[name]
            return float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub)
        num = {v: k for k, v in mavutil.mode_mapping_acm.items()}[name]
        return float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(num), 0.0

    def set_mode(self, name: str, tries: int = 1, why: str = "") -> int | None:
        res = None
        for _ in range(tries):
            n = len(self.texts)
            res = self.command(M.MAV_CMD_DO_SET_MODE, *self.mode_args(name))
            self.sleep(0.3)
            self.tr["mode_acks"].append({"t": round(self.vt, 2), "mode": name, "why": why, "result": _res(res),
                                         "texts": [x for _, x in self.texts[n:]]})
            if res == M.MAV_RESULT_ACCEPTED:
                return res
            self.sleep(1.0)
        return res

    def param(self, name: str, value: float | None = None) -> dict | None:
        """PARAM_REQUEST_READ (value None) or PARAM_SET; the PARAM_VALUE answer (dict) or None."""
        self.params.pop(name, None)
        for _ in range(5):
            if value is None:
                self.m.mav.param_request_read_send(self.sysid, self.compid, name.encode(), -1)
            else:
                self.m.mav.param_set_send(self.sysid, self.compid, name.encode(), float(value),
                                          M.MAV_PARAM_TYPE_REAL32)
            if self.wait(lambda: name in self.params, 2.0):
                return dict(self.params[name])
        return None

    # -------------------------------------------------------------- mission
    def _send_item(self, seq: int) -> None:
        if not 0 <= seq < len(self.mission):
            return
        cmd, lat, lon, alt, p1 = self.mission[seq]
        frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if seq or self.px4 else M.MAV_FRAME_GLOBAL_INT
        self.m.mav.mission_item_int_send(self.sysid, self.compid, seq, frame, cmd, 0, 1, p1, 0, 0, math.nan,
                                         int(round(lat * 1e7)), int(round(lon * 1e7)), alt, 0)


def _res(r: int | None) -> str:
    return "NO_ANSWER" if r is None else M.enums["MAV_RESULT"][r].name.replace("MAV_RESULT_", "")


def _offset(lat: float, lon: float, north: float, east: float) -> tuple[float, float]:
    return (lat + math.degrees(north / 6378137.0),
            lon + math.degrees(east / (6378137.0 * math.cos(math.radians(lat)))))


def _dist(p: Any, lat: float, lon: float) -> float:
    dn = math.radians(p.lat / 1e7 - lat) * 6378137.0
    de = math.radians(p.lon / 1e7 - lon) * 6378137.0 * math.cos(math.radians(lat))
    return math.hypot(dn, de)


def run_trace(conn: str, autopilot: str, *, wall_limit_s: float = 600.0, alt: float = 5.0, leg1: float = 60.0,
              leg2: float = 20.0, hold: float = 3.0, slow: float = 2.0) -> dict:
    """Fly the scripted sequence (module docstring) on ``conn`` (pymavlink connection string) against an
    ``autopilot`` ("ardupilot" or "px4") vehicle; returns the trace dict (``ok`` True when it ended landed and
    disarmed). ``alt`` m above home, ``leg1``/``leg2`` m, ``hold`` s, ``slow`` m/s; ``wall_limit_s`` caps the
    whole run in wall seconds. Raises ValueError for another autopilot."""
    if autopilot not in ("ardupilot", "px4"):
        raise ValueError(f"autopilot must be 'ardupilot' or 'px4', got {autopilot!r}")
    T = _Tracer(conn, autopilot, wall_limit_s, alt)
    tr = T.tr
    tr["ok"] = False
    try:
        _sequence(T, tr, leg1, leg2, hold, slow)
    except Exception as e:  # noqa: BLE001 - a trace is written whatever happened
        tr["error"] = f"{type(e).__name__}: {e}"
    tr["t_end"] = round(T.vt, 2)
    tr["home_alts"] = [[round(t, 2), round(a, 3)] for t, a in T.home_alts]
    tr["reached_raw"] = [[round(t, 2), s] for t, s in T.reached]
    tr["mission_request_types"] = sorted(set(T.requests))
    T.m.close()
    return tr


def _sequence(T: _Tracer, tr: dict, leg1: float, leg2: float, hold: float, slow: float) -> None:
    """The traced flight, stage by stage (``tr["stage"]`` says where it stopped): pre-flight, arm, take-off, a
    two-leg mission, return to launch."""
    if not T.wait(lambda: T.mode is not None, 1e9):
        tr["stage"] = "no heartbeat"
        return
    _preflight(T, tr)
    armed_at = _arm(T, tr)
    if armed_at is None:
        return
    took_off, home_alt = _takeoff(T, tr, armed_at)
    if not took_off:
        return
    flown = _mission(T, tr, leg1, leg2, hold, slow)
    if flown is not None:
        _return_to_launch(T, tr, *flown, home_alt)


def _preflight(T: _Tracer, tr: dict) -> None:
    """Telemetry streams, the pre-arm mode, an arm before the vehicle is ready (its refusal), the parameters."""
    tr["stage"] = "streams"
    for mid, hz in _STREAMS_HZ.items():
        res = T.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, mid, 1e6 / hz)
        tr.setdefault("interval_acks", {})[M.mavlink_map[mid].msgname] = [_res(res), round(T.vt, 2)]
    if not T.px4:
        T.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, _AP_EKF_STATUS_REPORT, 1e6 / 2)
        for sid in (M.MAV_DATA_STREAM_EXTENDED_STATUS, M.MAV_DATA_STREAM_POSITION, M.MAV_DATA_STREAM_EXTRA3):
            T.m.mav.request_data_stream_send(T.sysid, T.compid, sid, 2, 1)
    tr["stage"] = "mode"
    T.set_mode("LOITER" if T.px4 else "GUIDED", tries=120, why="pre-arm")
    tr["stage"] = "cold arm"
    n = len(T.texts)
    res = T.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    T.sleep(0.3)
    tr["cold_arm"] = {"t": round(T.vt, 2), "result": _res(res), "mode": T.mode,
                      "texts": [x for _, x in T.texts[n:] if any(w in x.lower() for w in _REFUSAL_WORDS)]}
    if res == M.MAV_RESULT_ACCEPTED:
        T.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    tr["stage"] = "params"
    tr["params"] = {n: T.param(n) for n in _PARAMS[T.ap]}
    tr["param_unknown"] = T.param("NO_SUCH_PARAM")


def _arm(T: _Tracer, tr: dict) -> float | None:
    """Arm, retried each vehicle second (at most 180 tries); the vehicle time it armed at, None if it never did."""
    tr["stage"] = "arm"
    armed_at = None
    for _ in range(180):
        n = len(T.texts)
        res = T.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        T.sleep(0.3)
        entry = {"t": round(T.vt, 2), "result": _res(res), "mode": T.mode,
                 "texts": [x for _, x in T.texts[n:] if any(w in x.lower() for w in _REFUSAL_WORDS)]}
        if T.ekf_flags is not None:
            entry["ekf_flags"] = _bits(T.ekf_flags, "EKF_STATUS_FLAGS")
        if T.health is not None:
            entry["health_missing"] = _bits(T.health[0] & ~T.health[2], "MAV_SYS_STATUS_SENSOR")
            entry["present"] = _bits(T.health[0], "MAV_SYS_STATUS_SENSOR")
        tr["arm_acks"].append(entry)
        if res == M.MAV_RESULT_ACCEPTED:
            armed_at = T.vt
            break
        T.sleep(1.0)
    return armed_at


def _takeoff(T: _Tracer, tr: dict, armed_at: float) -> tuple[bool, float | None]:
    """Take off to ``T.alt``: (reached it, the home altitude at arming)."""
    tr["armable_after_s"] = round(armed_at, 2)
    T.wait(lambda: bool(T.home_alts), 3.0)
    home_alt = T.home_alts[-1][1] if T.home_alts else None
    tr["home_alt_at_arm"] = home_alt
    tr["stage"] = "takeoff"
    p7 = (home_alt + T.alt) if T.px4 and home_alt is not None else T.alt
    res = T.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, p7)
    tr["takeoff_ack"] = _res(res)
    if not T.wait(lambda: T.pos is not None and T.pos.relative_alt / 1000.0 > T.alt - 0.5, 60.0):
        tr["stage"] = "takeoff timeout"
        return False, home_alt
    tr["takeoff_done_t"] = round(T.vt, 2)
    T.wait(lambda: T.mode in ("LOITER", "GUIDED") and T.speed_log and T.speed_log[-1][1] < 0.3, 20.0)
    return True, home_alt


def _mission(T: _Tracer, tr: dict, leg1: float, leg2: float, hold: float,
             slow: float) -> tuple[list[dict], float, int] | None:
    """Upload and fly the two-leg mission (the speed parameter lowered to ``slow`` m/s after the first leg): (the
    legs, the vehicle time it started, the STATUSTEXT count before it), None when it did not fly."""
    lat0, lon0 = T.pos.lat / 1e7, T.pos.lon / 1e7
    wp1 = _offset(lat0, lon0, leg1, 0.0)
    wp2 = _offset(wp1[0], wp1[1], 0.0, leg2)
    items = [(M.MAV_CMD_NAV_WAYPOINT, wp1[0], wp1[1], T.alt, hold), (M.MAV_CMD_NAV_WAYPOINT, wp2[0], wp2[1], T.alt, hold)]
    if not T.px4:  # ArduPilot's item 0 is home (overwritten by the vehicle)
        items.insert(0, (M.MAV_CMD_NAV_WAYPOINT, lat0, lon0, 0.0, 0.0))
    T.mission = items
    tr["stage"] = "mission upload"
    # a transfer the vehicle gave up on is started again from the count, as the mission protocol lets a ground
    # station do (mavlink.io, "Mission Protocol"): PX4 drops one when nothing arrives for 5 s of its own clock
    # ("Operation timeout", MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT, src/modules/mavlink/mavlink_mission.cpp), 1 s
    # of wall time at 5x: a loaded machine's tracer answered later and PX4 ignored its items
    for tries in range(1, MISSION_UPLOAD_TRIES + 1):
        T.mission_acks.clear()
        T.m.mav.mission_count_send(T.sysid, T.compid, len(items), M.MAV_MISSION_TYPE_MISSION)
        if not T.wait(lambda: bool(T.mission_acks), 15.0):
            return None
        if T.mission_acks[-1] == M.MAV_MISSION_ACCEPTED:
            break
    tr["mission_ack"] = M.enums["MAV_MISSION_RESULT"][T.mission_acks[-1]].name
    tr["mission_upload_tries"] = tries
    n_texts = len(T.texts)
    tr["stage"] = "mission"
    first = 0 if T.px4 else 1
    t_start = T.vt
    res = T.set_mode("MISSION" if T.px4 else "AUTO", tries=3, why="mission")
    if res != M.MAV_RESULT_ACCEPTED:
        return None
    legs: list[dict] = []
    T.wps = [wp1, wp2]
    for k in range(2):
        seq = first + k
        # leg 2 from the departure: the end of waypoint 1's hold (its first MISSION_ITEM_REACHED, both firmware)
        t_leg = t_start if k == 0 else min([t for t, s in T.reached if s == seq - 1] or [T.arrivals[0] + hold])
        # leg 2 tells the parameter's effect only if its echo came before the departure (PX4 reads the cruise
        # speed when an item starts); on a loaded machine it may come later: then None
        late = k == 1 and legs[0].get("param_set_t", 0.0) > T.arrivals[0] + hold - 0.5
        if not T.wait(lambda: k in T.arrivals, 120.0):
            tr["stage"] = f"wp{k + 1} timeout"
            return None
        arrived = T.arrivals[k]
        # None: the parameter's echo came after the leg (a loaded machine), so the leg says nothing about it
        vmax = None if late else max((v for t, v in T.speed_log if t_leg <= t <= arrived), default=None)
        leg = {"seq": seq, "arrival_t": round(arrived, 2), "max_speed": None if vmax is None else round(vmax, 2)}
        if k == 0:
            leg["change_speed_minus2"] = _res(T.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, -2, -1))
            value = slow * 100.0 if not T.px4 else slow
            leg["param_set"] = {n: T.param(n, value) for n in ((_AP_SPEED,) if not T.px4 else _PX4_SPEED)}
            leg["param_set_t"] = round(T.vt, 2)
        if not T.wait(lambda: any(s == seq for _, s in T.reached), hold + 20.0):
            leg["reached"] = None
        legs.append(leg)
    return legs, t_start, n_texts


def _return_to_launch(T: _Tracer, tr: dict, legs: list[dict], t_start: float, n_texts: int,
                      home_alt: float | None) -> None:
    """After the mission: its texts, the parameters restored, RTL to the landing, and the reached reports."""
    tr["legs"] = legs
    T.wait(lambda: T.mode not in ("AUTO", "MISSION"), 4.0)  # mission end: PX4 goes to LOITER, ArduPilot stays
    tr["after_mission_mode"] = T.mode
    tr["mission_texts"] = [x for _, x in T.texts[n_texts:]]
    for n, pv in tr["params"].items():
        if pv is not None and n in ((_AP_SPEED,) if not T.px4 else _PX4_SPEED):
            T.param(n, pv["value"])
    tr["stage"] = "rtl"
    tr["rtl_ack"] = _res(T.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH))
    if not T.wait(lambda: T.armed is False, 200.0):
        tr["stage"] = "rtl timeout"
        return
    tr["landed_t"] = round(T.vt, 2)
    tr["stage"] = "done"
    tr["ok"] = True
    # reached events: when, relative to arrival
    for leg in legs:
        ts = [t for t, s in T.reached if s == leg["seq"]]
        leg["reached_count"] = len(ts)
        leg["reached_after_arrival_s"] = [round(t - leg["arrival_t"], 2) for t in ts]
    tr["t_start_mission"] = round(t_start, 2)
    if home_alt is not None:
        after = [a for t, a in T.home_alts if t > tr["takeoff_done_t"]]
        tr["home_alt_drift_m"] = round(max((abs(a - home_alt) for a in after), default=0.0), 3)




def summarise(tr: dict) -> dict:
    """The comparable part of a trace: acknowledgement results, refusal texts, mode sequence, reached events
    (count, first one relative to arrival, s), max horizontal speed per leg (m/s), parameter values, home drift."""
    legs = tr.get("legs") or []
    modes: list[str] = []
    for x in tr.get("transitions", []):
        label = f"{x['mode']}{'+armed' if x['armed'] else ''}"
        if not modes or modes[-1] != label:
            modes.append(label)
    return {
        "ok": tr.get("ok"), "stage": tr.get("stage"),
        "cold_arm": (tr.get("cold_arm") or {}).get("result"),
        "refusal_results": sorted({a["result"] for a in tr.get("arm_acks", []) if a["result"] != "ACCEPTED"}),
        "refusal_texts": sorted({x for a in tr.get("arm_acks", []) + [tr.get("cold_arm") or {"texts": []}]
                                 for x in a["texts"] if "Arming motors" not in x and "Armed by" not in x}),
        "arm_final": (tr.get("arm_acks") or [{}])[-1].get("result"),
        "armable_after_s": tr.get("armable_after_s"),
        "mode_results": sorted({(m["mode"], m["result"]) for m in tr.get("mode_acks", [])}),
        "modes": modes,
        "takeoff": tr.get("takeoff_ack"), "rtl": tr.get("rtl_ack"), "mission_ack": tr.get("mission_ack"),
        "mission_requests": tr.get("mission_request_types"),
        "change_speed_minus2": legs[0].get("change_speed_minus2") if legs else None,
        "param_set_echo": {k: (v or {}).get("last") for k, v in (legs[0].get("param_set") or {}).items()} if legs else {},
        "params": {k: (v or {}).get("value") for k, v in (tr.get("params") or {}).items()},
        "param_types": sorted({(v or {}).get("type") for v in (tr.get("params") or {}).values()}, key=str),
        "param_unknown": tr.get("param_unknown"),
        "reached_count": [leg.get("reached_count") for leg in legs],
        "reached_first_after_arrival_s": [(leg.get("reached_after_arrival_s") or [None])[0] for leg in legs],
        "leg_max_speed": [leg.get("max_speed") for leg in legs],
        "after_mission_mode": tr.get("after_mission_mode"),
        "home_alt_drift_m": tr.get("home_alt_drift_m"),
    }


def trace_emulator(autopilot: str, speedup: float = 10.0, wall_limit_s: float = 300.0,
                   emulator: dict | None = None) -> dict:
    """:func:`run_trace` against our emulator (``autopilot`` flavour, ``speedup`` x real time, ``emulator``:
    keyword arguments of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator`, JSON-able) in a child
    process on a free loopback UDP port; the vehicle sends to the tracer as the SITL firmware does (``udpout`` ->
    ``udpin``)."""
    port = free_udp_port()
    spec = json.dumps({"autopilot": autopilot, "speedup": speedup, **(emulator or {})})
    code = ("import json, sys, time; from aerodaas.emulators.mavlink import MavlinkVehicleEmulator as E; "
            f"e = E(**json.loads(sys.argv[1])); e.start('udpout:127.0.0.1:{port}'); time.sleep(1e6)")
    proc = subprocess.Popen([sys.executable, "-c", code, spec], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        tr = run_trace(f"udpin:127.0.0.1:{port}", autopilot, wall_limit_s=wall_limit_s)
    finally:
        proc.kill()
        _, err = proc.communicate(timeout=10)
    if not tr.get("ok") and err:
        tr["emulator_stderr"] = err.decode(errors="replace")[-2000:]
    return tr


def main(argv: list[str] | None = None) -> int:
    """CLI: ``CONNECTION --autopilot ardupilot|px4 [--out FILE] [--wall-limit S]``; exit 0 when the vehicle flew
    the whole sequence and landed, 1 otherwise, 2 for bad arguments."""
    ap = argparse.ArgumentParser(prog="python -m aerodaas.emulators.mavlink.trace", description=__doc__.split("\n")[0])
    ap.add_argument("connection", help="pymavlink connection string, or 'emulator' for our emulated vehicle")
    ap.add_argument("--autopilot", choices=["ardupilot", "px4"], required=True)
    ap.add_argument("--out", default="-")
    ap.add_argument("--wall-limit", type=float, default=600.0)
    ap.add_argument("--emulator", default="{}", help="emulator keyword arguments as JSON (connection 'emulator')")
    a = ap.parse_args(argv)
    if a.connection == "emulator":
        tr = trace_emulator(a.autopilot, wall_limit_s=a.wall_limit, emulator=json.loads(a.emulator))
    else:
        tr = run_trace(a.connection, a.autopilot, wall_limit_s=a.wall_limit)
    text = json.dumps(tr, indent=1)
    if a.out == "-":
        print(text)
    else:
        with open(a.out, "w") as f:
            f.write(text)
    return 0 if tr.get("ok") else 1


if __name__ == "__main__":
    sys.exit(main())
