"""`aerodaas sim --mavlink ...` as a process: a third-party MAVLink client (pymavlink) reaches the emulated vehicle,
and SIGTERM stops it cleanly and promptly."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from aerodaas.emulators import free_tcp_port

pytestmark = pytest.mark.skipif(sys.platform.startswith("win"), reason="POSIX signals")

HOME = (47.3977, 8.5456, 488.0)


def test_sim_serves_an_ardupilot_vehicle_and_stops_on_sigterm():
    from pymavlink import mavutil

    port = free_tcp_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "aerodaas.cli", "sim", "--mavlink", f"tcp:127.0.0.1:{port}", "--autopilot",
         "ardupilot", "--speedup", "4", "--home", ",".join(f"{v:g}" for v in HOME)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    out: list[str] = []
    err_lines: list[str] = []  # both pipes drained in threads: a full pipe must not block the server
    readers = [threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True),
               threading.Thread(target=lambda: err_lines.extend(proc.stderr), daemon=True)]
    for r in readers:
        r.start()
    conn = None
    try:
        deadline = time.monotonic() + 30
        while not any("aerodaas sim:" in x for x in out):  # listening
            assert proc.poll() is None and time.monotonic() < deadline, (proc.poll(), out, err_lines)
            time.sleep(0.05)
        assert f"tcp:127.0.0.1:{port}" in out[0] and "SIGTERM" in out[0]
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250, source_component=190)
        hb = conn.wait_heartbeat(timeout=10)
        assert hb is not None and hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
        # ArduPilot streams nothing but HEARTBEAT until asked: 5 Hz GLOBAL_POSITION_INT (interval in µs)
        conn.mav.command_long_send(hb.get_srcSystem(), hb.get_srcComponent(),
                                   mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                   mavutil.mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 200_000, 0, 0, 0, 0, 0)
        pos = None
        end = time.monotonic() + 15
        while time.monotonic() < end:  # lat/lon are 0 until the emulated GPS has its 3-D fix
            m = conn.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=1)
            if m is not None and m.lat != 0:
                pos = m
                break
        assert pos is not None, "no GLOBAL_POSITION_INT with a position"
        assert abs(pos.lat / 1e7 - HOME[0]) < 1e-5 and abs(pos.lon / 1e7 - HOME[1]) < 1e-5
        assert abs(pos.alt / 1000 - HOME[2]) < 0.5 and abs(pos.relative_alt) < 500  # mm
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=60)  # stops on its own (bounded by the wait), however loaded the machine
        for r in readers:
            r.join(5)
        err = "".join(err_lines)
        assert rc == 0, (rc, err)  # a stopped server ends normally, as on Ctrl-C
        assert "Traceback" not in err and "aerodaas sim: stopped" in err
        # the listening socket is closed: nobody answers on the port any more
        with socket.socket() as s:
            s.settimeout(1.0)
            assert s.connect_ex(("127.0.0.1", port)) != 0
    finally:
        if conn is not None:
            conn.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
