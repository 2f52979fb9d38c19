"""Every detector and tiling setting is checked before Ray starts, the way a user meets it: an app
file with a bad value, ``aerodaas plan`` / ``aerodaas run`` (in-process, one real subprocess), exit 2, a message
naming the field and the value, and no Ray session created (a fresh ``RAY_TMPDIR`` stays empty, no Ray process
names it). Values that need no model file fail where the app writes them (``Tiling(tile=16)``, a threshold of 15);
the model's own class names and a missing model file fail in the pre-flight (``ObjectDetector.check``)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from aerodaas.analytics.detector import ObjectDetector
from aerodaas.perception.tiling import Tiling
from aerodaas.perception.tracking import ByteTrackConfig

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import needs_data_case
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

APP = """from aerodaas import *
from aerodaas.perception.tiling import Tiling
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
detector = ObjectDetector({args})
detector.deploy(env.get_compute_resource_by_id("edge"))
detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
drone.start_mission()
"""

#: (ObjectDetector arguments in the app, what stderr must name): each a field and its value
CASES = [
    ('"yolox_nano", tiling=Tiling(tile=16)', "tiling.tile must be an integer number of pixels within [32, 8192], got 16"),
    ('"yolox_nano", tiling=Tiling(overlap=1.0)', "tiling.overlap must be a fraction within [0, 0.9), got 1.0"),
    ('"yolox_nano", score_threshold=15', "analytics 'detector': score_threshold must be a number within [0, 1]"),
    ('"yolox_nano", class_thresholds={"car": -0.5}', "class_thresholds['car'] must be a number within [0, 1]"),
    ('"yolox_nano", model_path="no_such_model.onnx"', "analytics 'detector': model_path='no_such_model.onnx' is not a file"),
    ('"yolox_nano", threads=-1', "analytics 'detector': threads must be an integer >= 0"),
    ('"yolox_nano", input_size=(100, 100)', "input_size must be (H, W) with each a multiple of 32"),
    ('"yolox_nano", tracker=ByteTrackConfig(high_threshold=5)', "tracker.high_threshold must be within [0, 1], got 5"),
]
#: needs the shipped model's class names (the pre-flight resolves the model file)
NEEDS_MODEL = [('"yolox_nano", classes=["Car"]', "classes: unknown class name(s) ['Car'] ('Car' -> did you mean 'car'?")]


def _app(tmp_path, args: str):
    env = tmp_path / "env.json"
    env.write_text(json.dumps({"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera"}]}],
                               "compute": [{"id": "edge", "tier": "edge"}]}))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env), args=args))
    return app


def _cli(tmp_path, command: str, app, own_process: bool = False):
    """``aerodaas COMMAND APP`` with a new empty RAY_TMPDIR: (result, that folder); in this process
    (:func:`tests.inputs.cli_inprocess.run_cli`, which fails the test if Ray is started), or with ``own_process`` as the
    real command in a subprocess."""
    ray_tmp = fresh_ray_tmp(tmp_path)
    args = [command, str(app)] + (["--quiet"] if command == "run" else ["--json"])
    env = {**os.environ, "RAY_TMPDIR": str(ray_tmp)}
    if not own_process:
        return run_cli(*args, cwd=tmp_path, env=env), ray_tmp
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True, cwd=tmp_path,
                       env=env, timeout=300)
    return p, ray_tmp


def _assert_refused_before_ray(p, ray_tmp, message):
    assert p.returncode == 2, p.stdout[-1500:] + p.stderr[-1500:]
    assert message in p.stderr, p.stderr[-1500:]
    assert "Traceback" not in p.stderr
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []


@pytest.mark.parametrize("args,message", CASES + [pytest.param(*c, marks=needs_data_case) for c in NEEDS_MODEL],
                         ids=[a.split(", ", 1)[1] for a, _ in CASES + NEEDS_MODEL])
def test_plan_refuses_a_bad_detector_setting(tmp_path, args, message):
    p, ray_tmp = _cli(tmp_path, "plan", _app(tmp_path, args))
    _assert_refused_before_ray(p, ray_tmp, message)


@pytest.mark.parametrize("args,message", [CASES[0], CASES[2], CASES[4], pytest.param(*NEEDS_MODEL[0], marks=needs_data_case)],
                         ids=["tile=16", "score_threshold=15", "missing model file", "unknown class"])
def test_run_refuses_a_bad_detector_setting_before_ray(tmp_path, args, message):
    # the first case as the real command: its exit code 2 and no Ray session, from the process itself
    p, ray_tmp = _cli(tmp_path, "run", _app(tmp_path, args), own_process=args == CASES[0][0])
    _assert_refused_before_ray(p, ray_tmp, message)


def test_settings_fail_where_the_app_writes_them():
    """Not at the first frame in an actor: a Tiling or ByteTrackConfig given to one's own analytics is checked too."""
    with pytest.raises(ValueError, match=r"tiling.tile .* got 16"):
        Tiling(tile=16)
    with pytest.raises(ValueError, match=r"tiling.full_frame must be True or False, got 'no'"):
        Tiling(full_frame="no")
    with pytest.raises(ValueError, match=r"tracker.track_buffer .* got 0"):
        ByteTrackConfig(track_buffer=0)
    with pytest.raises(ValueError, match=r"analytics 'det': score_threshold .* got 30"):
        ObjectDetector(score_threshold=30, name="det")
    with pytest.raises(ValueError, match=r"model must be one of .* got model='yolo11'"):
        ObjectDetector("yolo11")
    with pytest.raises(ValueError, match=r"format must be one of .* got 'v8'"):
        ObjectDetector(format="v8")
    assert ObjectDetector(score_threshold=0.1, threads=0, tiling=Tiling(tile=800, overlap=0.1)).tiling.tile == 800


def test_a_field_changed_after_construction_is_checked_in_the_pre_flight():
    det = ObjectDetector(model_path="no_such.onnx")
    with pytest.raises(ValueError, match=r"model_path='no_such.onnx' is not a file"):
        det.check()
    t = Tiling()
    t.tile = 16
    with pytest.raises(ValueError, match=r"tiling.tile .* got 16"):
        ObjectDetector(model_path="no_such.onnx", tiling=t)
