"""Helpers of the take-off-stall SITL test (``tests/firmware/test_sitl_takeoff_stall.py``), run as ``python -m
tests.firmware.sitl_no_lift COMMAND ...`` from the steps of :func:`tests.firmware.sitl.run_in_namespace`, in raw pymavlink on the
firmware's second link (its own system id 253), independent of AeroDaaS:

* ``set-params CONN NAME=VALUE ...``: PARAM_SET each parameter until the firmware's PARAM_VALUE echoes it (exit 0),
  e.g. ArduPilot SITL's ``SIM_ENGINE_FAIL=15 SIM_ENGINE_MUL=0``: the PWM of motors 1-4 scaled by 0, so the
  vehicle's motors lift nothing (libraries/SITL/SITL.cpp ``ENGINE_MUL`` / ``ENGINE_FAIL``).
* ``drive ENV OUT TIMEOUT``: the drone's flight logic alone (no Ray) flying the environment's MAVLink robot
  (:func:`drive`).
* ``observe CONN OUT TIMEOUT``: follow the firmware's own HEARTBEAT (armed flag, ArduCopter mode number),
  GLOBAL_POSITION_INT (``relative_alt``, asked at 10 Hz) and STATUSTEXT until the vehicle has been armed and is
  disarmed again (+1 s), or TIMEOUT wall seconds; writes ``{"armed", "disarmed", "modes": [[t, mode], ...],
  "alts": [[t, metres], ...], "texts": [...]}`` to OUT (t: the firmware's ``time_boot_ms`` in seconds)."""
from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

from tests.recording.recorded_calls import RecordedCalls


def _link(conn: str):
    from pymavlink import mavutil

    return mavutil.mavlink_connection(conn, source_system=253, source_component=190)


def set_params(conn: str, pairs: dict[str, float], timeout_s: float = 120.0) -> int:
    """PARAM_SET every ``pairs`` entry (REAL32) until echoed; 0 when all were, 1 after ``timeout_s`` wall seconds."""
    m = _link(conn)
    left, end, next_send = dict(pairs), time.monotonic() + timeout_s, 0.0
    target = None
    while left and time.monotonic() < end:
        if target is not None and time.monotonic() >= next_send:
            for name, value in left.items():
                m.mav.param_set_send(target, 1, name.encode(), float(value), 9)  # MAV_PARAM_TYPE_REAL32
            next_send = time.monotonic() + 1.0
        msg = m.recv_match(type=["HEARTBEAT", "PARAM_VALUE"], blocking=True, timeout=0.5)
        if msg is None:
            continue
        if msg.get_type() == "HEARTBEAT":
            if msg.autopilot != 8 and msg.type != 6:
                target = target or msg.get_srcSystem()
            continue
        name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else msg.param_id
        if name in left and abs(msg.param_value - left[name]) < 1e-6:
            print(f"{name} = {msg.param_value:g}", flush=True)
            del left[name]
    return 0 if not left else 1


def observe(conn: str, out: str, timeout_s: float) -> int:
    """See the module docstring. Also written when stopped by SIGTERM."""
    m = _link(conn)
    st = {"armed": False, "disarmed": False, "modes": [], "alts": [], "texts": []}
    t_boot, armed_now, disarmed_at, next_hb = 0.0, False, None, 0.0
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    end = time.monotonic() + timeout_s
    try:
        while time.monotonic() < end and not (disarmed_at is not None and time.monotonic() - disarmed_at > 1.0):
            if time.monotonic() >= next_hb:
                m.mav.heartbeat_send(6, 8, 0, 0, 4)
                m.mav.command_long_send(1, 1, 511, 0, 33, 100000, 0, 0, 0, 0, 0)  # GLOBAL_POSITION_INT at 10 Hz
                next_hb = time.monotonic() + 1.0
            msg = m.recv_match(type=["HEARTBEAT", "GLOBAL_POSITION_INT", "STATUSTEXT"], blocking=True, timeout=0.5)
            if msg is None:
                continue
            kind = msg.get_type()
            if kind == "GLOBAL_POSITION_INT":
                t_boot = msg.time_boot_ms / 1000.0
                st["alts"].append([t_boot, msg.relative_alt / 1000.0])
            elif kind == "STATUSTEXT":
                st["texts"].append([t_boot, msg.text])
            elif msg.autopilot != 8 and msg.type != 6:
                armed_now = bool(msg.base_mode & 128)
                st["armed"] = st["armed"] or armed_now
                if not st["modes"] or st["modes"][-1][1] != msg.custom_mode:
                    st["modes"].append([t_boot, msg.custom_mode])
                if st["armed"] and not armed_now and disarmed_at is None:
                    disarmed_at, st["disarmed"] = time.monotonic(), True
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        tmp = Path(f"{out}.tmp")
        tmp.write_text(json.dumps(st))
        os.replace(tmp, out)
    return 0


def drive(env_path: str, out: str, timeout_s: float) -> int:
    """Fly the first robot of ``env_path`` (a MAVLink robot) with the drone's own flight logic
    (:class:`~aerodaas.actors.drone.component.DroneComponent`, no Ray: its control step every 0.05 wall seconds) to one
    waypoint 5 m north at 1.5 m, until its mission ends or ``timeout_s`` wall seconds, then until the vehicle says
    it is disarmed (at most 20 s); writes ``{"outcome", "done", "states", "armed_end", "events"}`` to ``out``."""
    from aerodaas.actors.drone.component import DroneComponent
    from aerodaas.config import load_environment_config
    from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
    from aerodaas.schedulers.base import TrajectoryScheduler

    cfg = load_environment_config(env_path).robots[0]
    sched = TrajectoryScheduler()
    sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=0, y=5, z=1.5)],
                                        SchedulingType.ORDERED))
    rec = RecordedCalls()
    d = DroneComponent(f"{cfg.id}/drone", cfg.model_dump(mode="json"), None, sched, rec, 0, 1, [], [])
    d.connect(60)
    try:
        d.start()
        end = time.monotonic() + timeout_s
        while not d.done and time.monotonic() < end:
            d.step(0.0)
            d.control_tick()
            time.sleep(0.05)
        end = time.monotonic() + 20.0
        while d.backend.state().armed and time.monotonic() < end:
            d.step(0.0)
            time.sleep(0.1)
        Path(out).write_text(json.dumps({"outcome": d.outcome, "done": d.done, "states": rec.states,
                                         "armed_end": d.backend.state().armed, "events": rec.events}, default=str))
    finally:
        d.close()
    return 0


if __name__ == "__main__":
    if sys.argv[1] == "set-params":
        sys.exit(set_params(sys.argv[2], {k: float(v) for k, v in (a.split("=", 1) for a in sys.argv[3:])}))
    if sys.argv[1] == "observe":
        sys.exit(observe(sys.argv[2], sys.argv[3], float(sys.argv[4])))
    if sys.argv[1] == "drive":
        sys.exit(drive(sys.argv[2], sys.argv[3], float(sys.argv[4])))
    raise SystemExit(f"unknown command {sys.argv[1]!r}")
