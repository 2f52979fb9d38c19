"""The helpers of tests/firmware/test_sitl_signing.py run inside the firmware's network namespace (``python -m
tests.firmware.sitl_signing_attack ...``): a control probe, an observer of the firmware's own telemetry, and the attacker.

- ``probe ATTACK_AT OUT.json [no]``: without a key, over ``ATTACK_AT`` (another serial port of the firmware), a
  MAV_CMD_REQUEST_MESSAGE and a PARAM_REQUEST_READ of ``WPNAV_SPEED`` (unless ``no``); writes the COMMAND_ACKs and
  PARAM_VALUEs answered and whether each HEARTBEAT was signed (the control: before provisioning, unsigned messages
  on that port are taken).
- ``watch WATCH_AT ATTACK_AT SPOOF_AT OUT.json STOP_FILE``: watches the firmware's own telemetry on ``WATCH_AT``
  (ArduCopter's serial0, channel 0, which the firmware treats as its secure USB port: GCS_Signing.cpp
  ``accept_unsigned_callback``, so the observer needs no key) until ``STOP_FILE`` exists, recording a timeline of
  (firmware seconds, armed, mode, relative altitude, whether the HEARTBEAT was signed) and every ``WPNAV_SPEED``
  PARAM_VALUE. It starts the attacker (below) at once, and releases it when the vehicle is armed and more than 1 m
  up; after the attack it reads ``WPNAV_SPEED`` back. OUT.json: the timeline, the attack's start and end in
  firmware seconds, the attacker's output, the parameter values seen.
- ``attack ATTACK_AT SPOOF_AT``: another process without the key, speaking as system 255 component 190 (the ids
  our backend uses) over ``ATTACK_AT``: 5 rounds 0.1 s apart of a forced disarm, MAV_CMD_DO_FLIGHTTERMINATION,
  DO_SET_MODE LAND, PARAM_SET WPNAV_SPEED 1234 and a harmless MAV_CMD_REQUEST_MESSAGE (the probe's), and onto our
  backend's own port ``SPOOF_AT``, in the vehicle's name (system 1, component 1), a GLOBAL_POSITION_INT 100 m north
  of home, a BATTERY_STATUS at 5 % (the battery our backend reads while the firmware sends BATTERY_STATUS), a
  SYS_STATUS at 5 % and 1 V (the voltage it reads) and a HEARTBEAT claiming disarmed in LAND with system_status
  CRITICAL; then it collects for 1.5 s every COMMAND_ACK and PARAM_VALUE answered and
  prints them as JSON."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

#: the parameter the attacker sets (ArduCopter's horizontal waypoint speed, cm/s) and the value it asks for
PARAM, EVIL = "WPNAV_SPEED", 1234.0
#: MAV_CMD_REQUEST_MESSAGE(AUTOPILOT_VERSION): a harmless command every firmware acknowledges
PROBE_CMD = (512, 148)


def _connect(address: str, system: int = 255, component: int = 190):
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    # retries: a TCP port of a firmware still starting on a loaded machine (pymavlink tries every second)
    return mavutil.mavlink_connection(address, source_system=system, source_component=component,
                                      dialect="ardupilotmega", retries=120)


def _answers(conn, until: float) -> dict:
    """COMMAND_ACKs, PARAM_VALUEs of :data:`PARAM` and whether each HEARTBEAT was signed, from system 1 until wall
    time ``until``."""
    from aerodaas.backends.mavlink.signing import sign_fields

    acks, params, beats = [], [], []
    while time.monotonic() < until:
        m = conn.recv_match(type=["COMMAND_ACK", "PARAM_VALUE", "HEARTBEAT"], blocking=True, timeout=0.2)
        if m is None or m.get_srcSystem() != 1:
            continue
        if m.get_type() == "HEARTBEAT":
            beats.append(sign_fields(m.get_msgbuf())[0])
        elif m.get_type() == "COMMAND_ACK":
            acks.append([m.command, m.result])
        elif m.param_id == PARAM:
            params.append(m.param_value)
    return {"acks": acks, "params": params, "signed_heartbeats": beats}


def probe(attack_at: str, out: str, param: str = "yes") -> None:
    """``param`` "no": no parameter read (PX4 has no ``WPNAV_SPEED``)."""
    conn = _connect(attack_at)
    got: dict = {"acks": [], "params": [], "signed_heartbeats": []}
    for _ in range(10):  # until answered (the firmware may still be starting)
        conn.mav.command_long_send(1, 1, PROBE_CMD[0], 0, PROBE_CMD[1], 0, 0, 0, 0, 0, 0)
        if param == "yes":
            conn.mav.param_request_read_send(1, 1, PARAM.encode(), -1)
        a = _answers(conn, time.monotonic() + 1.0)
        got["acks"] += a["acks"]
        got["params"] += a["params"]
        got["signed_heartbeats"] += a["signed_heartbeats"]
        if got["acks"] and (got["params"] or param != "yes"):
            break
    Path(out).write_text(json.dumps(got))


def attack(attack_at: str, spoof_at: str) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as M

    from tests.firmware.sitl import FARM_HOME

    conn = _connect(attack_at)
    spoof = _connect(spoof_at, system=1, component=1)  # unsigned, in the vehicle's name
    print("ready", flush=True)
    t_ms = int(sys.stdin.readline().split()[1])  # "go <firmware ms>"
    lat = int((FARM_HOME["lat"] + 100.0 / 111_320.0) * 1e7)
    for i in range(5):
        m = conn.mav
        m.command_long_send(1, 1, 400, 0, 0, 21196, 0, 0, 0, 0, 0)  # MAV_CMD_COMPONENT_ARM_DISARM: disarm, forced
        m.command_long_send(1, 1, 185, 0, 1, 0, 0, 0, 0, 0, 0)  # MAV_CMD_DO_FLIGHTTERMINATION
        m.command_long_send(1, 1, 176, 0, 1, 9, 0, 0, 0, 0, 0)  # MAV_CMD_DO_SET_MODE: LAND (ArduCopter mode 9)
        m.param_set_send(1, 1, PARAM.encode(), EVIL, M.MAV_PARAM_TYPE_REAL32)
        m.command_long_send(1, 1, PROBE_CMD[0], 0, PROBE_CMD[1], 0, 0, 0, 0, 0, 0)
        for k in range(4):
            spoof.mav.global_position_int_send(t_ms + 50 * (4 * i + k), lat, int(FARM_HOME["lon"] * 1e7),
                                               int((FARM_HOME["alt"] + 30.0) * 1000), 30_000, 0, 0, 0, 0)
            spoof.mav.sys_status_send(0, 0, 0, 0, 1000, -1, 5, 0, 0, 0, 0, 0, 0)
            spoof.mav.battery_status_send(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767,
                                          [1000] + [65535] * 9, -1, -1, -1, 5)
            spoof.mav.heartbeat_send(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                     M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9, M.MAV_STATE_CRITICAL)
        time.sleep(0.1)
    print(json.dumps(_answers(conn, time.monotonic() + 1.5)), flush=True)


def watch(watch_at: str, attack_at: str, spoof_at: str, out: str, stop_file: str) -> None:
    from pymavlink import mavutil

    from aerodaas.backends.mavlink.signing import sign_fields

    attacker = subprocess.Popen([sys.executable, "-m", "tests.firmware.sitl_signing_attack", "attack", attack_at, spoof_at],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ready = attacker.stdout.readline().strip() == "ready"
    conn = _connect(watch_at, component=191)
    res: dict = {"ready": ready, "timeline": [], "params": [], "attack": None}
    t, alt, next_req, read_back = 0.0, 0.0, 0.0, None
    while not os.path.exists(stop_file):
        now = time.monotonic()
        if now >= next_req:
            conn.mav.request_data_stream_send(1, 1, 0, 10, 1)  # every stream, 10 Hz (channel 0: unsigned is taken)
            if read_back is not None and not read_back:
                conn.mav.param_request_read_send(1, 1, PARAM.encode(), -1)
            next_req = now + 1.0
        m = conn.recv_match(type=["HEARTBEAT", "GLOBAL_POSITION_INT", "PARAM_VALUE"], blocking=True, timeout=0.2)
        if m is not None and m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            if m.get_type() == "GLOBAL_POSITION_INT":
                t, alt = m.time_boot_ms / 1000.0, m.relative_alt / 1000.0
            elif m.get_type() == "PARAM_VALUE" and m.param_id == PARAM:
                res["params"].append([t, m.param_value])
                if read_back is not None:
                    read_back.append(m.param_value)
            elif m.get_type() == "HEARTBEAT":
                armed = bool(m.base_mode & 128)
                res["timeline"].append([t, armed, mavutil.mode_string_v10(m), alt, sign_fields(m.get_msgbuf())[0]])
                if ready and res["attack"] is None and armed and alt > 1.0:
                    res["attack"] = {"start": t}
                    attacker.stdin.write(f"go {int(t * 1000)}\n")
                    attacker.stdin.flush()
        if res["attack"] is not None and "end" not in res["attack"] and attacker.poll() is not None:
            res["attack"].update(end=t, rc=attacker.returncode, stderr=attacker.stderr.read()[-1500:],
                                 answers=json.loads(attacker.stdout.read() or "null"))
            read_back = []
    if attacker.poll() is None:
        attacker.kill()
    res["read_back"] = read_back
    Path(out).write_text(json.dumps(res))


if __name__ == "__main__":
    {"probe": probe, "attack": attack, "watch": watch}[sys.argv[1]](*sys.argv[2:])
