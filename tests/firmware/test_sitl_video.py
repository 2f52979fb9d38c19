"""apps/vehicle_tracking.py, unchanged, on real ArduCopter SITL firmware with its camera from a video stream:
from GStreamer's RTSP server (gst-rtsp-server) and from raw RTP H.264 on UDP 5600 as QGroundControl
receives it, both fed with real aerial footage by a sender in the same private loopback-only network namespace as
the firmware. The firmware flies in real time (speed-up 1: a stream runs on the wall clock, as on a real drone; it
boots at 10x until its pre-arm checks pass) with its default parameters plus what our backend sets, and the
stream tests' quick limits (``tests/video/video_rig.py`` ``QUICK_LIMITS``).

Judged from the recording: the detector's detections of the footage's cars, the follow analytics' navigation
commands, the firmware's own odometry after them (the vehicle flew), every frame taken from the stream recorded or
counted, and each frame's pose tag at its capture time."""
from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import pytest

from aerodaas.recording.metrics import load_run
from tests.firmware import sitl
from tests.conftest import REPO, needs_data, skip_or_fail
from tests.video.video_rig import QUICK_LIMITS, check_stream_recording, make_footage

pytestmark = [pytest.mark.sitl, pytest.mark.timeout(1800)]

APP = REPO / "apps" / "vehicle_tracking.py"
ROBOT = "quadrotor_base"


@pytest.fixture(scope="module", autouse=True)
def _namespaces():
    """No private network namespace or firmware: skipped, failed in CI (which provides both)."""
    reason = sitl.namespace_skip_reason()
    if reason is not None:
        skip_or_fail(reason)


def _flight(tmp: Path, scheme: str) -> tuple[int | None, str, Path]:
    """One fresh ArduCopter, one sender, one ``aerodaas run`` of the app; returns (exit code, output, recording)."""
    footage = make_footage(tmp / "pan.mp4", seconds=8.0, empty_s=22.0)  # cars, then none: the follow ends
    py = shlex.quote(sys.executable)
    rig = shlex.quote(str(REPO / "tests" / "video" / "video_rig.py"))
    if scheme == "rtsp":
        url = "rtsp://127.0.0.1:8554/cam"  # a companion computer's RTSP server (gst-rtsp-server's usual port)
        sender = f"{py} {rig} rtsp {shlex.quote(str(footage))} 8554 5004"
    else:
        url = "rtp://127.0.0.1:5600"  # QGroundControl's port, no SDP from the sender
        sender = f"{py} {rig} {shlex.quote(str(footage))} {url}"
    cfg = sitl.mavlink_env("ardupilot", REPO / "apps" / "vehicle_tracking.json")
    robot = cfg["robots"][0]
    app_robot = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())["robots"][0]
    # the app's limits, at the stream tests' pace (not the farm survey's SITL speed): the stream is under test
    robot["limits"] = {**app_robot["limits"], **QUICK_LIMITS}
    robot["home"] = dict(sitl.FARM_HOME)  # where the firmware boots
    robot["sensors"][0]["properties"]["source"] = url
    cfg["simulation"] = {"speedup": 1, "lockstep": False, "physics_hz": 50}
    env = tmp / "vehicle_tracking_stream.json"
    env.write_text(json.dumps(cfg))
    rec = tmp / "run.mcap"
    # booted at 10x until its pre-arm checks pass (GPS, EKF), then real time before the app connects
    real_time = (f"{py} -m tests.firmware.sitl_watchers real-time-when-ready "
                 f"{sitl.monitor_connection('ardupilot')} 1 120")
    step = (f"( {sender} > {shlex.quote(str(tmp / 'sender.log'))} 2>&1 & ) ; "
            + sitl.aerodaas_run(APP, env, rec, timeout_s=500))
    sitl.run_in_namespace("ardupilot", tmp / "ns", [real_time, step], speedup=10.0, timeout_s=900)
    rc, text = sitl.step_result(tmp / "ns", 0)
    assert rc == 0, text[-2000:]
    rc, out = sitl.step_result(tmp / "ns", 1)
    return rc, out, rec


@needs_data
@pytest.mark.parametrize("scheme", ["rtsp", "rtp"])
def test_vehicle_tracking_flies_on_arducopter_with_its_camera_from_a_stream(tmp_path, data_env, scheme):
    rc, out, rec = _flight(tmp_path, scheme)
    sender_log = (tmp_path / "sender.log").read_text(errors="replace") if (tmp_path / "sender.log").exists() else ""
    assert rc == 0, out[-3000:] + "\n--- sender:\n" + sender_log[-2000:]
    run = load_run(str(rec))
    detections = [(t, boxes) for t, boxes in run["detections"] if boxes]
    assert len(detections) >= 5, len(detections)  # cars in the real footage, seen through the stream
    got = check_stream_recording(rec, ROBOT)  # every frame accounted for, every pose tag at its capture time
    follow, odometry, stats = got["follow"], got["odometry"], got["stats"]
    assert follow, "the follow analytics never commanded the vehicle from the stream's detections"
    # the firmware's own odometry: the vehicle flew (took off to the app's 16 m) and was still reporting after the
    # first follow command
    assert odometry and max(m["position"][2] for _, m in odometry) > 10.0
    assert any(t > follow[0] for t, _ in odometry)
    assert 0.0 < stats["latency_ms_median"] <= stats["latency_ms_p99"], stats  # glass to analytics, measured
