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
from aerodaas.tools.hitl_client import request, state_file
from tests.conftest import REPO, needs_data
from tests.video.video_rig import (
    QUICK_LIMITS, RtspServer, Sender, check_stream_recording, free_udp_port, make_footage,
)

APP = REPO / "apps" / "vehicle_tracking.py"


def check_recording_replays_as_a_trace(rec, fps: float = 2.0, seed: int = 1) -> dict[str, int]:
    """A recording of a real stream as the scheduler benchmarks' trace ``--trace recording:FILE``: its
    camera-frame gaps are read — :func:`recording_frame_gaps` gives one gap list per camera topic, with as many
    gaps as the topic has frames minus one, the gaps between their log times (counted here from the MCAP file
    itself) — and :func:`frame_times` replays them at ``fps``: a drone's replayed gaps are the recorded ones, in
    order from a seeded start (looping), scaled so their mean is ``1/fps``, and each whole loop of them averages
    ``1/fps`` s. Returns the frames per camera topic."""
    from mcap.reader import make_reader

    from aerodaas.bench.traces import IMAGE_SCHEMAS, TraceSpec, frame_times, recording_frame_gaps

    stamps: dict[str, list[int]] = {}
    with open(rec, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if schema is not None and schema.name in IMAGE_SCHEMAS:
                stamps.setdefault(channel.topic, []).append(message.log_time)
    cams = sorted(t for t, ts in stamps.items() if len(ts) >= 3)
    assert cams, f"no camera topic with 3 frames in {rec}: {sorted(stamps)}"
    gaps = recording_frame_gaps(rec)
    assert [len(g) for g in gaps] == [len(stamps[t]) - 1 for t in cams], ([len(g) for g in gaps], cams)
    for g, t in zip(gaps, cams):
        ts = sorted(stamps[t])
        assert g == pytest.approx([(b - a) / 1e6 for a, b in zip(ts, ts[1:])], abs=1e-6)
    period = 1000.0 / fps
    for i, g in enumerate(gaps):                      # fleet drone i replays camera i
        n, scale = len(g), period / (sum(g) / len(g))
        want = [max(x * scale, 1e-3) for x in g]
        times = frame_times(TraceSpec.parse(f"recording:{rec}"), f"d{i}", 0, 1, i, period, (2 * n + 1) * period,
                            seed)
        got = [b - a for a, b in zip(times, times[1:])]
        assert len(got) >= 2 * n, (len(got), n)
        # the replayed gaps: the recorded ones scaled, in their order from one start (times rounded to 1 us)
        start = next((k for k in range(n) if all(abs(got[j] - want[(k + j) % n]) <= 2e-3 for j in range(n))), None)
        assert start is not None, f"{cams[i]}: the replayed gaps are not the recorded ones x {scale:g} in order"
        for loop in (got[:n], got[n:2 * n]):          # a whole loop of the recording at the requested rate
            assert sum(loop) / n == pytest.approx(period, rel=1e-3), (sum(loop) / n, period)
    return {t: len(stamps[t]) for t in cams}


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
    env["robots"][0]["limits"].update(QUICK_LIMITS)  # the stream is under test, not the flight's pace
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
    # the recording replays as a scheduler-benchmark trace (--trace recording:run.mcap): its camera's frame gaps,
    # the 5 s outage among them, at a requested mean rate
    frames = check_recording_replays_as_a_trace(rec)
    assert frames.get("/quadrotor_base/camera/cam1", 0) >= 3, frames
