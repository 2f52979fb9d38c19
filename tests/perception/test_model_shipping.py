"""The driver resolves a detector's model once and ships its bytes with the analytics (aerodaas.perception.model_files.ShippedModel):
a node without the file (a cloud node: other disk, no model folder, no internet) writes the bytes to its own cache
and loads them; the driver's own node keeps loading the file it resolved."""
from __future__ import annotations

import hashlib
import pickle
import shutil

import numpy as np
import pytest

from aerodaas.analytics.core import ObjectDetector
from aerodaas.perception.model_files import MODELS, ModelNotFoundError, ShippedModel
from tests.conftest import MODEL_DIR, needs_path

needs_model = needs_path(MODEL_DIR / "yolox_nano.onnx", reason="the shipped detector model (set AERODAAS_MODEL_DIR)")


@pytest.fixture
def other_node(tmp_path, monkeypatch):
    """This process as a node that has neither the model folder nor a cached model: its own cache folder, no
    AERODAAS_MODEL_DIR, and no download possible."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "node-cache"))
    monkeypatch.delenv("AERODAAS_MODEL_DIR", raising=False)

    def no_download(*a, **k):
        raise AssertionError("the node tried to download the model")

    monkeypatch.setattr("aerodaas.perception.model_files._download", no_download)
    return tmp_path / "node-cache" / "aerodaas" / "models" / "shipped"


def test_shipped_bytes_land_once_in_the_node_cache(tmp_path, other_node):
    src = tmp_path / "m.onnx"
    src.write_bytes(b"model-bytes" * 1000)
    shipped = pickle.loads(pickle.dumps(ShippedModel.read(src)))
    assert shipped.sha256 == hashlib.sha256(src.read_bytes()).hexdigest() and "bytes" in repr(shipped)
    assert shipped.path_on_this_node(src) == src  # the file is here with the same bytes: used as is
    src.unlink()  # another node: the driver's path does not exist there
    p = shipped.path_on_this_node(src)
    assert p.parent == other_node and p.read_bytes() == b"model-bytes" * 1000
    mtime = p.stat().st_mtime_ns
    assert shipped.path_on_this_node(src) == p and p.stat().st_mtime_ns == mtime  # written once
    src.write_bytes(b"another model at the same path")  # same path, other bytes: never loaded
    assert shipped.path_on_this_node(src) == p
    assert [f.name for f in other_node.iterdir()] == [p.name]  # no temp file left behind


def test_reading_a_missing_model_names_it(tmp_path):
    with pytest.raises(ModelNotFoundError, match="nope.onnx"):
        ShippedModel.read(tmp_path / "nope.onnx")


@needs_model
def test_object_detector_runs_where_the_model_file_is_absent(tmp_path, monkeypatch, other_node):
    """check() on the driver, pickled as Ray ships an actor's arguments, set up on a node without the file."""
    driver_copy = tmp_path / "driver" / "yolox_nano.onnx"
    driver_copy.parent.mkdir()
    shutil.copy(MODEL_DIR / "yolox_nano.onnx", driver_copy)
    det = ObjectDetector("yolox_nano", model_path=str(driver_copy))
    det.check()
    assert det.shipped.sha256 == MODELS["yolox_nano"].sha256
    local = pickle.loads(pickle.dumps(det))
    local.setup()  # the driver's node: its own file, no copy written
    assert str(local.detector.model_path) == str(driver_copy) and not other_node.exists()
    wire = pickle.dumps(det)
    driver_copy.unlink()
    remote = pickle.loads(wire)
    remote.setup()
    assert remote.detector.model_path.parent == other_node
    assert remote.process(np.zeros((480, 640, 3), np.uint8), None) == []



@needs_model
def test_the_actor_builds_the_checked_format_without_opening_the_model_twice(monkeypatch):
    """check() on the driver reads the model's format from its graph; the actor's setup (pickled as Ray ships it)
    builds that decoder without inspecting the model again, and detects what a detector whose setup inspected the
    model detects, on a window of a real aerial photo with parked cars."""
    import cv2

    import aerodaas.perception.options as options
    from tests.conftest import DATA_DIR, skip_or_fail

    im = cv2.imread(str(DATA_DIR / "imagery" / "brighton_beach" / "DJI_0028.JPG"))
    if im is None:
        skip_or_fail("shared imagery not available (set AERODAAS_DATA_DIR)")
    frame = np.ascontiguousarray(im[0:480, 3200:3840])
    opened: list = []
    real = options.inspect_model
    monkeypatch.setattr(options, "inspect_model", lambda *a, **k: opened.append(a[0]) or real(*a, **k))
    det = ObjectDetector("yolox_nano", score_threshold=0.1)
    det.check()
    assert det.checked_format == "yolox" and len(opened) == 1  # the driver's reading
    opened.clear()
    inspected = pickle.loads(pickle.dumps(det))
    inspected.checked_format = None  # an actor without the driver's reading inspects the model itself
    inspected.setup()
    assert len(opened) == 1
    actor = pickle.loads(pickle.dumps(det))
    actor.setup()
    assert len(opened) == 1  # not opened a second time
    assert type(actor.detector) is type(inspected.detector)
    expected = inspected.process(frame, None)
    assert expected and actor.process(frame, None) == expected


def test_a_checked_format_that_is_no_decoder_is_refused(tmp_path):
    from aerodaas.perception.options import build_detector

    with pytest.raises(ValueError, match="checked_format.*'yolo9'"):
        build_detector(model_path=tmp_path / "m.onnx", checked_format="yolo9")
