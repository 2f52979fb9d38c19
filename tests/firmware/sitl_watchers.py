"""Watchers beside a SITL flight, each independent of AeroDaaS's own view (run as ``python -m tests.firmware.sitl_watchers
COMMAND ...`` from the steps of :func:`tests.firmware.sitl.run_in_namespace`): followers of the firmware's own telemetry
(``observe``, ``observe-raw``, ``observe-truth``), the faults (``stop-when-flying``: the firmware SIGSTOPped,
``freeze-our-drone``: our drone actor SIGSTOPped) and ``real-time-when-ready`` (an ArduCopter booted fast, then
slowed to real time once it passes its pre-arm checks)."""
from __future__ import annotations

import json
import math
import os
import signal
import sys
import time
from pathlib import Path

from tests.firmware.sitl import FARM_HOME


def wait_until(cond, timeout_s: float, every_s: float = 0.2) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(every_s)
    return False


def observe(conn: str, out: str, timeout_s: float, ready: str | None = None) -> int:
    """Follow a vehicle with the MAVLink backend (never commanding it) until it has been armed and is disarmed
    again, or ``timeout_s`` wall seconds; write ``{"armed": bool, "samples": [[t, x, y, z, vx, vy], ...]`` (x, y
    ENU metres from :data:`FARM_HOME`, z above the vehicle's home),
    "events": [...]}`` to ``out`` (whole: written beside it, then renamed). Used on the vehicle's second link
    around ``aerodaas mission upload --start``; ``ready``: a file created once connected (the upload waits for it)."""
    from aerodaas.backends import make_backend
    from aerodaas.config import MavlinkConfig, RobotConfig
    from aerodaas.model.geo import geodetic_to_enu
    from aerodaas.model.types import GeoPoint

    b = make_backend(RobotConfig(id="observer", backend="mavlink", home=FARM_HOME,
                                 mavlink=MavlinkConfig(connection=conn, set_speed_limits=False)))
    b.connect(timeout_s=60)
    if ready:
        Path(ready).touch()
    samples, was_armed = [], False
    end = time.monotonic() + timeout_s
    try:
        while time.monotonic() < end:
            was_armed = was_armed or b.state().armed
            g, v = b.telemetry.odometry().geodetic, b.state().velocity
            e, n, _ = geodetic_to_enu(g.lat, g.lon, FARM_HOME["alt"], GeoPoint(**FARM_HOME))
            samples.append([b.t, float(e), float(n), float(b.state().position[2]), float(v[0]), float(v[1])])
            if was_armed and not b.state().armed and not b.state().in_air:
                break
            time.sleep(0.05)
    finally:
        events = b.drain_events()
        b.close()
    part = Path(out + ".part")
    part.write_text(json.dumps({"armed": was_armed, "landed": was_armed and not b.state().armed,
                                "samples": samples, "events": events}, default=str))
    os.replace(part, out)
    return 0


def observe_raw(conn: str, out: str, timeout_s: float, per_sysid: dict[int, str] | None = None) -> int:
    """Follow a vehicle in raw pymavlink, independent of AeroDaaS (its own link, system id 253): HEARTBEAT's armed
    flag and every GLOBAL_POSITION_INT (asked at 10 Hz with MAV_CMD_SET_MESSAGE_INTERVAL), until it has been armed
    and is disarmed again (+1 s) or ``timeout_s`` wall seconds. Writes ``{"armed", "landed", "samples": [[t, x, y,
    z, vx, vy], ...], "complete"}`` to ``out`` (also when stopped by SIGTERM; ``complete``: it was seen disarmed
    for 1 s): t the firmware's own ``time_boot_ms`` in seconds, x/y ENU metres from :data:`FARM_HOME`, z
    ``relative_alt`` metres, vx/vy ENU m/s.

    ``per_sysid`` (system id -> output file, ``out`` then unused): several vehicles on one port, each followed on
    its own. PX4 SITL sends every instance's ground-station link to 127.0.0.1:14550 (``px4-rc.mavlink``: ``mavlink
    start -x -u 18570+i`` has no ``-o``, so the remote port is the default 14550), so a PX4 fleet is observed on
    one port and told apart by the MAVLink header's system id."""
    from pymavlink import mavutil

    from aerodaas.model.types import GeoPoint

    home = GeoPoint(**FARM_HOME)
    m = mavutil.mavlink_connection(conn, source_system=253, source_component=190)
    end = time.monotonic() + timeout_s
    outs: dict = dict(per_sysid) if per_sysid else {None: out}
    st = {k: {"samples": [], "armed": False, "was_armed": False, "disarmed_at": None} for k in outs}
    seen: set[int] = set()
    # stopped early (the step's SIGTERM when the run ended without every vehicle landing): write what was seen
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        _follow_raw(m, st, seen, end, per_sysid is not None, home)
    finally:
        # the step takes a file's existence for done: each is written whole (a temporary file renamed), and a
        # second SIGTERM does not cut the writing short
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        for k, path in outs.items():
            s = st[k]
            tmp = Path(f"{path}.tmp")
            tmp.write_text(json.dumps({"armed": s["was_armed"], "landed": s["was_armed"] and not s["armed"],
                                       "samples": s["samples"], "complete": _done(s)}))
            os.replace(tmp, path)
    return 0


