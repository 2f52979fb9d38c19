"""MAVLink 2 message signing (aerodaas/backends/mavlink/signing.py, the emulator's
aerodaas/emulators/mavlink/signing.py). Judged by what the vehicle did (the emulated autopilot's own state), what the
recording holds (read with the ``mcap`` package's reader) and the exit code a user meets. Spoofed messages come from
another process (a pymavlink ground station run with ``sys.executable``) or are written onto the link unsigned."""
from __future__ import annotations

import contextlib
import hashlib
import os
import subprocess
import sys
import textwrap

import numpy as np
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

#: an unsigned ground station in another process: MAV_CMD_COMPONENT_ARM_DISARM forced (param2 21196) with param1
#: ``sys.argv[2]`` (1 arms, 0 disarms), LAND, flight termination and a PARAM_SET, each sent 5 times over a second, as
#: system 255 component 190 (the ids our backend speaks as)
SPOOFER = textwrap.dedent("""
    import os, sys, time
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil
    arm = float(sys.argv[2])
    conn = mavutil.mavlink_connection(sys.argv[1], source_system=255, source_component=190, dialect="ardupilotmega")
    m = conn.mav
    for _ in range(5):
        m.command_long_send(1, 1, 400, 0, arm, 21196, 0, 0, 0, 0, 0)     # MAV_CMD_COMPONENT_ARM_DISARM, forced
        m.command_long_send(1, 1, 176, 0, 1, 9, 0, 0, 0, 0, 0)           # MAV_CMD_DO_SET_MODE LAND (ArduCopter 9)
        m.command_long_send(1, 1, 185, 0, 1, 0, 0, 0, 0, 0, 0)           # MAV_CMD_DO_FLIGHTTERMINATION
        m.param_set_send(1, 1, b"WPNAV_SPEED", 1234.0, 9)                # MAV_PARAM_TYPE_REAL32
        time.sleep(0.2)
    conn.close()
""")
#: :data:`SPOOFER`'s ``sys.argv[2]``: a forced arm (on the ground) or a forced disarm (in flight)
ARM, DISARM = "1", "0"


def _spoof(address: str, arm: str) -> None:
    """Run :data:`SPOOFER` against ``address`` (the emulator's tcp address) in another process, its arming command
    ``arm`` (:data:`ARM` or :data:`DISARM`)."""
    p = subprocess.run([sys.executable, "-c", SPOOFER, address, arm], capture_output=True, text=True, timeout=60)
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
        _spoof(open_emu.start("tcp:127.0.0.1:0"), ARM)
        assert open_emu.params["WPNAV_SPEED"] == 1234.0
    finally:
        open_emu.stop()
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, gps_lock_s=0.0, signing_key=KEY)
    try:
        address = emu.start("tcp:127.0.0.1:0")
        before = emu.snapshot()
        _spoof(address, ARM)
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
        _spoof(address, ARM)
        assert emu.params["WPNAV_SPEED"] != 1234.0 and not emu.snapshot()["armed"]
        p = _signing_cli("remove", address, key_file, "--secure-link")
        assert p.returncode == 0, p.stdout + p.stderr
        assert emu.signing.key is None and [k for _, k in emu.signing.setups][-1] == "disable"
        _spoof(address, ARM)
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


class _Taken:
    """Every message the backend *takes* (past its signature check, into its own update path) and its view right
    after: every message type through the handler the backend registered for it (``MavlinkLink.handlers``, the I/O
    thread's dispatch: telemetry, parameters, ...), and every autopilot HEARTBEAT through
    ``MavlinkLink.on_heartbeat``. Recorded in the I/O thread at the moment of the update, so a spoofed value is seen
    even when a real message overwrites it a moment later. :attr:`seen`: (message type, whether its packet was
    signed, the message, the view)."""

    def __init__(self, backend) -> None:
        from aerodaas.backends.mavlink.signing import sign_fields

        self.b, self.seen, self._signed = backend, [], lambda msg: sign_fields(msg.get_msgbuf())[0]
        link = backend.link
        for t, handler in list(link.handlers.items()):
            link.handlers[t] = self._wrap(t, handler)
        heartbeat = link.on_heartbeat

        def on_heartbeat(msg, now):
            heartbeat(msg, now)
            self._note("HEARTBEAT", msg)

        link.on_heartbeat = on_heartbeat  # dispatch calls self.on_heartbeat: the instance attribute wins

    def _wrap(self, mtype: str, handler):
        def wrapped(msg):
            handler(msg)
            self._note(mtype, msg)
        return wrapped

    def _note(self, mtype: str, msg) -> None:
        b = self.b
        odo = b.telemetry.odometry()  # under the backend's lock (an RLock the I/O thread holds here)
        view = {"position": tuple(odo.position), "battery_pct": odo.battery_pct, "voltage": odo.battery_voltage,
                "armed": b.link.armed, "mode": b.link.mode, "system_status": b.link.system_status,
                "failsafe": b.link.failsafe}
        self.seen.append((mtype, self._signed(msg), msg, view))

    def unsigned(self) -> list:
        """The unsigned messages the backend took (RADIO_STATUS, the one type allowed unsigned, aside)."""
        return [(t, m) for t, signed, m, _ in self.seen if not signed and t != "RADIO_STATUS"]


