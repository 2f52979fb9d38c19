"""MAVLink 2 message signing (aerodaas/backends/mavlink/signing.py, the emulator's
aerodaas/emulators/mavlink/signing.py). Judged by what the vehicle did (the emulated autopilot's own state), what the
recording holds (read with the ``mcap`` package's reader) and the exit code a user meets. Spoofed messages come from
another process (a pymavlink ground station run with ``sys.executable``) or are written onto the link unsigned."""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import textwrap

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends.mavlink.signing import (
    NEW_STREAM_WINDOW,
    LinkSigning,
    SignatureCheck,
    TimestampStore,
    Verdict,
    now_timestamp,
)
from tests.inputs.test_app_errors_before_ray import _cli, _refused_before_ray, _write

KEY = hashlib.sha256(b"aerodaas signing test key").digest()
OTHER_KEY = hashlib.sha256(b"someone else's key").digest()

#: an unsigned ground station in another process: arm (forced), LAND, flight termination and a PARAM_SET, each
#: sent 5 times over a second, as system 255 component 190 (the ids our backend speaks as)
SPOOFER = textwrap.dedent("""
    import os, sys, time
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(sys.argv[1], source_system=255, source_component=190, dialect="ardupilotmega")
    m = conn.mav
    for _ in range(5):
        m.command_long_send(1, 1, 400, 0, 1, 21196, 0, 0, 0, 0, 0)       # MAV_CMD_COMPONENT_ARM_DISARM, forced
        m.command_long_send(1, 1, 176, 0, 1, 9, 0, 0, 0, 0, 0)           # MAV_CMD_DO_SET_MODE LAND (ArduCopter 9)
        m.command_long_send(1, 1, 185, 0, 1, 0, 0, 0, 0, 0, 0)           # MAV_CMD_DO_FLIGHTTERMINATION
        m.param_set_send(1, 1, b"WPNAV_SPEED", 1234.0, 9)                # MAV_PARAM_TYPE_REAL32
        time.sleep(0.2)
    conn.close()
""")


def _spoof(address: str) -> None:
    """Run :data:`SPOOFER` against ``address`` (the emulator's tcp address) in another process."""
    p = subprocess.run([sys.executable, "-c", SPOOFER, address], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr[-1500:]


def _key_file(path, key: bytes = KEY, mode: int = 0o600) -> str:
    path.write_text(key.hex() + "\n")
    os.chmod(path, mode)
    return str(path)


def _packet(msg, key: bytes | None, timestamp: int, system: int = 1):
    """``msg`` framed as MAVLink 2 by system ``system`` component 1 (signed with ``key`` at ``timestamp``, or
    unsigned) and parsed back, as the backend's receive path gets it."""
    enc = M.MAVLink(None, srcSystem=system, srcComponent=1)
    if key is not None:
        enc.signing.secret_key, enc.signing.sign_outgoing, enc.signing.timestamp = key, True, timestamp
    buf = msg.pack(enc)
    return M.MAVLink(None).parse_buffer(buf)[0]


def _heartbeat():
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)


def test_the_signature_check_takes_only_correctly_signed_new_messages():
    check, now = SignatureCheck(KEY), now_timestamp()
    assert check.verdict(_packet(_heartbeat(), KEY, now), now) is Verdict.SIGNED
    assert check.verdict(_packet(_heartbeat(), KEY, now), now) is Verdict.REPLAYED  # the same timestamp again
    assert check.verdict(_packet(_heartbeat(), KEY, now + 1), now) is Verdict.SIGNED
    assert check.verdict(_packet(_heartbeat(), OTHER_KEY, now + 50), now) is Verdict.BAD_SIGNATURE
    assert check.verdict(_packet(_heartbeat(), None, 0), now) is Verdict.UNSIGNED
    radio = M.MAVLink_radio_status_message(200, 190, 100, 90, 80, 0, 0)
    assert check.verdict(_packet(radio, None, 0), now) is Verdict.ALLOWED_UNSIGNED
    for spoof in (M.MAVLink_global_position_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0),
                  M.MAVLink_sys_status_message(0, 0, 0, 0, 12000, -1, 5, 0, 0, 0, 0, 0, 0)):
        assert check.verdict(_packet(spoof, None, 0), now) is Verdict.UNSIGNED
    # a new stream (system 2) more than a minute older than our clock is a replay (spec: Accepting Signed Packets)
    assert check.verdict(_packet(_heartbeat(), KEY, now - NEW_STREAM_WINDOW - 100, system=2), now) is Verdict.REPLAYED
    # a forged packet with a huge timestamp does not lock the real stream out (signature checked first)
    assert check.verdict(_packet(_heartbeat(), OTHER_KEY, now + 10**9), now) is Verdict.BAD_SIGNATURE
    assert check.verdict(_packet(_heartbeat(), KEY, now + 2), now) is Verdict.SIGNED


