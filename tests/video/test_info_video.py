"""``aerodaas info RUN.mcap`` on a recording with a stream camera ("`aerodaas info` and the summary give
the glass-to-analytics latency"): the reader's counters from ``<topic>/video_stats`` and the capture-to-hand-off
latency from the frames' ``<topic>/timing``, per stream camera; nothing about video for a run without one."""
from __future__ import annotations

import json

from aerodaas import cli
from aerodaas.recording.writer import McapRecorder

STATS = {"robot": "quad", "sensor": "cam1", "source": "rtp://0.0.0.0:5600", "kind": "rtp", "decoded": 104,
         "taken": 100, "overwritten": 3, "waiting": 1, "not_recorded": 2, "decode_errors": 5, "lost": 1,
         "restored": 1, "outage_s": 5.25, "latency_ms_median": 30.0, "latency_ms_p99": 80.0, "latency_ms_max": 90.0}


def _recording(path, *, stream: bool = True, stats: bool = True) -> None:
    """A small recording: odometry, and (``stream``) 100 frames' timing of ``/quad/camera/cam1`` whose hand-off age
    is 10, 11, ... 109 ms and decoded arrival 5 ms after capture, then (``stats``) its final video_stats."""
    with McapRecorder(path) as r:
        for i in range(100):
            t = 1.0 + 0.1 * i
            r.write_json("/quad/odometry", int(t * 1e9), {"t": t, "position": [0, 0, 16]}, schema_name="t.Odometry")
            if stream:
                r.write_json("/quad/camera/cam1/timing", int(t * 1e9) + 1, {
                    "robot": "quad", "sensor": "cam1", "seq": i, "capture_t": t, "arrival_t": t + 0.005,
                    "pose_t": t, "stream_seq": i + 1, "age_ms": 10.0 + i}, schema_name="aerodaas.FrameTiming")
        if stream and stats:
            r.write_json("/quad/camera/cam1/video_stats", int(11e9), STATS, schema_name="aerodaas.VideoStats")


def test_info_prints_each_stream_cameras_counters_and_latency(tmp_path, capsys):
    rec = tmp_path / "run.mcap"
    _recording(rec)
    assert cli.main(["info", str(rec)]) == 0
    out = capsys.readouterr().out
    video = out[out.index("video streams:"):].splitlines()
    assert video[1] == ("  /quad/camera/cam1: rtp://0.0.0.0:5600: 104 decoded, 100 taken, 3 replaced by a newer frame "
                        "before use, 2 not recorded, 5 damaged packets; 1 outage(s) (5.2 s without video, 1 restored)")
    # ages 10..109 ms: median 59.5, p99 108.01; arrival 5 ms after capture
    assert video[2] == ("    capture to hand-off 60 ms median, 108 ms p99 (100 frames); capture to decoded 5 ms median, "
                        "5 ms p99")
    assert cli.main(["info", "--json", str(rec)]) == 0
    got = json.loads(capsys.readouterr().out)["video"]
    assert got == [{"topic": "/quad/camera/cam1", "stats": STATS, "frames_timed": 100,
                    "handoff_ms": {"median": 59.5, "p99": 108.0}, "arrival_ms": {"median": 5.0, "p99": 5.0}}]


def test_info_without_a_stream_camera_says_nothing_of_video_and_without_stats_says_so(tmp_path, capsys):
    plain, cut = tmp_path / "sim.mcap", tmp_path / "cut.mcap"
    _recording(plain, stream=False)
    _recording(cut, stats=False)  # a run killed before its camera closed: timing, no video_stats
    assert cli.main(["info", str(plain)]) == 0
    assert "video" not in capsys.readouterr().out
    assert cli.main(["info", str(cut)]) == 0
    out = capsys.readouterr().out
    assert "/quad/camera/cam1: no video_stats (the run did not end cleanly)" in out
    assert "capture to hand-off 60 ms median, 108 ms p99 (100 frames)" in out
