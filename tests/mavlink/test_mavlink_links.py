"""The MAVLink backend's links and wire: corrupt packets, refused and temporarily rejected commands, older
firmware, long STATUSTEXT, UDP and serial links, the real PX4 telemetry log through the receive path, and MAVProxy
as a third-party ground station (emulated vehicle, in-process, loopback)."""
from __future__ import annotations

import importlib.util
import logging
import math
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from aerodaas.backends import BackendError, CommandRefused
from aerodaas.backends.mavlink import CommandNotConfirmed, MavlinkBackend
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import Waypoint
from tests.conftest import DATA_DIR, skip_or_fail
from tests.mavlink.emulated import (
    AUTOPILOTS,
    CONFIG_HOME,
    PREARM_PREFIX,
    VEHICLE_HOME,
    dist,
    position_ready,
    run_until,
)


def _frame_v2(msgid: int, payload: bytes, seq: int = 0, sysid: int = 1, compid: int = 1,
              crc_extra: int = 0) -> bytes:
    """A MAVLink 2 frame (no signature) with a CRC computed over ``crc_extra``."""
    from pymavlink.generator.mavcrc import x25crc

    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16)
    crc = x25crc(header[1:] + payload)
    crc.accumulate(bytes([crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def test_corrupt_packets_are_skipped_and_the_backend_keeps_working(fly):
    """Garbage bytes, a frame with a bad CRC, a truncated known message and an unknown message id, mixed into
    the vehicle's stream: the receive path skips them (no event from their contents, no receive error), telemetry
    goes on and later commands work."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    emu, b = fly("ardupilot", mavlink={"heartbeat_timeout_s": 1.0})
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    b.drain_events()
    enc = M.MAVLink(None, srcSystem=1, srcComponent=1)  # the vehicle's own ids
    rtl_armed = enc.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                     M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED, 6,
                                     M.MAV_STATE_ACTIVE, 3).pack(enc)
    bad_crc = rtl_armed[:-2] + bytes([rtl_armed[-2] ^ 0x5A, rtl_armed[-1]])
    far = enc.global_position_int_encode(1, 10 * 10**7, 20 * 10**7, 0, 900_000, 0, 0, 0, 0).pack(enc)
    truncated = far[:len(far) // 2]
    unknown = _frame_v2(0xBEEF1, b"\x01\x02\x03\x04\x05", seq=7)
    rng = np.random.default_rng(5)
    garbage = bytes(rng.integers(0, 256, 300, dtype=np.uint8)) + b"\xfd\xff\x00" + b"\xfe\x09"
    n0, t0 = b.link.messages_received, b.t
    for _ in range(5):
        for data in (garbage, bad_crc, truncated, unknown):
            emu.inject(data)
            time.sleep(0.02)
    assert run_until(b, lambda: b.link.messages_received > n0 + 100 and b.t > t0 + 3.0, 10)
    assert emu.snapshot()["links"] == 1 and b.state().link_ok and b.link.io_alive
    b.step(0.05)  # raises if the I/O thread failed
    events = b.drain_events()
    assert not [e for e in events if e["event"] in ("receive_error", "armed", "mode", "link_lost")], events
    assert not b.state().armed and b.state().mode == "STABILIZE" and dist(b.state().position, (0, 0, 0)) < 0.3  # nothing taken from them
    assert b.telemetry.odometry().t > t0 + 3.0
    b.actions.arm()
    b.actions.takeoff(2.0)
    assert run_until(b, lambda: b.state().position[2] > 1.7, 10) and emu.snapshot()["in_air"]


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_accepted_but_never_shown_mode_or_arming_raises(fly, autopilot):
    """A vehicle that acknowledges MAV_CMD_DO_SET_MODE / MAV_CMD_COMPONENT_ARM_DISARM with MAV_RESULT_ACCEPTED but
    whose HEARTBEAT never shows the change: set_mode() and arm() raise CommandNotConfirmed after the bounded wait,
    naming what was asked and what the HEARTBEAT shows."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    emu, b = fly(autopilot, mavlink={"command_timeout_s": 0.5, "heartbeat_timeout_s": 1.0},
                 ack_only_commands={M.MAV_CMD_DO_SET_MODE})
    assert run_until(b, lambda: position_ready(b), 10)
    first, target = ("STABILIZE", "GUIDED") if autopilot == "ardupilot" else ("MANUAL", "LOITER")
    t0 = time.monotonic()
    with pytest.raises(CommandNotConfirmed) as e:
        b.commands.set_mode(target)
    assert 0.9 < time.monotonic() - t0 < 30.0  # at least max(command_timeout_s, heartbeat_timeout_s), not forever
    assert e.value.expected == f"mode {target}" and e.value.observed == f"mode {first}, disarmed"
    assert f"mode {target}" in str(e.value) and f"shows mode {first}" in str(e.value)
    assert "MAV_RESULT_ACCEPTED" in str(e.value) and emu.snapshot()["mode"] != target
    emu.commands.ack_only_commands = {M.MAV_CMD_COMPONENT_ARM_DISARM}
    with pytest.raises(CommandNotConfirmed) as e:
        b.actions.arm()
    assert e.value.command == "arm" and e.value.expected == "armed" and e.value.observed.endswith("disarmed")
    assert not emu.snapshot()["armed"]
    emu.commands.ack_only_commands = set()
    b.actions.arm()
    assert b.state().armed


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_temporarily_rejected_is_retried_and_in_progress_is_bounded(fly, autopilot):
    """MAV_RESULT_TEMPORARILY_REJECTED ("retrying later should work") is re-sent within the bounded tries;
    an endless MAV_RESULT_IN_PROGRESS ends in BackendError at (retries + 1) x timeout, without re-sending."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    emu, b = fly(autopilot, mavlink={"command_timeout_s": 0.3, "command_retries": 2})
    assert run_until(b, lambda: position_ready(b), 10)
    b.commands.set_mode("GUIDED" if autopilot == "ardupilot" else "LOITER")
    arm = M.MAV_CMD_COMPONENT_ARM_DISARM
    emu.reject_next(arm, 2)
    b.drain_events()
    b.actions.arm()  # rejected twice, accepted on the third try
    assert b.state().armed and emu.snapshot()["commands_seen"].count(arm) == 3
    resent = [(e["command"], e["attempt"], e["after"]) for e in b.drain_events()
              if e["event"] == "command_resent" and e["command"] == "arm"]
    assert resent == [("arm", 1, "MAV_RESULT_TEMPORARILY_REJECTED"), ("arm", 2, "MAV_RESULT_TEMPORARILY_REJECTED")]
    speed = M.MAV_CMD_DO_CHANGE_SPEED
    emu.reject_next(speed, 5)
    t0 = time.monotonic()
    with pytest.raises(CommandRefused) as e:
        b.commands.command_long("change speed", speed, 1, 1.5, -1)
    assert e.value.result == "MAV_RESULT_TEMPORARILY_REJECTED"
    assert e.value.status_text == "Command temporarily rejected: busy"
    assert emu.snapshot()["commands_seen"].count(speed) == 3 and time.monotonic() - t0 < 30.0  # bounded tries
    emu.commands.in_progress_commands = {speed}
    seen = emu.snapshot()["commands_seen"].count(speed)
    box: dict = {}

    def call() -> None:
        t = time.monotonic()
        try:
            b.commands.command_long("change speed", speed, 1, 1.5, -1)
        except BaseException as exc:  # noqa: BLE001 - examined below
            box["error"] = exc
        box["s"] = time.monotonic() - t

    th = threading.Thread(target=call, daemon=True)
    th.start()
    th.join(5.0)
    assert not th.is_alive(), "an endless MAV_RESULT_IN_PROGRESS kept command_long() waiting"
    assert type(box.get("error")) is BackendError and "MAV_RESULT_IN_PROGRESS" in str(box["error"]), box
    assert box["s"] > 0.85  # not before the overall deadline, (2 + 1) x 0.3 s (the join above bounds it)
    assert emu.snapshot()["commands_seen"].count(speed) == seen + 1  # progress came: nothing re-sent


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_mission_round_trip_with_older_firmware_using_mission_item(fly, autopilot):
    """A vehicle that speaks only the float forms (MISSION_REQUEST, MISSION_ITEM with latitude/longitude as float32
    degrees): upload answers its MISSION_REQUESTs and download accepts its MISSION_ITEM replies, on the same
    1e-7 degree grid, equal to what was sent within float32 precision."""
    emu, b = fly(autopilot, mission_int=False)
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    wps = [Waypoint(id=f"w{i}", x=x, y=y, z=5.0, hover_duration=1.0) for i, (x, y) in enumerate([(12, 3), (-7, 25)])]
    sent = b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    got = b.mission.download().items
    assert len(got) == len(sent) == 4
    for s_, g in zip(sent, got):
        assert (g.seq, g.command, g.frame, g.autocontinue) == (s_.seq, s_.command, s_.frame, s_.autocontinue)
        assert g.params[:4] == s_.params[:4] and g.params[6] == pytest.approx(s_.params[6], abs=1e-4)
        for k in (4, 5):  # float32 degrees: ~2e-6 at 47 degrees; rounded to the 1e-7 grid like MISSION_ITEM_INT
            assert abs(g.params[k] - s_.params[k]) < 3e-6
            assert abs(g.params[k] * 1e7 - round(g.params[k] * 1e7)) < 1e-3
    assert min(abs(g.params[4] - VEHICLE_HOME.lat) for g in got if g.command == 16) < 1e-3


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_long_statustext_chunks_are_joined(fly, autopilot, caplog):
    """MAVLink 2 sends a STATUSTEXT longer than 50 characters in chunks (same non-zero id, chunk_seq 0, 1, ...;
    the last one shorter than 50): CommandRefused and the log line carry the whole text; a chunked text whose last
    chunk is lost is emitted after a short timeout; id 0 texts are emitted at once."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    emu, b = fly(autopilot, mavlink={"arm_timeout_s": 0.2, "command_retries": 1})
    reason = ("Compass not calibrated: run the onboard calibration and keep the vehicle away from steel, then "
              "reboot")  # 106 characters: three chunks with the prefix
    emu.set_prearm_failure(reason)
    with caplog.at_level(logging.INFO, logger="aerodaas.mavlink"), pytest.raises(CommandRefused) as e:
        b.actions.arm()
    whole = PREARM_PREFIX[autopilot] + reason
    assert e.value.status_text == whole and whole in str(e.value)
    assert ("quad: " + whole) in [r.getMessage() for r in caplog.records if r.name == "aerodaas.mavlink"]
    emu.set_prearm_failure(None)
    b.drain_events()
    exact = "".join(chr(65 + i % 26) for i in range(100))  # fills two chunks: an empty third one ends it
    emu.send_status_text(exact, M.MAV_SEVERITY_WARNING)
    got: list = []
    assert run_until(b, lambda: bool(got), 3,
                     every=lambda: got.extend(x for x in b.drain_events() if x["event"] == "status_text"))
    assert [(x["text"], x["severity"]) for x in got] == [(exact, "MAV_SEVERITY_WARNING")]
    emu.inject(M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"x" * 50, 4242, 0))  # its last chunk never comes
    emu.inject(M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"short one", 0, 0))
    texts: list = []
    assert run_until(b, lambda: len(texts) >= 2, 3,
                     every=lambda: texts.extend(x["text"] for x in b.drain_events() if x["event"] == "status_text"))
    assert texts == ["short one", "x" * 50]