def _done(s: dict) -> bool:
    """A followed vehicle was armed and has been disarmed for 1 s."""
    return s["disarmed_at"] is not None and time.monotonic() - s["disarmed_at"] > 1.0


def _follow_raw(m, st: dict, seen: set, end: float, per_sysid: bool, home) -> None:
    """observe_raw's loop: until every followed vehicle has been disarmed for 1 s, or ``end``."""
    from aerodaas.model.geo import geodetic_to_enu

    next_hb = 0.0
    while time.monotonic() < end and not all(_done(s) for s in st.values()):
        if time.monotonic() >= next_hb:
            m.mav.heartbeat_send(6, 8, 0, 0, 4)
            for sysid in sorted(seen):
                m.mav.command_long_send(sysid, 1, 511, 0, 33, 100000, 0, 0, 0, 0, 0)
            next_hb = time.monotonic() + 1.0
        msg = m.recv_match(type=["HEARTBEAT", "GLOBAL_POSITION_INT"], blocking=True, timeout=0.5)
        if msg is None:
            continue
        key = msg.get_srcSystem() if per_sysid else None
        s = st.get(key)
        if s is None:
            continue
        if msg.get_type() == "HEARTBEAT":
            if msg.autopilot == 8 or msg.type == 6:
                continue
            seen.add(msg.get_srcSystem())
            s["armed"] = bool(msg.base_mode & 128)
            s["was_armed"] = s["was_armed"] or s["armed"]
            if s["was_armed"] and not s["armed"] and s["disarmed_at"] is None:
                s["disarmed_at"] = time.monotonic()
        elif msg.lat or msg.lon:
            e, n, _ = geodetic_to_enu(msg.lat / 1e7, msg.lon / 1e7, home.alt, home)
            s["samples"].append([msg.time_boot_ms / 1000.0, float(e), float(n), msg.relative_alt / 1000.0,
                                 msg.vy / 100.0, msg.vx / 100.0])


def observe_truth(conn: str, out: str, timeout_s: float, stop: tuple[int, float, float] | None = None) -> int:
    """Follow a PX4 SIH on its ground-station link in raw pymavlink (system id 253) until it has been armed and is
    disarmed again (+1 s) or ``timeout_s`` wall seconds: SIH's ground truth (HIL_STATE_QUATERNION) and the
    estimate (GLOBAL_POSITION_INT), each asked at 20 Hz. Writes ``{"truth": [[wall_s, horizontal m/s, alt m AMSL],
    ...], "estimate": [[wall_s, horizontal m/s, relative_alt m], ...], "armed_s": wall_s or None, "disarmed_s": wall_s
    or None}`` (wall: this observer's monotonic clock; the first HEARTBEAT armed after one disarmed, the first
    disarmed after that; HIL_STATE_QUATERNION carries no time stamp on SIH). ``stop`` (pid, delay_s, stop_s): also what
    :func:`stop_when_flying` does, from this link (one process per UDP port), while observing on. SIGTERM ends
    the observation early, the file written all the same."""
    import signal
    import threading

    from pymavlink import mavutil

    m = mavutil.mavlink_connection(conn, source_system=253, source_component=190)
    end = time.monotonic() + timeout_s
    truth, est = [], []
    sysid, was, armed_at, disarmed_at, next_req = None, False, None, None, 0.0
    seen_disarmed = False  # an arm counts only when the vehicle was heard disarmed first (not joined in flight)
    ended: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, frame: ended.append(signum))
    while time.monotonic() < end and not ended and not (disarmed_at and time.monotonic() - disarmed_at > 1.0):
        if time.monotonic() >= next_req:
            m.mav.heartbeat_send(6, 8, 0, 0, 4)
            for mid in (115, 33) if sysid else ():
                m.mav.command_long_send(sysid, 1, 511, 0, mid, 50000, 0, 0, 0, 0, 0)
            next_req = time.monotonic() + 2.0
        msg = m.recv_match(type=["HEARTBEAT", "HIL_STATE_QUATERNION", "GLOBAL_POSITION_INT"], blocking=True,
                           timeout=0.5)
        if msg is None:
            continue
        now = time.monotonic()
        if msg.get_type() == "HEARTBEAT":
            if msg.autopilot == 8 or msg.type == 6:
                continue
            if sysid is None:
                print(f"{now:.1f}: vehicle {msg.get_srcSystem()} heard", flush=True)
            sysid = msg.get_srcSystem()
            armed = bool(msg.base_mode & 128)
            if armed != was and disarmed_at is None:
                print(f"{now:.1f}: {'armed' if armed else 'disarmed'}", flush=True)
            if stop and armed and mavutil.mode_string_v10(msg) in ("GUIDED", "OFFBOARD"):
                threading.Thread(target=_stop_for, args=stop, daemon=True).start()
                stop = None
            seen_disarmed = seen_disarmed or not armed
            if armed and armed_at is None and seen_disarmed:
                armed_at = now
            was = was or armed
            if was and not armed and disarmed_at is None:
                disarmed_at = now
        elif msg.get_type() == "HIL_STATE_QUATERNION":
            truth.append([now, math.hypot(msg.vx, msg.vy) / 100.0, msg.alt / 1000.0])
        else:
            est.append([now, math.hypot(msg.vx, msg.vy) / 100.0, msg.relative_alt / 1000.0])
    why = "disarmed" if disarmed_at else "told to stop" if ended else "timed out"
    print(f"{time.monotonic():.1f}: done ({why}), {len(truth)} truth and "
          f"{len(est)} estimate samples", flush=True)
    Path(out + ".part").write_text(json.dumps({"truth": truth, "estimate": est, "armed_s": armed_at,
                                               "disarmed_s": disarmed_at}))
    os.replace(out + ".part", out)  # whole or absent: the scenario waits for the file, then kills what is left
    return 0


