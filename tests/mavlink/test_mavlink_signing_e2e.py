"""MAVLink 2 message signing through the whole runtime (Ray, the drone actor, the recorder) on the MAVLink
emulator. A signed survey flies while unsigned telemetry in the vehicle's name and unsigned commands from another
process are refused (judged from the recording, read with the ``mcap`` package, and the emulated autopilot's own
state); a key the vehicle does not hold fails before take-off with exit 2."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from tests.mavlink.test_mavlink_signing import DISARM, KEY, OTHER_KEY, SPOOFED_HEARTBEATS, SPOOFER, _key_file


def _signed_survey(tmp_path, vehicle_key: bytes, key_file_key: bytes, connect_timeout_s: float = 30.0):
    """apps/farm_survey.py on an emulated ArduCopter at 10x that signs with ``vehicle_key``, the robot's
    ``mavlink.signing_key_file`` holding ``key_file_key``. Returns (emulator, environment file)."""
    from tests.runtime.test_backends_e2e import _mavlink_variant

    key_path = _key_file(tmp_path / "vehicle.key", key_file_key)
    emu, env_path = _mavlink_variant("farm_survey", "ardupilot", 10.0, tmp_path,
                                     mavlink={"signing_key_file": key_path, "connect_timeout_s": connect_timeout_s})
    emu.stop()  # the same vehicle again, now with its key (the variant's emulator was made without one)
    from aerodaas.config import load_environment_config
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

    robot = load_environment_config(str(env_path)).robots[0]
    emu = MavlinkVehicleEmulator("ardupilot", robot=robot, speedup=10.0, signing_key=vehicle_key)
    data = json.loads(env_path.read_text())
    data["robots"][0]["mavlink"]["connection"] = emu.start("tcp:127.0.0.1:0")
    env_path.write_text(json.dumps(data))
    return emu, env_path


#: :data:`tests.mavlink.test_mavlink_signing.SPOOFER`'s messages from a process started (and connected) before the flight
#: that sends them when told to (a line on its stdin): the attack does not wait for a Python start-up in flight
READY_SPOOFER = SPOOFER.replace("m = conn.mav\n", "m = conn.mav\nprint('ready', flush=True)\nsys.stdin.readline()\n")
assert READY_SPOOFER != SPOOFER, "tests.mavlink.test_mavlink_signing.SPOOFER no longer has the line to wait after"


class _Attack(threading.Thread):
    """Once the vehicle is in the air: unsigned GLOBAL_POSITION_INT 100 m north of it, BATTERY_STATUS at 5 % (the
    battery the backend reads), SYS_STATUS at 5 % and 1 V, and HEARTBEATs claiming disarmed / LAND / RTL / a critical
    state (:data:`~tests.mavlink.test_mavlink_signing.SPOOFED_HEARTBEATS`) written onto the link in the vehicle's
    name (system 1, component 1), then :data:`READY_SPOOFER` (a forced disarm, LAND, flight termination, PARAM_SET,
    from another process) released. :attr:`after`: the emulated autopilot's own state right after the spoofer
    ended, while still in flight; :attr:`rejected`: the packets the vehicle's parser refused meanwhile. Waits until
    the vehicle flies or :attr:`stop` is set (no wall-clock limit: the test's own timeout bounds it)."""

    def __init__(self, emu) -> None:
        super().__init__(daemon=True)
        self.emu, self.after, self.rejected, self.error = emu, None, 0, None
        self.stop = threading.Event()
        self.spoofer = subprocess.Popen([sys.executable, "-c", READY_SPOOFER, emu.address, DISARM], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def run(self) -> None:
        try:
            assert self.spoofer.stdout.readline().strip() == "ready", self.spoofer.stderr.read()[-1500:]
            while not self.stop.is_set() and not self.emu.snapshot()["in_air"]:
                time.sleep(0.02)
            if self.stop.is_set():
                return
            rejected0 = self.emu.signing.rejected
            enc = M.MAVLink(None, srcSystem=1, srcComponent=1)  # no key: unsigned
            home = self.emu.state.home
            for i in range(10):
                lat = int((home.lat + 100.0 / 111_320.0) * 1e7)
                pos = M.MAVLink_global_position_int_message(int(self.emu.state.t * 1000) + 1, lat,
                                                            int(home.lon * 1e7), int((home.alt + 30) * 1000),
                                                            30_000, 0, 0, 0, 0)
                status = M.MAVLink_sys_status_message(0, 0, 0, 0, 1000, -1, 5, 0, 0, 0, 0, 0, 0)
                battery = M.MAVLink_battery_status_message(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO,
                                                           32767, [1000] + [65535] * 9, -1, -1, -1, 5)
                base, custom, state = SPOOFED_HEARTBEATS[i % len(SPOOFED_HEARTBEATS)]
                beat = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, custom,
                                                   state, 3)
                self.emu.inject(b"".join(m.pack(enc) for m in (pos, status, battery, beat)))
                time.sleep(0.02)
            out, err = self.spoofer.communicate("go\n", timeout=120)
            assert self.spoofer.returncode == 0, err[-1500:]
            self.rejected = self.emu.signing.rejected - rejected0
            self.after = self.emu.snapshot()
        except Exception as e:  # noqa: BLE001 - reported by the test
            self.error = e
        finally:
            if self.spoofer.poll() is None:
                self.spoofer.kill()
                self.spoofer.wait()


@pytest.mark.e2e
def test_a_signed_mission_flies_and_unsigned_spoofs_change_nothing_in_the_recording(ray_session, run_options,
                                                                                    tmp_path):
    from aerodaas.runtime.report import format_summary
    from tests.firmware.sitl import read_recording
    from tests.runtime.test_backends_e2e import _run_app

    emu, env_path = _signed_survey(tmp_path, KEY, KEY)
    attack = _Attack(emu)
    attack.start()
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
    finally:
        attack.stop.set()
        attack.join()
        vehicle = emu.snapshot()
        params = dict(emu.params)
        emu.stop()
    assert attack.error is None and attack.after is not None, attack.error
    # the forced disarm, LAND and flight termination came in flight: right after them the vehicle still flies armed
    assert attack.after["armed"] and attack.after["in_air"] and attack.after["mode"] != "LAND", attack.after
    assert attack.rejected >= 20, attack.rejected  # the spoofer's 5 rounds of 4 unsigned messages, all refused
    rep = res.robots["quadrotor_base"]
    assert res.outcome == "success", rep.get("error")
    # landed and disarmed by the survey itself; our backend sends 400 and 176 too, flight termination never
    assert not vehicle["armed"] and 185 not in vehicle["commands_seen"] and params["WPNAV_SPEED"] != 1234.0
    rec = read_recording(tmp_path / "farm.mcap")
    ev = [m for _, m in rec["/quadrotor_base/events"]]
    names = [e["event"] for e in ev]
    assert not {"battery_critical", "battery_low", "failsafe_rtl", "autopilot_failsafe"} & set(names), names
    # armed once, disarmed once after landing: a spoofed HEARTBEAT taken would add a disarm (and a re-arm) in flight
    assert names.count("armed") == 1 and names.count("disarmed") <= 1, [n for n in names if "arm" in n]
    dropped = {e.get("message") for e in ev if e["event"] == "link_unsigned"}
    assert {"GLOBAL_POSITION_INT", "SYS_STATUS", "BATTERY_STATUS", "HEARTBEAT"} <= dropped, \
        [e for e in ev if e["event"] == "link_unsigned"]
    unsigned_total = max(e["total"] for e in ev if e["event"] == "link_unsigned")
    assert unsigned_total >= 6  # the first five one by one, then a summary (reports are lower bounds: 5 s apart)
    odo = [m for _, m in rec["/quadrotor_base/odometry"]]
    # the survey stays within ~60 m of home; a spoofed fix would put a sample 100 m north (every position sample the
    # backend takes is recorded: telemetry.py _queue_odometry)
    far = max(math.hypot(*o["position"][:2]) for o in odo)
    assert far < 90.0, far
    # BATTERY_STATUS comes every 2 vehicle seconds, SYS_STATUS every second: a spoof taken would stand in several
    # position samples
    assert min(o["battery_pct"] for o in odo if o.get("battery_pct") is not None) > 50.0
    assert min(o["battery_voltage"] for o in odo if o.get("battery_voltage")) > 2.0
    assert "MAVLink signing: at least" in format_summary(res)


@pytest.mark.e2e
def test_a_key_the_vehicle_does_not_hold_fails_before_take_off_with_exit_2(ray_session, run_options, tmp_path):
    from aerodaas.runtime.fly import exit_code
    from tests.runtime.test_backends_e2e import _run_app

    emu, env_path = _signed_survey(tmp_path, OTHER_KEY, KEY, connect_timeout_s=5.0)
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
        vehicle, took_off = emu.snapshot(), emu.state.took_off
    finally:
        emu.stop()
    err = res.robots["quadrotor_base"].get("error", "")
    assert res.outcome == "refused" and exit_code([res], []) == 2, (res.outcome, err)
    assert "no correctly signed heartbeat from system 1 within 5 s" in err, err
    assert not vehicle["armed"] and not vehicle["in_air"] and vehicle["commands_seen"] == []
    assert not took_off  # the emulated autopilot's own record: it never left the ground