def _connect_and_take_off(b: MavlinkBackend, emu: MavlinkVehicleEmulator, autopilot: str | None = None) -> None:
    """Over whatever link ``b`` uses: connect, identify the autopilot, arm, take off to 2 m — as the vehicle sees it."""
    b.connect(timeout_s=10)
    if autopilot is not None:
        assert b.link.autopilot == autopilot
    b.actions.arm()
    b.actions.takeoff(2.0)
    assert run_until(b, lambda: b.state().position[2] > 1.7, 10)
    assert emu.snapshot()["armed"] and emu.snapshot()["in_air"]


def test_udp_link_backend_listens_emulator_sends():
    """The usual SITL arrangement: the vehicle sends to udp 14550-style, the ground station listens (udpin)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    emu = MavlinkVehicleEmulator("px4", speedup=10, gps_lock_s=0.5)
    emu.start(f"udpout:127.0.0.1:{port}")
    b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink",
                                   mavlink=MavlinkConfig(connection=f"udpin:127.0.0.1:{port}")))
    try:
        _connect_and_take_off(b, emu)
    finally:
        b.close()
        emu.stop()


def test_udpout_backend_sends_first_to_a_listening_vehicle():
    """The other UDP arrangement (a companion computer pointed at an autopilot's UDP port): the vehicle listens
    (udpin) and knows no peer until the ground station speaks first, so the backend must not wait for the
    vehicle's HEARTBEAT before sending its own."""
    emu = MavlinkVehicleEmulator("ardupilot", speedup=10, gps_lock_s=0.5)
    addr = emu.start("udpin:127.0.0.1:0")
    b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink",
                                   mavlink=MavlinkConfig(connection=addr.replace("udpin", "udpout"))))
    try:
        _connect_and_take_off(b, emu, "ardupilot")
    finally:
        b.close()
        emu.stop()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pseudo-terminals as serial ports: Linux")