def test_a_restart_never_reuses_a_signing_timestamp(tmp_path, monkeypatch):
    """The timestamp store runs ahead of use: a second process on the key starts after everything the first used,
    even when the first was killed (no close) and the clock has been set back a long way (the stored value, not the
    clock, decides: spec, Timestamp Handling)."""
    from aerodaas.backends.mavlink import signing

    path = _key_file(tmp_path / "key")
    first = LinkSigning(path, "r", print)
    enc = M.MAVLink(None, srcSystem=255, srcComponent=190)
    for _ in range(5):
        first.before_send(enc)
        enc.heartbeat_encode(6, 8, 0, 0, 4).pack(enc)  # pack() signs and steps the timestamp
        first.after_send(enc)
    used = enc.signing.timestamp - 1
    store = TimestampStore(path)
    assert store.load() > used and os.stat(store.path).st_mode & 0o777 == 0o600
    monkeypatch.setattr(signing, "now_timestamp", lambda: used - 10**8)  # the clock a quarter hour back
    second = LinkSigning(path, "r", print)
    enc2 = M.MAVLink(None, srcSystem=255, srcComponent=190)
    second.before_send(enc2)
    assert enc2.signing.timestamp > used


def test_unsigned_commands_from_another_process_change_nothing_on_a_signing_vehicle():
    """A control first: the same spoofer does change an emulated vehicle that does not sign (its PARAM_SET lands),
    so the refusal below is signing's doing. With a key, the vehicle stays disarmed in its mode, its parameter
    unchanged, and its parser counts the rejected packets."""
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

    open_emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, gps_lock_s=0.0)
    try:
        _spoof(open_emu.start("tcp:127.0.0.1:0"))
        assert open_emu.params["WPNAV_SPEED"] == 1234.0
    finally:
        open_emu.stop()
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, gps_lock_s=0.0, signing_key=KEY)
    try:
        address = emu.start("tcp:127.0.0.1:0")
        before = emu.snapshot()
        _spoof(address)
        after = emu.snapshot()
        rejected = emu.signing.rejected
    finally:
        emu.stop()
    assert emu.params["WPNAV_SPEED"] != 1234.0
    assert not after["armed"] and after["mode"] == before["mode"]
    assert not {400, 176, 185} & {c for c in after["commands_seen"]}, after["commands_seen"]
    assert rejected >= 20, rejected  # 5 rounds of 4 messages


@pytest.mark.parametrize("case,expect", [
    ("missing", "not found"),
    ("group_readable", "has mode 0640"),
    ("short", "holds 31 bytes"),
    ("not_hex", "holds 65 bytes"),
])
def test_bad_key_files_are_refused_before_ray(tmp_path, case, expect):
    name = "vehicle.key"
    if case == "group_readable":
        _key_file(tmp_path / name, mode=0o640)
    elif case == "short":
        (tmp_path / name).write_bytes(os.urandom(31))
        os.chmod(tmp_path / name, 0o600)
    elif case == "not_hex":
        (tmp_path / name).write_text("z" * 64 + "\n")
        os.chmod(tmp_path / name, 0o600)
    app = _write(tmp_path, robot={"backend": "mavlink", "mavlink": {"signing_key_file": name}})
    p, ray_tmp = _cli(tmp_path, "run", app)
    _refused_before_ray(p, ray_tmp, "robots.0.mavlink.signing_key_file", repr(name), expect)


