"""apps/vehicle_tracking.py, unchanged, on real drone video served over RTSP (slow group ``video``).

The footage is ``tests/data/meva_uav/uav_parked_cars.mp4``: 7.5 s of real UAV video from the MEVA dataset (Kitware
and IARPA, CC BY 4.0; ``tests/data/meva_uav/README.md``), a near-nadir view of a building with parked cars, from a
source the shipped aerial model never trained on. GStreamer's RTSP server serves it in a loop (the rig of
``tests/video/video_rig.py``); the app runs on the embedded simulator backend with its camera pointed at the stream.

Judged from the recording: the detector's boxes on the real cars against hand-labelled boxes of three frames
(``cars.json``, IoU >= 0.3), and one ByteTrack id kept on each labelled car across most frames (the follow
analytics' recorded tracks). The cars are parked, so following is not shown by this footage (a moving car from the same
source, with its own hovering pose, is in tests/perception/test_follow_moving.py). The follow commands of the run are
not asserted: the stream does not move with the simulated drone, so a parked car's geo-located fixes move with the
drone and the follow adopts it (``docs/results/tracking.md``, "Real footage over RTSP"); their count is printed."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from aerodaas.recording.reader import read_messages
from tests.conftest import REPO, needs_data
from tests.video.video_rig import RtspServer, check_stream_recording

APP = REPO / "apps" / "vehicle_tracking.py"
FOOTAGE = REPO / "tests" / "data" / "meva_uav" / "uav_parked_cars.mp4"
LABELS = REPO / "tests" / "data" / "meva_uav" / "cars.json"
ROBOT = "quadrotor_base"


def iou(a, b) -> float:
    """Intersection over union of two pixel boxes ``(x0, y0, x1, y1)``; 0 for disjoint or empty boxes."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def labelled_cars() -> dict[str, list[list[float]]]:
    """Each hand-labelled car's boxes on the labelled frames of the clip (``cars.json``): name -> [box, ...]."""
    frames = json.loads(LABELS.read_text())["frames"]
    out: dict[str, list[list[float]]] = {}
    for boxes in frames.values():
        for name, box in boxes.items():
            out.setdefault(name, []).append(box)
    return out


def boxes_of(annotations) -> list[tuple[tuple[float, float, float, float], dict[str, str]]]:
    """The boxes of a ``foxglove.ImageAnnotations`` message with each one's metadata (``track_id``, ...)."""
    out = []
    for p in annotations.points:
        xs, ys = [q.x for q in p.points], [q.y for q in p.points]
        if xs:
            out.append(((min(xs), min(ys), max(xs), max(ys)), {kv.key: kv.value for kv in p.metadata}))
    return out


def read_run(rec) -> dict:
    """The app's detections and the follow analytics' tracks per analysed frame, from the recording ``rec``:
    ``{"detections": [[box, ...] per frame], "tracks": [{track_id: box} per frame], "follow": [log time, ...]}``."""
    out = {"detections": [], "tracks": [], "follow": []}
    for topic, schema, t, msg in read_messages(str(rec)):
        if topic == f"/{ROBOT}/detector/detections" and schema == "foxglove.ImageAnnotations":
            out["detections"].append([b for b, _ in boxes_of(msg)])
        elif topic == f"/{ROBOT}/follow/tracks" and schema == "foxglove.ImageAnnotations":
            out["tracks"].append({int(m["track_id"]): b for b, m in boxes_of(msg)})
        elif topic == f"/{ROBOT}/follow/navigation":
            out["follow"].append(t)
    return out


def car_recall(frames: list[list], cars: dict[str, list[list[float]]]) -> dict[str, float]:
    """Per labelled car, the share of ``frames`` (each a list of boxes) with a box of IoU >= 0.3 against one of
    its labelled boxes (the camera drifts by a few pixels over the clip: any of its three labels counts)."""
    return {name: sum(any(iou(b, lab) >= 0.3 for b in boxes for lab in labs) for boxes in frames) / len(frames)
            for name, labs in cars.items()}