@contextlib.contextmanager
def _flying(tmp_path):
    """A signing emulated ArduCopter at 5x and a backend with its key (no Ray: driven as the runtime drives it),
    armed and hovering 5 m up in GUIDED. Yields (emulator, backend); closes both."""
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
        b.actions.arm()
        b.actions.takeoff(5.0)
        assert run_until(b, lambda: abs(b.state().position[2] - 5.0) < 0.3 and b.state().in_air, 30), b.state().position
        yield emu, b
    finally:
        b.close(safe_end=False)
        emu.stop()


def _inject_unsigned(emu, b, messages: list) -> None:
    """Write ``messages`` (pymavlink messages) onto the link unsigned, in the vehicle's name (system 1, component
    1), and drive the backend until its signature check has counted them all (or, were they taken, 5 s)."""
    from tests.mavlink.emulated import run_until

    enc = M.MAVLink(None, srcSystem=1, srcComponent=1)  # no key: unsigned
    before = b.signing.unsigned
    emu.inject(b"".join(m.pack(enc) for m in messages))
    run_until(b, lambda: b.signing.unsigned >= before + len(messages), 5.0)


def test_spoofed_position_and_battery_in_flight_are_never_taken(tmp_path):
    """In flight on a signing emulated ArduCopter: unsigned GLOBAL_POSITION_INT 100 m north, BATTERY_STATUS at 5 %
    (the battery the backend reads while the autopilot sends it) and SYS_STATUS at 5 % and 1 V (its voltage, and
    the battery without BATTERY_STATUS) written onto the link in the vehicle's name. Judged at every update the
    backend made (:class:`_Taken`): none of them was taken, no position, battery or voltage it held was the spoof's,
    and all were counted as ``link_unsigned`` events naming their types."""
    from tests.mavlink.emulated import run_until

    types = ("GLOBAL_POSITION_INT", "BATTERY_STATUS", "SYS_STATUS")
    with _flying(tmp_path) as (emu, b):
        taken = _Taken(b)
        home = emu.state.home
        spoofs = []
        for _ in range(10):
            spoofs += [M.MAVLink_global_position_int_message(int(emu.state.t * 1000) + 1,
                                                             int((home.lat + 100 / 111_320) * 1e7),
                                                             int(home.lon * 1e7), int((home.alt + 30) * 1000),
                                                             30_000, 0, 0, 0, 0),
                       M.MAVLink_battery_status_message(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767,
                                                        [1000] + [65535] * 9, -1, -1, -1, 5),
                       M.MAVLink_sys_status_message(0, 0, 0, 0, 1000, -1, 5, 0, 0, 0, 0, 0, 0)]
        _inject_unsigned(emu, b, spoofs)
        # the control: the observer does see the vehicle's own messages of each type on that path
        run_until(b, lambda: {t for t, *_ in taken.seen} >= set(types), 15.0)
        events = b.drain_events()
        unsigned_total = b.signing.unsigned
    events += b.drain_events()
    views = {t: [v for mt, _, _, v in taken.seen if mt == t] for t in types}
    assert all(views.values()), {t: len(v) for t, v in views.items()}
    far = max(float(np.hypot(*v["position"][:2])) for v in views["GLOBAL_POSITION_INT"])
    low = min(v["battery_pct"] for vs in views.values() for v in vs)
    volts = min(v["voltage"] for vs in views.values() for v in vs)
    assert far < 5.0 and low > 50.0 and volts > 2.0, (far, low, volts)
    assert taken.unsigned() == [], [t for t, _ in taken.unsigned()]
    dropped = [e for e in events if e["event"] == "link_unsigned"]
    assert set(types) <= {e.get("message") for e in dropped}, dropped
    assert unsigned_total >= len(spoofs), unsigned_total


#: unsigned HEARTBEATs in the autopilot's name, each claiming another state than the armed GUIDED flight: (base_mode,
#: ArduCopter custom_mode, system_status): disarmed in LAND (9), disarmed in RTL (6) with CRITICAL, armed in RTL
#: (a failsafe mode) with EMERGENCY, disarmed in GUIDED (4)
SPOOFED_HEARTBEATS = ((M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9, M.MAV_STATE_ACTIVE),
                      (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, M.MAV_STATE_CRITICAL),
                      (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED, 6, M.MAV_STATE_EMERGENCY),
                      (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, M.MAV_STATE_ACTIVE))