def stop_when_flying(conn: str, pid: int, delay_s: float, stop_s: float, timeout_s: float = 300) -> int:
    """On a second MAVLink link (``conn``: the firmware's other output), wait for a HEARTBEAT showing the vehicle
    armed in a guided mode (GUIDED / OFFBOARD), ``delay_s`` wall seconds more, then SIGSTOP firmware ``pid`` for
    ``stop_s`` seconds and SIGCONT it (a link loss the runtime must ride out)."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(conn, source_system=254, source_component=191)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
        if hb is None or hb.autopilot == 8:
            continue
        if hb.base_mode & 128 and mavutil.mode_string_v10(hb) in ("GUIDED", "OFFBOARD"):
            _stop_for(pid, delay_s, stop_s)
            return 0
    print("never saw the vehicle flying", flush=True)
    return 1


def _stop_for(pid: int, delay_s: float, stop_s: float) -> None:
    """``delay_s`` seconds, then SIGSTOP ``pid`` for ``stop_s`` seconds and SIGCONT it."""
    import signal

    time.sleep(delay_s)
    os.kill(pid, signal.SIGSTOP)
    time.sleep(stop_s)
    os.kill(pid, signal.SIGCONT)
    print(f"stopped {pid} for {stop_s} s", flush=True)


def freeze_our_drone_when_flying(conn: str, root_pid: int, out: str, delay_s: float, stop_s: float,
                                 timeout_s: float = 400) -> int:
    """PX4's own failsafe while AeroDaaS runs: on a second MAVLink link (``conn``), wait for a HEARTBEAT showing the
    vehicle armed in OFFBOARD, ``delay_s`` wall seconds more, then SIGSTOP our drone actor (the ``ray::DroneActor``
    process among the descendants of ``root_pid``, the scenario's shell) for ``stop_s`` seconds: our setpoint stream
    stops, PX4 leaves OFFBOARD after ``COM_OF_LOSS_T`` (its offboard-loss failsafe, ``COM_OBL_RC_ACT``), and when the
    actor runs again it finds the autopilot in its failsafe mode. Then follow the firmware's HEARTBEATs until it is
    disarmed (or ``timeout_s``) and write ``{"frozen": bool, "modes": [[time_boot_ms s, mode, armed], ...] (on
    each change), "landed": bool}`` to ``out``."""
    import signal

    import psutil
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(conn, source_system=254, source_component=190)
    end = time.monotonic() + timeout_s
    modes: list = []
    frozen = was_armed = landed = False
    t_boot = 0.0
    while time.monotonic() < end:
        msg = m.recv_match(type=["HEARTBEAT", "SYSTEM_TIME", "ATTITUDE"], blocking=True, timeout=1.0)
        if msg is None:
            continue
        if msg.get_type() != "HEARTBEAT":
            t_boot = getattr(msg, "time_boot_ms", 0) / 1000.0
            continue
        if msg.autopilot == 8:
            continue
        mode, armed = mavutil.mode_string_v10(msg), bool(msg.base_mode & 128)
        if not modes or modes[-1][1:] != [mode, armed]:
            modes.append([t_boot, mode, armed])
        was_armed = was_armed or armed
        if was_armed and not armed:
            landed = True
            break
        if not frozen and armed and mode == "OFFBOARD":
            time.sleep(delay_s)
            drones = [p for p in psutil.Process(root_pid).children(recursive=True)
                      if "DroneActor" in " ".join(p.cmdline()[:1])]
            for p in drones:
                p.send_signal(signal.SIGSTOP)
            time.sleep(stop_s)
            for p in drones:
                p.send_signal(signal.SIGCONT)
            frozen = bool(drones)
            print(f"froze {[p.pid for p in drones]} for {stop_s} s", flush=True)
    Path(out).write_text(json.dumps({"frozen": frozen, "modes": modes, "landed": landed}))
    return 0 if frozen else 1


def real_time_when_ready(conn: str, speedup: float = 1.0, timeout_s: float = 120.0) -> int:
    """Set an ArduCopter SITL's ``SIM_SPEEDUP`` (the simulator's, not the vehicle's, parameter) to ``speedup`` once
    its pre-arm checks pass (``SYS_STATUS.onboard_control_sensors_health`` has ``MAV_SYS_STATUS_PREARM_CHECK``), so
    a firmware booted at a high speed-up waits for its GPS and EKF at that speed and then flies in real time: MAVProxy's
    ``sitl_autospeedup`` module does the same the other way round. 0 once the firmware reports the new value; 1 after
    ``timeout_s`` wall seconds."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(conn, source_system=250, source_component=191)
    end = time.monotonic() + timeout_s
    ready = asked = 0.0
    target = None  # (system, component) of the autopilot, from its HEARTBEAT
    while time.monotonic() < end:
        msg = m.recv_match(type=["HEARTBEAT", "SYS_STATUS", "PARAM_VALUE"], blocking=True, timeout=0.5)
        now = time.monotonic()
        if target and not ready and now - asked > 0.5:  # Copter streams SYS_STATUS only when asked
            m.mav.command_long_send(*target, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                    mavutil.mavlink.MAVLINK_MSG_ID_SYS_STATUS, 0, 0, 0, 0, 0, 0)
            asked = now
        if msg is None:
            continue
        t = msg.get_type()
        if t == "HEARTBEAT" and msg.type != mavutil.mavlink.MAV_TYPE_GCS and target is None:
            target = (msg.get_srcSystem(), msg.get_srcComponent())
        if t == "SYS_STATUS" and msg.onboard_control_sensors_health & mavutil.mavlink.MAV_SYS_STATUS_PREARM_CHECK:
            ready = ready or now
        if ready and target and now - asked > 0.5:  # a streamed SYS_STATUS can come before the first HEARTBEAT
            m.mav.param_set_send(*target, b"SIM_SPEEDUP", float(speedup),
                                 mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            asked = now
        if t == "PARAM_VALUE" and msg.param_id == "SIM_SPEEDUP" and ready and abs(msg.param_value - speedup) < 1e-6:
            print(f"SIM_SPEEDUP {speedup:g}: pre-arm checks passed, the firmware now runs at {speedup:g}x", flush=True)
            return 0
    print(f"the firmware did not pass its pre-arm checks and take SIM_SPEEDUP {speedup:g} in {timeout_s:g} s",
          flush=True)
    return 1


if __name__ == "__main__":
    if sys.argv[1] == "observe":
        sys.exit(observe(sys.argv[2], sys.argv[3], float(sys.argv[4]), *sys.argv[5:6]))
    if sys.argv[1] == "observe-raw":
        extra = dict(a.split("=", 1) for a in sys.argv[5:])  # SYSID=FILE: several vehicles on one port
        sys.exit(observe_raw(sys.argv[2], sys.argv[3], float(sys.argv[4]),
                             {int(k): v for k, v in extra.items()} or None))
    if sys.argv[1] == "observe-truth":
        stop = (int(sys.argv[5]), float(sys.argv[6]), float(sys.argv[7])) if len(sys.argv) > 5 else None
        sys.exit(observe_truth(sys.argv[2], sys.argv[3], float(sys.argv[4]), stop))
    if sys.argv[1] == "freeze-our-drone":
        sys.exit(freeze_our_drone_when_flying(sys.argv[2], int(sys.argv[3]), sys.argv[4], float(sys.argv[5]),
                                              float(sys.argv[6])))
    if sys.argv[1] == "stop-when-flying":
        sys.exit(stop_when_flying(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])))
    if sys.argv[1] == "real-time-when-ready":
        sys.exit(real_time_when_ready(sys.argv[2], *map(float, sys.argv[3:5])))
    raise SystemExit(f"unknown command {sys.argv[1]!r}")