def kept_ids(tracks: list[dict[int, tuple]], cars: dict[str, list[list[float]]]) -> dict[str, tuple[int, float]]:
    """Per labelled car, its most frequent track id (over frames where a track box has IoU >= 0.3 with one of its
    labels) and the share of all ``tracks`` frames on which that one id sits on the car."""
    out = {}
    for name, labs in cars.items():
        counts: dict[int, int] = {}
        for frame in tracks:
            for tid, box in frame.items():
                if any(iou(box, lab) >= 0.3 for lab in labs):
                    counts[tid] = counts.get(tid, 0) + 1
        tid = max(counts, key=counts.get) if counts else -1
        out[name] = (tid, counts.get(tid, 0) / len(tracks))
    return out


def _stop_after(proc: subprocess.Popen, rec, frames: int, deadline_s: float = 600.0) -> None:
    """SIGTERM the run ``proc`` (a clean stop: its recording is finished) once its recording ``rec`` holds
    ``frames`` analysed frames (detections messages; an unfinished MCAP is read up to its last complete chunk)."""
    end = time.monotonic() + deadline_s
    topic = f"/{ROBOT}/detector/detections"
    while proc.poll() is None:
        assert time.monotonic() < end, f"fewer than {frames} analysed frames in {deadline_s:.0f} s"
        time.sleep(10.0)  # a poll period, not a bound on anything
        try:
            n = sum(1 for _ in read_messages(str(rec), [topic])) if rec.is_file() else 0
        except ValueError:  # no complete chunk yet
            n = 0
        if n >= frames:
            proc.send_signal(signal.SIGTERM)
            return


@pytest.mark.video
@needs_data
def test_vehicle_tracking_on_real_uav_footage_over_rtsp(tmp_path, monkeypatch):
    """The run is stopped (SIGTERM, exit 143) after 120 analysed frames rather than flown to its end: its follow
    is not judged here (module docstring), and a follow that has adopted a parked car would not end by itself."""
    server = RtspServer(FOOTAGE)
    env = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())
    env["robots"][0]["sensors"][0]["properties"]["source"] = server.url
    env["simulation"] = {"speedup": 1, "lockstep": False, "physics_hz": 50}  # a stream runs on the wall clock
    env_path = tmp_path / "vehicle_tracking_footage.json"
    env_path.write_text(json.dumps(env))
    rec, log = tmp_path / "run.mcap", tmp_path / "run.log"
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path / "state"))
    server.start()
    try:
        with open(log, "w") as out_file:
            proc = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "run", str(APP), "--env", str(env_path),
                                     "--record", str(rec), "--timeout", "600", "--quiet"],
                                    stdout=out_file, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
            try:
                _stop_after(proc, rec, frames=120)
                proc.wait(timeout=300)
            finally:
                if proc.poll() is None:
                    proc.kill()
    finally:
        server.stop_all()
    out = log.read_text(errors="replace")
    print(out[-3000:])
    assert proc.returncode == 143, out[-3000:]  # stopped by our SIGTERM, cleanly (not a crash, not a timeout)
    run = read_run(rec)
    cars = labelled_cars()
    frames, tracks = run["detections"], run["tracks"]
    assert len(frames) >= 120 and len(tracks) == len(frames), (len(frames), len(tracks))
    recall = car_recall(frames, cars)
    ids = kept_ids(tracks, cars)
    print(f"frames {len(frames)}, boxes/frame {sum(map(len, frames)) / len(frames):.1f}, recall {recall}, "
          f"track ids {ids}, follow commands {len(run['follow'])}")
    # the real cars are found on the real frames: each labelled car on at least 80 % of the analysed frames
    # (measured offline on the clip's 75 frames: 99-100 %; the COCO YOLOX-Nano finds none of them)
    assert min(recall.values()) >= 0.8, recall
    # and each keeps one ByteTrack id across most frames (the stream loops every 7.5 s: the jump back is a few px)
    assert len({tid for tid, _ in ids.values()}) == len(cars), ids  # five cars, five ids
    assert min(share for _, share in ids.values()) >= 0.7, ids
    check_stream_recording(rec, ROBOT)  # every frame taken from the stream recorded or counted