def test_unsigned_heartbeats_never_change_arming_mode_or_failsafe(tmp_path):
    """In flight (armed, GUIDED): unsigned HEARTBEATs from the autopilot's own system and component claiming
    disarmed, LAND, RTL (a failsafe mode) and system_status CRITICAL / EMERGENCY (:data:`SPOOFED_HEARTBEATS`). At
    every HEARTBEAT the backend took (:class:`_Taken`) it is signed and the view is armed, GUIDED, no failsafe,
    no critical state; no ``disarmed``, ``mode`` or ``autopilot_failsafe`` event; the HEARTBEATs counted as
    ``link_unsigned``."""
    from tests.mavlink.emulated import run_until

    with _flying(tmp_path) as (emu, b):
        assert b.link.armed and b.link.mode == "GUIDED", (b.link.armed, b.link.mode)
        taken = _Taken(b)
        b.drain_events()
        beats = [M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, custom, status,
                                             3)
                 for base, custom, status in SPOOFED_HEARTBEATS for _ in range(3)]
        _inject_unsigned(emu, b, beats)
        # the control: the vehicle's own (signed) HEARTBEATs reach the observer
        run_until(b, lambda: any(t == "HEARTBEAT" for t, *_ in taken.seen), 10.0)
        events = b.drain_events()
    views = [v for t, _, _, v in taken.seen if t == "HEARTBEAT"]
    assert views, "no HEARTBEAT taken meanwhile"
    bad = [v for v in views if not v["armed"] or v["mode"] != "GUIDED" or v["failsafe"] is not None
           or v["system_status"] in (M.MAV_STATE_CRITICAL, M.MAV_STATE_EMERGENCY)]
    assert not bad, bad[:3]
    assert taken.unsigned() == [], [t for t, _ in taken.unsigned()]
    names = [e["event"] for e in events]
    assert not {"disarmed", "mode", "autopilot_failsafe"} & set(names), names
    assert "HEARTBEAT" in {e.get("message") for e in events if e["event"] == "link_unsigned"}, events


def test_an_unsigned_forced_disarm_in_flight_changes_nothing(tmp_path):
    """In flight (armed, GUIDED, 5 m up): a forced disarm (MAV_CMD_COMPONENT_ARM_DISARM param1 0, param2 21196),
    LAND, flight termination and PARAM_SET, unsigned, from another process (:data:`SPOOFER`). Checked in flight,
    right after: the emulated autopilot's own state is still armed, in the air, in GUIDED; it saw none of the
    commands; the parameter is unchanged; the backend's view (every HEARTBEAT it took) stayed armed in GUIDED."""
    from tests.mavlink.emulated import run_until

    with _flying(tmp_path) as (emu, b):
        taken = _Taken(b)
        seen0 = len(emu.snapshot()["commands_seen"])
        _spoof(emu.address, DISARM)
        run_until(b, lambda: False, 1.0)  # the vehicle's answer, had it taken any, reaches the backend
        vehicle = emu.snapshot()
        in_flight = b.state().in_air
    assert vehicle["armed"] and vehicle["in_air"] and vehicle["mode"] == "GUIDED", vehicle
    assert in_flight
    assert not {400, 176, 185} & set(vehicle["commands_seen"][seen0:]), vehicle["commands_seen"]
    assert emu.params["WPNAV_SPEED"] != 1234.0
    views = [v for t, _, _, v in taken.seen if t == "HEARTBEAT"]
    assert views and all(v["armed"] and v["mode"] == "GUIDED" for v in views), views[-3:]


def test_a_refused_key_travels_to_exit_code_2():
    """The plumbing from the drone actor to ``aerodaas run``'s exit code, without Ray: a CredentialsRefused robot is
    named in RobotsNotConnected.refused, which survives pickling (Ray carries it so), and a run whose outcome is
    ``refused`` exits 2, one that merely failed exits 1."""
    import pickle

    from aerodaas.backends.base import RobotsNotConnected
    from aerodaas.runtime.driver import MissionResult
    from aerodaas.runtime.fly import exit_code

    e = pickle.loads(pickle.dumps(RobotsNotConnected({"a": "CredentialsRefused: no correctly signed heartbeat",
                                                      "b": "BackendError: no HEARTBEAT"}, ("a",))))
    assert e.refused == ("a",) and set(e.errors) == {"a", "b"}

    def result(outcome):
        return MissionResult(outcome=outcome, robots={}, stats={}, latency={}, recording=None, wall_s=0.0)

    assert exit_code([result("refused")], []) == 2 and exit_code([result("failed")], []) == 1
