"""End-to-end missions on Ray actors in the embedded simulator (one shared Ray session)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aerodaas.recording.metrics import load_run, tracking_metrics, waypoint_visits
from aerodaas.recording.reader import read_messages, summarize_mcap
from aerodaas.runtime.driver import run_file

from tests.conftest import REPO, needs_data
from tests.recording.mcap_validation import validate_recording
from tests.runtime.app_variant import variant_env

APPS = REPO / "apps"
pytestmark = pytest.mark.e2e


def run_app(name: str, opts, **kw):
    for k, v in kw.items():
        setattr(opts, k, v)
    t0 = time.monotonic()
    res = run_file(str(APPS / name), opts)[-1]
    print(f"{name}: wall {time.monotonic() - t0:.1f} s")
    return res


def test_farm_survey_visits_all_waypoints_and_records_foxglove_schemas(ray_session, run_options, tmp_path):
    rec = tmp_path / "farm.mcap"
    res = run_app("farm_survey.py", run_options, record=str(rec), speedup=20.0)
    assert res.outcome == "success", res.robots
    rep = res.robots["quadrotor_base"]
    assert [v["id"] for v in rep["visited_waypoints"]] == ["wp1", "wp2", "wp3", "wp4"]
    assert rep["state"] == "LANDED"
    run = load_run(str(rec))
    visits = waypoint_visits(run["odometry"], [(0, 0, 1.5), (0, 10, 1.5), (10, 10, 1.5), (10, 0, 1.5)], 0.5)
    for v in visits:
        assert v["closest_m"] <= 0.5 and v["time_within_s"] >= 5.0, v
    # visited in the scheduled order
    firsts = [v["first_within_t"] for v in visits]
    assert firsts == sorted(firsts)
    assert run["odometry"][-1]["position"][2] == pytest.approx(0.0, abs=0.05)
    s = summarize_mcap(rec)
    schemas = {c["schema"] for c in s["channels"]}
    assert {"foxglove.CompressedImage", "foxglove.LocationFix", "foxglove.PoseInFrame", "foxglove.FrameTransform"} <= schemas
    counts = {c["schema"]: c["count"] for c in s["channels"]}
    assert counts["foxglove.CompressedImage"] > 10 and counts["foxglove.PoseInFrame"] > 100
    assert s["finished"] and s["mission"]["outcome"] == "success" and s["mission"]["final_state"] == "LANDED"
    states = [m["state"] for m in run["states"]]
    assert states[:4] == ["PREFLIGHT", "ARMED", "TAKING_OFF", "HOVERING"] and states[-2:] == ["LANDING", "LANDED"]


@needs_data
def test_vehicle_tracking_detects_follows_and_resumes_the_survey(ray_session, run_options, data_env, tmp_path):
    rec = tmp_path / "vt.mcap"
    # the camera at 5 fps, not the app's 10: every metric below is per frame or in vehicle seconds (lock-step: each
    # frame is detected before the clock moves on), and the follow's speed fit needs 3 fixes in its 1 s window
    env = variant_env("vehicle_tracking", tmp_path, camera={"cam1": {"fps": 5}})
    res = run_app("vehicle_tracking.py", run_options, record=str(rec), env_path=str(env))
    assert res.outcome == "success", res.robots
    rep = res.robots["quadrotor_base"]
    assert [v["id"] for v in rep["visited_waypoints"]] == ["wp1", "wp2", "wp3"]
    run = load_run(str(rec))
    m = tracking_metrics(run, "car1")
    print("tracking metrics:", m, "latency:", res.latency)
    assert m["detection_rate"] >= 0.80, m
    assert m["switch_delay_s"] is not None and m["switch_delay_s"] <= 2.0, m
    assert m["time_within_5m_s"] >= 20.0, m
    # the followed track is the moving car, not one of the parked cars the aerial model also finds: the
    # drone stays over the driving car (ground truth from the recording), whose path runs 30 m past the car park
    assert m["tracking_error_m"]["median"] <= 2.0, m
    # the survey resumed after the car left: a waypoint was completed after tracking ended
    done = [e["t"] for e in run["events"] if e["event"] == "waypoint_done"]
    assert m["tracking_ended_t"] is not None and max(done) > m["tracking_ended_t"]
    assert res.latency["quadrotor_base"]["frames"] > 50
    # the recording opens fully populated in Foxglove: validated with the mcap reader, every message decoded, JSON
    # checked against its channel's JSON Schema, transform tree and camera calibration (tests/recording/mcap_validation.py)
    cfg = json.loads(env.read_text())["robots"][0]
    cams = {s["id"]: s["properties"] for s in cfg["sensors"] if s["type"] == "camera"}
    checked = validate_recording(rec, "quadrotor_base", cams)
    c = checked["counts"]
    assert c["/quadrotor_base/detector/detections"] > 50 and c["/quadrotor_base/follow/navigation"] > 0
    assert c["/quadrotor_base/camera/cam1/calibration"] == c["/quadrotor_base/camera/cam1"]
    # the follow tracks: its geo-located tracks are recorded, the car's among them
    assert c["/quadrotor_base/follow/tracks/scene"] > 20 and c["/quadrotor_base/follow/tracks"] > 20, c
    # one LocationFixes topic for all of them, a message per scene, the track ids in its fixes
    assert c["/quadrotor_base/follow/tracks/fixes"] == c["/quadrotor_base/follow/tracks/scene"], c
    assert not [t for t in c if t.endswith("/fix")], c
    assert checked["track_ids"]["/quadrotor_base/follow/tracks/fixes"], checked["track_ids"]


def test_missing_model_is_rejected_before_any_actor_starts(ray_session, run_options, monkeypatch, tmp_path):
    from aerodaas import Environment, ObjectDetector
    from aerodaas.runtime import driver
    from aerodaas.perception.model_files import ModelNotFoundError

    started = []

    def no_actors(*a, **kw):
        started.append("actors")
        raise AssertionError("the run's actors started although the model is missing")

    monkeypatch.setattr(driver, "start_actors", no_actors)  # every actor of a run is started there

    monkeypatch.setenv("AERODAAS_MODEL_DIR", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr("urllib.request.urlopen", lambda *a, **k: (_ for _ in ()).throw(OSError("offline")))
    env = Environment(str(APPS / "farm_survey.json"))
    drone = env.get_robot_by_id("quadrotor_base")
    ObjectDetector().analyse(drone.get_sensor_by_id("cam1").get_data_stream())
    run_options.record = str(tmp_path / "never.mcap")
    with pytest.raises(ModelNotFoundError, match="AERODAAS_MODEL_DIR"):
        drone.start_mission(options=run_options)
    assert started == [] and not (tmp_path / "never.mcap").exists()


def test_unknown_robot_id_names_the_id():
    from aerodaas import Environment

    env = Environment(str(APPS / "farm_survey.json"))
    with pytest.raises(KeyError, match="'drone9'.*quadrotor_base"):
        env.get_robot_by_id("drone9")


def _default_sigint() -> None:
    # a suite started in the background (`cmd &` in a non-interactive shell) inherits SIGINT ignored, and Python
    # keeps it ignored: give the child the default disposition, as a terminal's Ctrl-C would find it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("sig, code, group", [(signal.SIGINT, 130, True), (signal.SIGTERM, 143, False)],
                         ids=["ctrl-c", "sigterm"])
def test_interrupt_leaves_a_finished_recording(tmp_path, sig, code, group):
    """Ctrl-C (SIGINT to the terminal's process group) and `kill` / `docker stop` (SIGTERM to the driver only) both
    end the mission cleanly: outcome ``interrupted``, exit code 128 + signal, the MCAP finished."""
    rec = tmp_path / "int.mcap"
    # real time (86 s of mission): a slow machine must not finish the mission before the interrupt
    proc = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "run", str(APPS / "farm_survey.py"), "--record",
                             str(rec), "--speedup", "1", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True, preexec_fn=_default_sigint)
    # wait until the recording has started receiving data
    t0 = time.monotonic()
    sizes = []
    while time.monotonic() < t0 + 90 and (not rec.exists() or rec.stat().st_size < 20000):
        sizes.append((round(time.monotonic() - t0, 1), rec.stat().st_size if rec.exists() else None))
        time.sleep(0.5)
    assert proc.poll() is None, f"the run ended before the interrupt; recording sizes (s, bytes): {sizes[-6:]}"
    if group:
        os.killpg(proc.pid, sig)
    else:
        os.kill(proc.pid, sig)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == code, out
    s = summarize_mcap(rec)
    assert s["finished"], out
    assert s["mission"]["outcome"] == "interrupted"
    # the flight up to the stop is in the file (how much of it depends on the machine's load: camera frames alone
    # may fill the 20 kB the test waits for, and a stop during the actors' start ends the mission at once)
    assert sum(1 for _ in read_messages(rec, ["/quadrotor_base/pose"])) >= 1
