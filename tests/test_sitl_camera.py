"""Camera protocol v2 against real ArduCopter SITL firmware (slow group ``sitl``): the firmware has a camera
(``CAM1_TYPE 1``) whose video stream a Lua script announces (``tests/sitl_camera/announce_stream.lua``, as
ArduPilot's video-stream-information applet does for a Siyi or a Herelink); the MAVLink backend's discovery, as a
camera with ``source: "mavlink"`` runs it, must find the URL the firmware itself sends in VIDEO_STREAM_INFORMATION,
from the autopilot's component (ArduPilot's integrated camera: no camera component of its own)."""
from __future__ import annotations

import json
import shlex
import shutil
import sys

import pytest

from tests import sitl

pytestmark = [pytest.mark.sitl]


def test_discovery_finds_the_stream_the_firmware_announces(tmp_path):
    reason = sitl.namespace_skip_reason()
    if reason:
        pytest.fail(reason)
    (tmp_path / "scripts").mkdir()
    shutil.copy(sitl.REPO / "tests" / "sitl_camera" / "announce_stream.lua", tmp_path / "scripts")
    parm = tmp_path / "scripting.parm"
    parm.write_text("SCR_ENABLE 1\n")  # Lua scripting (off by default); CAM1_TYPE is set by the probe
    d = sitl.ARDUCOPTER.parent
    home = sitl.FARM_HOME
    firmware = (f"cd {shlex.quote(str(tmp_path))} && ( {shlex.quote(str(sitl.ARDUCOPTER))} --model + --speedup 1 -I0 "
                f"-w --defaults {shlex.quote(str(d / 'copter.parm'))},{shlex.quote(str(parm))} "
                f"--home {home['lat']},{home['lon']},{home['alt']},0 --serial0 udpclient:127.0.0.1:14550 "
                f"> {shlex.quote(str(tmp_path / 'fw.log'))} 2>&1 & ) ; true")
    probe = f"{shlex.quote(sys.executable)} tests/sitl_camera_probe.py udpin:127.0.0.1:14550 60"
    sitl.run_in_namespace("ardupilot", tmp_path, [firmware, probe], with_firmware=False, timeout_s=600)
    rc, out = sitl.step_result(tmp_path, 1)
    assert rc == 0, out[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert got["source"] == got["uri"] == "rtsp://127.0.0.1:8554/cam" and got["stream_type"] == "RTSP", got
    assert got["component"] == 1 and got["stream_id"] == 1 and got["codec"] == "h264", got  # the autopilot's own
    assert got["resolution"] == [640, 480] and got["stream_name"] == "main", got