def test_serial_link_through_a_pseudo_terminal():
    """A telemetry radio or USB link: the backend opens a serial device (a pty here, with ``baud``) through
    pyserial; a relay carries the bytes between the pty and the emulated vehicle's UDP port, as a radio would."""
    import os
    import selectors
    import tty

    emu = MavlinkVehicleEmulator("px4", speedup=10, gps_lock_s=0.5)
    _, host, port = emu.start("udpin:127.0.0.1:0").split(":")
    master, slave = os.openpty()
    tty.setraw(slave)
    radio = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    radio.connect((host, int(port)))
    stop = threading.Event()
    carried = {"to_vehicle": 0, "to_gcs": 0}

    def relay() -> None:
        sel = selectors.DefaultSelector()
        sel.register(master, selectors.EVENT_READ, "pty")
        sel.register(radio, selectors.EVENT_READ, "udp")
        while not stop.is_set():
            for key, _ in sel.select(0.1):
                try:
                    if key.data == "pty":
                        data = os.read(master, 4096)
                        radio.send(data)
                        carried["to_vehicle"] += len(data)
                    else:
                        data = radio.recv(65535)
                        os.write(master, data)
                        carried["to_gcs"] += len(data)
                except OSError:
                    pass

    t = threading.Thread(target=relay, daemon=True)
    t.start()
    b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink",
                                   mavlink=MavlinkConfig(connection=os.ttyname(slave), baud=57600)))
    try:
        _connect_and_take_off(b, emu, "px4")
        assert carried["to_vehicle"] > 0 and carried["to_gcs"] > 0
    finally:
        b.close()
        stop.set()
        t.join(timeout=2)
        emu.stop()
        radio.close()
        os.close(master)
        os.close(slave)


