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

from tests.firmware import sitl

pytestmark = [pytest.mark.sitl]


def test_discovery_finds_the_stream_the_firmware_announces(tmp_path):
    reason = sitl.namespace_skip_reason()
    if reason:
        pytest.fail(reason)
    (tmp_path / "scripts").mkdir()  # the firmware runs in tmp_path: its Lua scripts folder
    shutil.copy(sitl.REPO / "tests" / "sitl_camera" / "announce_stream.lua", tmp_path / "scripts")
    probe = f"{shlex.quote(sys.executable)} tests/firmware/sitl_camera_probe.py {sitl.connection('ardupilot')} 60"
    sitl.run_in_namespace("ardupilot", tmp_path, [probe], timeout_s=600)  # at sitl.SPEEDUP: no stream runs here
    rc, out = sitl.step_result(tmp_path, 0)
    assert rc == 0, out[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert got["source"] == got["uri"] == "rtsp://127.0.0.1:8554/cam" and got["stream_type"] == "RTSP", got
    assert got["component"] == 1 and got["stream_id"] == 1 and got["codec"] == "h264", got  # the autopilot's own
    assert got["resolution"] == [640, 480] and got["stream_name"] == "main", got
