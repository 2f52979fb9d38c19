"""``aerodaas label serve`` speaks Label Studio's ML backend protocol (``label_studio/ml/api_connector.py``) with the
shipped aerial detector: health, setup, one prediction per task in the project's classes and control names, a task
whose image it cannot have named with HTTP 400; it binds loopback only unless told otherwise. The round trip with
a real Label Studio is in ``test_label_studio_round_trip.py``."""
from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request

import pytest

from aerodaas.cli import main
from aerodaas.labelling.ml_backend import DetectorBackend, make_server
from aerodaas.labelling.push import label_config
from aerodaas.training.label_studio_export import tasks_to_boxes
from tests.labelling.frames_folder import FRAME_NAMES, write_frames_folder


@pytest.fixture(scope="module")
def backend(tmp_path_factory):
    """The backend on a free loopback port, its document root holding a frames folder: (url, root)."""
    from aerodaas.perception.detect import AerialDetector

    root = tmp_path_factory.mktemp("root")
    write_frames_folder(root / "frames")
    srv = make_server(DetectorBackend(AerialDetector(score_threshold=0.3), "aerial_nano@test", root), port=0)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{srv.server_address[1]}", root
    srv.shutdown()
    srv.server_close()


def _post(url: str, doc: dict) -> tuple[int, dict]:
    req = urllib.request.Request(url, json.dumps(doc).encode(), {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def test_health_setup_and_predictions_in_the_projects_classes(backend):
    url, _ = backend
    with urllib.request.urlopen(f"{url}/health", timeout=30) as r:
        assert json.loads(r.read())["status"] == "UP"
    assert _post(f"{url}/setup", {"project": "1.0", "schema": label_config(["car"])}) == (
        200, {"model_version": "aerial_nano@test"})
    tasks = [{"id": i, "data": {"image": f"/data/local-files/?d=frames/images/{n}"}} for i, n in enumerate(FRAME_NAMES)]
    config = label_config(["car", "person"]).replace('name="label"', 'name="box"')
    code, doc = _post(f"{url}/predict", {"tasks": tasks, "label_config": config})
    assert code == 200 and len(doc["results"]) == len(tasks)
    results = [r["result"] for r in doc["results"]]
    assert {x["from_name"] for r in results for x in r} == {"box"}
    assert {x["value"]["rectanglelabels"][0] for r in results for x in r} <= {"car", "person"}
    # the boxes are what pull and training read: on the 640x512 frames, in the classes, none outside
    kept, problems = tasks_to_boxes([{"id": t["id"], "data": t["data"], "predictions": [p]}
                                     for t, p in zip(tasks, doc["results"])], ["car", "person"], "served")
    assert problems == [] and sum(len(k.boxes) for k in kept) > 0


def test_a_task_whose_image_it_cannot_have_is_named(backend):
    url, _ = backend
    code, doc = _post(f"{url}/predict", {"tasks": [{"id": 7, "data": {"image": "/data/local-files/?d=nope.jpg"}}],
                                         "label_config": label_config(["car"])})
    assert code == 400 and "task 7" in doc["error"] and "nope.jpg" in doc["error"]


def test_serve_binds_loopback_only_unless_told(capsys):
    assert main(["label", "serve", "--host", "0.0.0.0", "--port", "0"]) == 2
    assert "--host '0.0.0.0': not loopback" in capsys.readouterr().err