def test_sim_cli_refuses_remote_bind_and_bad_address():
    from aerodaas.cli import main

    assert main(["sim", "--mavlink", "tcp:0.0.0.0:5760"]) == 2
    assert main(["sim", "--mavlink", "serial:/dev/null"]) == 2
    assert main(["sim", "--mavlink", "tcp:127.0.0.1:0", "--home", "47.3,8.5"]) == 2
    with pytest.raises(ValueError, match="allow-remote"):
        MavlinkVehicleEmulator("px4").start("udpin:10.1.2.3:14550")


def _tlog_packets(path: Path) -> list[bytes]:
    """Split a .tlog (8-byte big-endian µs timestamp + one MAVLink v1/v2 packet, repeated) into raw packets."""
    data = path.read_bytes()
    out, i = [], 0
    while i + 10 <= len(data):
        magic, n = data[i + 8], data[i + 9]
        if magic == 0xFD:
            size = 12 + n + (13 if data[i + 10] & 1 else 0)
        elif magic == 0xFE:
            size = 8 + n
        else:
            raise AssertionError(f"tlog desynchronised at byte {i}")
        out.append(data[i + 8:i + 8 + size])
        i += 8 + size
    return out


def test_real_px4_tlog_through_the_receive_path():
    """The real PX4 log (unknown message ids, messages captured twice) streamed over a loopback socket into
    connect() and the I/O thread: nothing raises, positions, home, status texts and mission progress parse."""
    tlog = DATA_DIR / "tlogs" / "thayer_rural.tlog"
    if not tlog.is_file():
        skip_or_fail(f"{tlog} not found (set AERODAAS_DATA_DIR)")
    packets = _tlog_packets(tlog)
    from pymavlink import mavutil

    ids = {mavutil.mavlink.MAVLink(None).parse_buffer(p)[0].get_msgId() for p in packets[:4000]}
    assert len(packets) > 30000 and ids
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    done = threading.Event()

    def serve():
        conn, _ = server.accept()
        for k in range(0, len(packets), 200):
            conn.sendall(b"".join(packets[k:k + 200]))
            time.sleep(0.002)
        done.set()
        time.sleep(30)
        conn.close()

    threading.Thread(target=serve, daemon=True).start()
    cfg = RobotConfig(id="thayer", backend="mavlink", home=CONFIG_HOME,
                      mavlink=MavlinkConfig(connection=f"tcp:127.0.0.1:{port}", command_timeout_s=0.1,
                                            command_retries=0, heartbeat_timeout_s=60))
    b = MavlinkBackend(cfg)
    try:
        b.connect(timeout_s=20)
        assert b.link.autopilot == "px4" and b.link.vehicle_type == "MAV_TYPE_QUADROTOR"
        assert done.wait(30)
        from aerodaas.backends.mavlink import shared_link

        link = shared_link.links()[cfg.mavlink.link_key()]
        seen = -1
        while seen != (link.messages, b.link.messages_received):  # until the receive path has drained the socket
            seen = (link.messages, b.link.messages_received)
            time.sleep(0.5)
        # the link read every packet; the robot got its own vehicle's (system id 1: 18905 of them; the ground
        # station's 255, a companion's 51 and unparsed ids go elsewhere)
        assert link.messages > 30000 and b.link.messages_received > 18000, (link.messages, b.link.messages_received)
        b.step(0.1)  # raises if the I/O thread failed
        events = b.drain_events()
        assert not [e for e in events if e["event"] == "receive_error"]
        assert b.telemetry.home_received and abs(b.telemetry.home.lat - 43.7) < 0.3 and abs(b.telemetry.home.lon + 72.2) < 0.5
        odo = b.telemetry.odometry()
        e, n, _ = geodetic_to_enu(odo.geodetic.lat, odo.geodetic.lon, b.telemetry.home.alt, b.telemetry.home)
        assert abs(odo.position[0] - e) < 0.01 and abs(odo.position[1] - n) < 0.01
        assert 0 < math.hypot(e, n) < 2000
        assert any(e["event"] == "status_text" and e["text"] for e in events)
        reached = [e for e in events if e["event"] == "mission_item_reached"]
        assert 0 < len(reached) < 176  # duplicated packets (two captured links) counted once
        assert {"MISSION", "RTL"} <= {e["name"] for e in events if e["event"] == "mode"}
    finally:
        b.close()
        server.close()


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_mavproxy_ground_station(autopilot, tmp_path):
    """MAVProxy, driven headless through its stdin, sees the emulated vehicle's heartbeat and position, switches
    its mode, arms it and takes off with the commands the README gives. (MAVProxy's ``mode NAME`` passes PX4's
    (base, main, sub) tuple to pymavlink's set_mode, which fails packing it, so for PX4 the mode goes out with the
    generic ``long DO_SET_MODE``.)"""
    if importlib.util.find_spec("MAVProxy") is None:
        skip_or_fail("MAVProxy not installed (pip install --no-deps 'MAVProxy>=1.8', as the README says)")
    emu = MavlinkVehicleEmulator(autopilot, home=VEHICLE_HOME, gps_lock_s=0.5)
    address = emu.start("tcp:127.0.0.1:0")
    proc = subprocess.Popen([sys.executable, "-m", "MAVProxy.mavproxy", "--master", address, "--no-state",
                             "--default-modules", "link,mode,arm,cmdlong,misc"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            bufsize=1, cwd=tmp_path)
    lines: list[str] = []
    threading.Thread(target=lambda: [lines.append(x.rstrip()) for x in proc.stdout], daemon=True).start()

    def wait_for(pred, timeout_s=20.0) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if pred():
                return True
            time.sleep(0.05)
        return False

    def say(cmd: str) -> None:
        proc.stdin.write(cmd + "\n")
        proc.stdin.flush()

    try:
        assert wait_for(lambda: any("online system 1" in x for x in lines)), lines
        assert wait_for(lambda: emu.snapshot()["home"] is not None, 10)
        assert wait_for(lambda: emu.snapshot()["links"] == 1, 5)
        # MAVProxy requests streams (REQUEST_DATA_STREAM) every 15 s, or at once when its stream rate changes; the
        # emulated ArduPilot streams nothing until asked
        say("set streamrate 5")
        lat = f"lat : {int(round(VEHICLE_HOME.lat * 1e7))}"

        def position_seen() -> bool:  # ask MAVProxy for the last GLOBAL_POSITION_INT it received
            say("status GLOBAL_POSITION_INT")
            time.sleep(0.3)
            return any("GLOBAL_POSITION_INT" in x and lat in x for x in lines)

        assert wait_for(position_seen, 10), lines[-10:]
        if autopilot == "ardupilot":
            say("mode guided")
            assert wait_for(lambda: emu.snapshot()["mode"] == "GUIDED", 10), lines[-10:]
            assert wait_for(lambda: any("Mode GUIDED" in x for x in lines), 5)
        else:
            def hold_mode() -> bool:  # like PX4, the emulator refuses Hold until it has a position estimate: retry
                say("long DO_SET_MODE 1 4 3")  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, AUTO, LOITER
                time.sleep(0.5)
                return emu.snapshot()["mode"] == "AUTO.LOITER"

            assert wait_for(hold_mode, 20), lines[-10:]
        say("arm throttle")
        assert wait_for(lambda: emu.snapshot()["armed"], 10), lines[-10:]
        assert wait_for(lambda: any("ARMED" in x for x in lines), 5)
        assert 400 in emu.snapshot()["commands_seen"]
        # a second ground station on the same TCP server (our backend) sees what MAVProxy did
        b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink", mavlink=MavlinkConfig(connection=address)))
        try:
            b.connect(timeout_s=10)
            assert b.state().armed and b.state().mode == ("GUIDED" if autopilot == "ardupilot" else "LOITER")
            assert emu.snapshot()["links"] == 2
        finally:
            b.close()
        # take-off as the README says: MAV_CMD_NAV_TAKEOFF param7 is metres above home on ArduPilot (MAVProxy's
        # `takeoff 5`), metres above mean sea level on PX4 (`takeoff 5` would mean 5 m AMSL)
        if autopilot == "ardupilot":
            say("takeoff 5")
        else:
            say(f"long NAV_TAKEOFF 0 0 0 nan nan nan {VEHICLE_HOME.alt + 5:g}")
        assert wait_for(lambda: emu.snapshot()["position"][2] > 0.3, 10), lines[-10:]
        assert emu.state.takeoff_alt == pytest.approx(5.0, abs=0.01)  # climbing to 5 m above home
        assert emu.snapshot()["mode"] == ("GUIDED" if autopilot == "ardupilot" else "AUTO.TAKEOFF")
    finally:
        proc.kill()  # --no-state: nothing to save
        proc.wait(5)
        emu.stop()


def test_recorded_odometry_ends_with_the_vehicles_end_state():
    """A vehicle reports its landing and disarm (EXTENDED_SYS_STATE, HEARTBEAT) between two position samples. A
    drone whose mission has ended is not settled (the clock keeps stepping it, odometry only) until a position
    sample carrying that state has been recorded: the CI run of 2026-11-23 ended a PX4 fleet robot's recording with
    ``in_air`` true after it had landed. Bounded: a vehicle that sends no further sample is settled after the wall
    bound."""
    from pymavlink.dialects.v20 import common as mav

    from tests.mavlink.mavlink_wire import WiredDrone

    def flying(w):
        w.heartbeat(True)
        w.landed_state(mav.MAV_LANDED_STATE_IN_AIR)
        w.drone.publish_odometry()
        for ms, alt in ((1000, 5.0), (1100, 4.0)):
            w.position(ms, alt_m=alt)
            w.drone.publish_odometry()

    def landed(w):
        w.landed_state(mav.MAV_LANDED_STATE_ON_GROUND)
        w.drone.publish_odometry()
        w.heartbeat(False)
        w.drone.publish_odometry()

    w = WiredDrone()
    d = w.drone
    flying(w)
    assert d.last_odom["in_air"] and d.last_odom["armed"]
    landed(w)  # landed and disarmed, no new position sample: nothing new is recorded
    assert not w.backend.state().in_air and not w.backend.state().armed and d.last_odom["in_air"]
    assert not d.settled(wait_s=60.0)
    w.position(1200, alt_m=0.0)
    d.publish_odometry()
    assert d.last_odom["in_air"] is False and d.last_odom["armed"] is False
    assert d.settled(wait_s=60.0)

    w = WiredDrone()  # the same, but the vehicle sends no further position
    d = w.drone
    flying(w)
    landed(w)
    assert not d.settled(wait_s=0.05)
    time.sleep(0.06)
    assert d.settled(wait_s=0.05)
