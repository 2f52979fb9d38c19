"""Gimbal protocol v2 against real ArduCopter SITL firmware (slow group ``sitl``): a copter whose mount is a
two-servo gimbal (the vehicle's hardware configuration: ``MNT1_TYPE 1`` servo mount, ``SERVO9_FUNCTION 7`` pitch,
``SERVO10_FUNCTION 6`` yaw; every other parameter ArduCopter's SITL default). Our
:class:`~aerodaas.backends.mavlink.gimbal.GimbalManager` points it; the firmware, acting as gimbal manager, moves
the mount and reports GIMBAL_DEVICE_ATTITUDE_STATUS, which is what is judged — with the limits it reports in
GIMBAL_MANAGER_INFORMATION, and for a region of interest, beside what our geometry
(:func:`aerodaas.navigation.gimbal.roi_angles`) predicts from the firmware's own position and heading."""
from __future__ import annotations

import json
import shlex
import sys

import pytest

from tests.firmware import sitl

pytestmark = [pytest.mark.sitl]

MOUNT_PARAMS = "MNT1_TYPE 1\nSERVO9_FUNCTION 7\nSERVO10_FUNCTION 6\n"


def _firmware(tmp_path) -> str:
    """The shell step that starts ArduCopter SITL with the mount parameters at :data:`sitl.SPEEDUP` (the probes wait
    on the firmware's messages, not on the wall clock), sending to UDP 14550 (the test fails when no private network
    namespace can be made)."""
    reason = sitl.namespace_skip_reason()
    if reason:
        pytest.fail(reason)
    parm = tmp_path / "mount.parm"
    parm.write_text(MOUNT_PARAMS)
    d = sitl.ARDUCOPTER.parent
    home = sitl.FARM_HOME
    speedup = sitl.SPEEDUP["ardupilot"]
    return (f"cd {shlex.quote(str(tmp_path))} && ( {shlex.quote(str(sitl.ARDUCOPTER))} --model + --speedup {speedup:g} "
            f"-I0 -w "
            f"--defaults {shlex.quote(str(d / 'copter.parm'))},{shlex.quote(str(parm))} "
            f"--home {home['lat']},{home['lon']},{home['alt']},0 --serial0 udpclient:127.0.0.1:14550 "
            f"> {shlex.quote(str(tmp_path / 'fw.log'))} 2>&1 & ) ; true")


def test_the_firmware_points_its_mount_where_the_gimbal_manager_says(tmp_path):
    firmware = _firmware(tmp_path)
    probe = f"{shlex.quote(sys.executable)} tests/firmware/sitl_gimbal_probe.py udpin:127.0.0.1:14550"
    sitl.run_in_namespace("ardupilot", tmp_path, [firmware, probe], with_firmware=False, timeout_s=600)
    rc, out = sitl.step_result(tmp_path, 1)
    assert rc == 0, out[-3000:]
    r = json.loads(out.strip().splitlines()[-1])
    lim = r["vehicle_limits"]  # ArduPilot's MNT1_PITCH_MIN/MAX, MNT1_YAW_MIN/MAX defaults, as the firmware says
    assert lim is not None and lim["pitch_min_deg"] == pytest.approx(-90, abs=0.1) and \
        lim["pitch_max_deg"] == pytest.approx(20, abs=0.1), r
    rep = r["pitchyaw"]["reported"]
    assert rep and not rep["earth"], r  # a servo mount's yaw follows the vehicle
    assert rep["pitch_deg"] == pytest.approx(-45, abs=1.0) and rep["yaw_deg"] == pytest.approx(30, abs=1.0), r
    # beyond the limits: refused by our check, nothing sent
    assert "pitch_deg -100.0 is outside" in r["beyond_limit"] and r["sent_after_refusal"] == 0, r
    pred, rep = r["roi"]["predicted"], r["roi"]["reported"]
    assert rep and pred[0] < -20, r  # 25 m below at 50 m: about -26.6 degrees
    assert rep["pitch_deg"] == pytest.approx(pred[0], abs=2.0) and \
        abs((rep["yaw_deg"] - pred[1] + 180) % 360 - 180) < 2.0, r
    assert r["commands_sent"] == [1000, 195, 197], r


def test_our_mavlink_backend_points_the_firmware_mount(tmp_path):
    """The MAVLink backend a drone actor holds (robot ``gimbal`` section; ``gimbal.point``, ``gimbal.drain``), not
    the probe's bare manager: the firmware's own GIMBAL_DEVICE_ATTITUDE_STATUS shows the angle asked for, then the
    angles to a region of interest given in ENU metres (converted by the backend to a COMMAND_INT location)."""
    firmware = _firmware(tmp_path)
    home = sitl.FARM_HOME
    probe = (f"{shlex.quote(sys.executable)} tests/firmware/sitl_gimbal_backend_probe.py udpin:127.0.0.1:14550 "
             f"{home['lat']} {home['lon']} {home['alt']}")
    sitl.run_in_namespace("ardupilot", tmp_path, [firmware, probe], with_firmware=False, timeout_s=600)
    rc, out = sitl.step_result(tmp_path, 1)
    assert rc == 0, out[-3000:]
    r = json.loads(out.strip().splitlines()[-1])
    rep = r["pitchyaw"]
    assert rep and not rep["earth"], r
    assert rep["pitch_deg"] == pytest.approx(-45, abs=1.0) and rep["yaw_deg"] == pytest.approx(30, abs=1.0), r
    pred, rep = r["roi"]["predicted"], r["roi"]["reported"]
    assert rep and pred[0] < -20, r
    assert rep["pitch_deg"] == pytest.approx(pred[0], abs=2.0) and \
        abs((rep["yaw_deg"] - pred[1] + 180) % 360 - 180) < 2.0, r
    assert r["reports"] > 0 and r["sources"] == ["mavlink"], r
