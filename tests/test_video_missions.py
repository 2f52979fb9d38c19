"""Missions flown on a real-time video stream (slow group ``video``): apps/vehicle_tracking.py, unchanged, with its
camera from MPEG-TS on UDP and from RTP H.264 on UDP 5600 (QGroundControl's port, no SDP from the sender), fed by a
sender process with real aerial footage. Mid-run the sender dies for 5 s. Judged from the recording: detections
and follow commands, video_lost/video_restored events, every frame taken from the stream recorded (decoded =
recorded + replaced + waiting, as counted), and each frame's pose tag at its capture time."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from aerodaas.recording.metrics import load_run
from aerodaas.tools.hitl import request, state_file
from .conftest import REPO, needs_data
from .video_rig import RtspServer, Sender, check_stream_recording, free_udp_port, make_footage

APP = REPO / "apps" / "vehicle_tracking.py"


def _wait_flying(proc, deadline_s: float = 300.0) -> None:
    """Until the drone is on its mission (the camera streams by then): polled through the HITL API."""
    end = time.monotonic() + deadline_s
    while True:
        assert proc.poll() is None, "the run ended before flying"
        assert time.monotonic() < end, "the drone never started its mission"
        if state_file().is_file():
            try:
                st, body = request("GET", "/drones/quadrotor_base")
            except (RuntimeError, OSError):
                st, body = 0, None
            if st == 200 and body.get("state") in ("NAVIGATING", "WAYPOINT_HOLD", "TRACKING"):
                return
        time.sleep(0.2)


@pytest.mark.video
@needs_data
@pytest.mark.parametrize("scheme,port", [("udp", None), ("rtp", 5600), ("rtsp", None)])
def test_vehicle_tracking_on_a_stream_survives_a_5s_outage(tmp_path, monkeypatch, scheme, port):
    """MPEG-TS on UDP, RTP H.264 on UDP 5600 (the sender dies for 5 s), and RTSP from GStreamer's gst-rtsp-server
    (the server dies for 5 s: the TCP session drops and must be opened again)."""
    footage = make_footage(tmp_path / "pan.mp4", seconds=8.0, empty_s=22.0)  # cars, then none: the follow ends
    if scheme == "rtsp":
        sender = RtspServer(footage)
        url = sender.url
    else:
        url = f"{scheme}://127.0.0.1:{port or free_udp_port()}"
        sender = Sender(footage, url)
    env = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())
    env["robots"][0]["sensors"][0]["properties"]["source"] = url
    env["simulation"] = {"speedup": 1, "lockstep": False, "physics_hz": 50}
    env_path = tmp_path / "vehicle_tracking_stream.json"
    env_path.write_text(json.dumps(env))
    rec = tmp_path / "run.mcap"
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path / "state"))
    sender.start()
    proc = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "run", str(APP), "--env", str(env_path),
                             "--record", str(rec), "--timeout", "400", "--quiet", "--hitl", "--hitl-port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
    try:
        _wait_flying(proc)
        sender.stop()
        time.sleep(5.0)  # the outage's length (not a bound on anything)
        sender.start()
        out, _ = proc.communicate(timeout=600)
    finally:
        sender.stop_all()
        if proc.poll() is None:
            proc.kill()
    print(out[-3000:])
    assert proc.returncode == 0, out[-3000:]
    run = load_run(str(rec))
    kinds = [e["event"] for e in run["events"]]
    assert "video_lost" in kinds and "video_restored" in kinds, kinds
    restored = next(e for e in run["events"] if e["event"] == "video_restored")
    assert restored["url"] == url and restored["outage_s"] >= 4.0, restored  # it was down for (at least) 5 s
    assert sum(1 for _, boxes in run["detections"] if boxes) >= 5  # cars in the real footage
    got = check_stream_recording(rec)  # every frame accounted for, every pose tag at its capture time
    assert got["follow"]  # the follow analytics commanded the drone from the stream's detections
    stats = got["stats"]
    assert stats["lost"] >= 1 and stats["restored"] >= 1, stats