def test_a_key_in_the_environment_file_is_refused_without_quoting_it(tmp_path):
    app = _write(tmp_path, robot={"backend": "mavlink", "mavlink": {"signing_key_file": KEY.hex()}})
    p, ray_tmp = _cli(tmp_path, "plan", app)
    _refused_before_ray(p, ray_tmp, "signing_key_file", "looks like a signing key itself")
    assert KEY.hex() not in p.stderr + p.stdout


def _signing_cli(action: str, address: str, key_file: str, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "mavlink", "signing", action, "--connection", address,
                           "--key-file", key_file, "--timeout", "20", *extra], capture_output=True, text=True,
                          timeout=300)


def test_setup_provisions_the_vehicle_and_remove_takes_the_key_away(tmp_path):
    """``aerodaas mavlink signing setup`` on a vehicle that does not sign: afterwards it holds the key (the
    emulated autopilot's own state) and drops an unsigned PARAM_SET from another process; ``remove`` switches it
    off again. Without --secure-link nothing is sent (exit 2)."""
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

    key_file = str(tmp_path / "new.key")
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, gps_lock_s=0.0)
    try:
        address = emu.start("tcp:127.0.0.1:0")
        p = _signing_cli("setup", address, key_file, "--generate")
        assert p.returncode == 2 and "--secure-link" in p.stderr and emu.signing.setups == [], p.stderr
        p = _signing_cli("setup", address, key_file, "--generate", "--secure-link")
        assert p.returncode == 0, p.stdout + p.stderr
        assert os.stat(key_file).st_mode & 0o777 == 0o600
        from aerodaas.backends.mavlink.signing import read_key_file

        assert emu.signing.key == read_key_file(key_file)
        _spoof(address)
        assert emu.params["WPNAV_SPEED"] != 1234.0
        p = _signing_cli("remove", address, key_file, "--secure-link")
        assert p.returncode == 0, p.stdout + p.stderr
        assert emu.signing.key is None and [k for _, k in emu.signing.setups][-1] == "disable"
        _spoof(address)
        assert emu.params["WPNAV_SPEED"] == 1234.0  # an open vehicle again
    finally:
        emu.stop()


def test_vehicles_with_their_own_keys_share_one_link(tmp_path):
    """Two emulated vehicles (system ids 1 and 2, each its own key) behind one UDP router (tests/video/udp_fanout.py),
    two backends on the one link, each with its vehicle's key file: both connect signed, and a parameter written
    through robot 1 changes vehicle 1 only (vehicle 2 drops what is signed with the other key)."""
    from aerodaas.backends import make_backend
    from aerodaas.config import MavlinkConfig, RobotConfig
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from tests.video.udp_fanout import UdpFanout

    keys = {1: KEY, 2: OTHER_KEY}
    emus = {s: MavlinkVehicleEmulator("ardupilot", speedup=5.0, system_id=s, gps_lock_s=1.0, signing_key=k)
            for s, k in keys.items()}
    for e in emus.values():
        e.start("udpin:127.0.0.1:0")
    router = UdpFanout([int(e.address.rsplit(":", 1)[1]) for e in emus.values()])
    backends = {}
    try:
        for s, k in keys.items():
            mc = MavlinkConfig(connection=f"udpout:127.0.0.1:{router.gcs_port}", target_system=s,
                               signing_key_file=_key_file(tmp_path / f"v{s}.key", k), set_speed_limits=False)
            backends[s] = make_backend(RobotConfig(id=f"r{s}", backend="mavlink", mavlink=mc))
            backends[s].connect()
        backends[1].parameters.set("WPNAV_SPEED", 321.0)
        assert emus[1].params["WPNAV_SPEED"] == 321.0 and emus[2].params["WPNAV_SPEED"] != 321.0
        assert backends[2].parameters.read(["WPNAV_SPEED"])["WPNAV_SPEED"] != 321.0
        assert backends[1].signing.bad_signature == 0 and backends[2].signing.bad_signature == 0
        assert emus[2].signing.rejected > 0  # it heard robot 1's messages, signed with a key it does not hold
    finally:
        for b in backends.values():
            b.close(safe_end=False)
        router.close()
        for e in emus.values():
            e.stop()


