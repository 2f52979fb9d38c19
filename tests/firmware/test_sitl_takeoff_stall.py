"""Real ArduCopter SITL whose motors lift nothing (``SIM_ENGINE_FAIL`` 15: motors 1-4, ``SIM_ENGINE_MUL`` 0;
libraries/SITL/SITL.cpp), flying apps/farm_survey.py (nothing bounded a take-off). The firmware
accepts GUIDED, the arm and NAV_TAKEOFF and never climbs; the drone must end the take-off at its deadline. The
drone's flight logic flies it alone, without Ray (``tests.firmware.sitl_no_lift drive``: on this shared machine Ray's own
start timed out at load 30-40 when this was written; the full runtime's handling of the outcome and exit code is
tested on the simulator and the emulator in tests/safety/test_phase_deadlines.py). Judged from the firmware's own telemetry
on its second link (:mod:`tests.firmware.sitl_no_lift`: it never climbed, it went GUIDED then LAND and disarmed) and from
the drone's recorded events, states and outcome. Marker ``sitl``."""
from __future__ import annotations

import json
import shlex
import sys

import pytest

from tests.conftest import needs_sitl
from tests.firmware import sitl

# without the firmware or a network namespace: skipped, failed in CI (tests/conftest.py needs_sitl)
pytestmark = [pytest.mark.sitl, pytest.mark.timeout(1200), needs_sitl]

#: ArduCopter mode numbers (ArduCopter/mode.h Mode::Number)
GUIDED, LAND = 4, 9


def test_an_arducopter_whose_motors_lift_nothing_is_stalled_at_the_takeoff_deadline_and_landed(tmp_path):
    autopilot = "ardupilot"
    env = sitl.small_cameras(sitl.mavlink_env(autopilot, sitl.FARM_ENV))  # the camera is not under test
    robot = env["robots"][0]
    env_path = tmp_path / "nolift.json"
    env_path.write_text(json.dumps(env))
    py = shlex.quote(sys.executable)
    mon = sitl.monitor_connection(autopilot)
    observed, flown = tmp_path / "observed.json", tmp_path / "flown.json"
    steps = [f"{py} -m tests.firmware.sitl_no_lift set-params {mon} SIM_ENGINE_FAIL=15 SIM_ENGINE_MUL=0",
             f"( {py} -m tests.firmware.sitl_no_lift observe {mon} {shlex.quote(str(observed))} 400 & ) ; "
             f"{py} -m tests.firmware.sitl_no_lift drive {shlex.quote(str(env_path))} {shlex.quote(str(flown))} 300; sleep 4"]
    sitl.run_in_namespace(autopilot, tmp_path / "ns", steps, timeout_s=900)
    rc_params, out_params = sitl.step_result(tmp_path / "ns", 0)
    rc, out = sitl.step_result(tmp_path / "ns", 1)
    assert rc_params == 0, out_params[-2000:]
    assert rc == 0 and flown.exists() and observed.exists(), f"exit {rc}\n{out[-3000:]}"
    fw, run = json.loads(observed.read_text()), json.loads(flown.read_text())
    ev = run["events"]
    stall = [e for e in ev if e["event"] == "takeoff_stalled"]
    print(f"stall {stall}; firmware modes {fw['modes']}; highest {max(a for _, a in fw['alts']):.2f} m "
          f"({len(fw['alts'])} samples); texts {[t for _, t in fw['texts']][-8:]}")
    # the firmware's own view: armed, took the take-off in GUIDED, never climbed, LAND, disarmed
    assert fw["armed"] and fw["disarmed"], fw
    modes = [m for _, m in fw["modes"]]
    assert GUIDED in modes and LAND in modes[modes.index(GUIDED):], fw["modes"]
    assert len(fw["alts"]) > 50 and max(a for _, a in fw["alts"]) < 0.3, fw["alts"][-20:]
    # the drone's record: the event at the deadline derived from the robot's limits, the action, the outcome
    lim = robot["limits"]["max_vertical_speed"]
    assert len(stall) == 1 and stall[0]["action"] == "land", stall
    assert stall[0]["deadline_s"] == pytest.approx(2.0 * robot["takeoff_altitude"] / lim + 15.0)
    assert stall[0]["elapsed_s"] >= stall[0]["deadline_s"] and stall[0]["height_m"] < 0.3
    assert run["outcome"] == "takeoff_stalled" and run["states"][-3:] == ["TAKING_OFF", "LANDING", "LANDED"], run
    assert not run["armed_end"]