def test_spoofed_telemetry_and_commands_in_flight_change_nothing_the_backend_knows(tmp_path):
    """In flight on a signing emulated ArduCopter (no Ray: the backend driven as the runtime drives it): unsigned
    GLOBAL_POSITION_INT 100 m north and SYS_STATUS at 5 % written onto the link in the vehicle's name, and an
    unsigned forced disarm, LAND, flight termination and PARAM_SET from another process. The backend's position
    and battery never show them, its mode and arming stay, the vehicle flies on, and the dropped messages are
    ``link_unsigned`` events naming their types."""
    import numpy as np

    from aerodaas.backends import make_backend
    from aerodaas.config import MavlinkConfig, RobotConfig
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from tests.mavlink.emulated import run_until

    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, gps_lock_s=1.0, signing_key=KEY)
    address = emu.start("tcp:127.0.0.1:0")
    mc = MavlinkConfig(connection=address, target_system=1, signing_key_file=_key_file(tmp_path / "v.key"),
                       set_speed_limits=False)
    b = make_backend(RobotConfig(id="r", backend="mavlink", mavlink=mc))
    try:
        b.connect()
        assert run_until(b, lambda: b.telemetry.home_received, 10)
        b.arm()
        b.takeoff(5.0)
        assert run_until(b, lambda: abs(b.position[2] - 5.0) < 0.3 and b.in_air, 30), b.position
        mode = b.mode
        enc = M.MAVLink(None, srcSystem=1, srcComponent=1)  # no key: unsigned, in the vehicle's name
        home = emu.state.home
        seen_pos, seen_batt = [], []
        for _ in range(20):
            pos = M.MAVLink_global_position_int_message(int(emu.state.t * 1000) + 1, int((home.lat + 100 / 111_320) * 1e7),
                                                        int(home.lon * 1e7), int((home.alt + 30) * 1000), 30_000,
                                                        0, 0, 0, 0)
            status = M.MAVLink_sys_status_message(0, 0, 0, 0, 10_000, -1, 5, 0, 0, 0, 0, 0, 0)
            emu.inject(pos.pack(enc) + status.pack(enc))
            run_until(b, lambda: False, 0.05)
            seen_pos.append(float(np.hypot(*b.position[:2])))
            seen_batt.append(b.battery_pct)
        _spoof(address)
        run_until(b, lambda: False, 1.0)
        events = b.drain_events()
        vehicle = emu.snapshot()
    finally:
        b.close()  # reports the counts not yet reported (LinkSigning.close)
        emu.stop()
    events += b.drain_events()
    assert max(seen_pos) < 5.0 and min(seen_batt) > 50.0, (max(seen_pos), min(seen_batt))
    assert vehicle["armed"] and vehicle["in_air"] and vehicle["mode"] == mode, vehicle["mode"]
    dropped = [e for e in events if e["event"] == "link_unsigned"]
    assert {"GLOBAL_POSITION_INT", "SYS_STATUS"} <= {e.get("message") for e in dropped}, dropped
    assert max(e["total"] for e in dropped) >= 40, dropped
    assert emu.params["WPNAV_SPEED"] != 1234.0 and 185 not in vehicle["commands_seen"]


def test_a_refused_key_travels_to_exit_code_2():
    """The plumbing from the drone actor to ``aerodaas run``'s exit code, without Ray: a CredentialsRefused robot is
    named in RobotsNotConnected.refused, which survives pickling (Ray carries it so), and a run whose outcome is
    ``refused`` exits 2, one that merely failed exits 1."""
    import pickle

    from aerodaas.backends.base import RobotsNotConnected
    from aerodaas.commands.run_main import _exit_code
    from aerodaas.runtime.driver import MissionResult

    e = pickle.loads(pickle.dumps(RobotsNotConnected({"a": "CredentialsRefused: no correctly signed heartbeat",
                                                      "b": "BackendError: no HEARTBEAT"}, ("a",))))
    assert e.refused == ("a",) and set(e.errors) == {"a", "b"}

    def result(outcome):
        return MissionResult(outcome=outcome, robots={}, stats={}, latency={}, recording=None, wall_s=0.0)

    assert _exit_code([result("refused")], []) == 2 and _exit_code([result("failed")], []) == 1
