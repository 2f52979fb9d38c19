"""Bring-your-own-model decoding and the detector API checks.

The Ultralytics heads are checked on small ONNX graphs written here with ``onnx.helper`` whose output is a known
constant (plus ``0 x mean(input)``, so the graph does read the image and keeps the batch axis): the boxes the
detector reports must be exactly those placed in the head, mapped back through the Ultralytics letterbox. Nothing is
downloaded."""
from __future__ import annotations

import numpy as np
import pytest

from aerodaas.analytics.core import ObjectDetector
from aerodaas.perception.decoders import UltralyticsDetector, inspect_model, metadata_names
from aerodaas.perception.options import build_detector, check_detector_options

from tests.conftest import MODEL_DIR, needs_data

import onnx  # noqa: E402 - the test extra (pyproject), installed by the README and CI
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

NAMES = {0: "car", 1: "truck", 2: "person"}
A640 = 80 * 80 + 40 * 40 + 20 * 20  # 8400 anchor points at strides 8/16/32 on 640x640


def _const_model(path, head: np.ndarray, *, in_shape=(1, 3, 640, 640), out_shape=None, meta=None) -> str:
    """An ONNX model whose single output ``output0`` is ``head`` (broadcast over the batch)."""
    nodes = [helper.make_node("ReduceMean", ["images"], ["m0"], axes=[1, 2, 3], keepdims=0),
             helper.make_node("Reshape", ["m0", "shape3"], ["m"]),
             helper.make_node("Mul", ["m", "zero"], ["z"]),
             helper.make_node("Add", ["head", "z"], ["output0"])]
    inits = [numpy_helper.from_array(head.astype(np.float32), "head"),
             numpy_helper.from_array(np.zeros((1, 1, 1), np.float32), "zero"),
             numpy_helper.from_array(np.array([-1, 1, 1], np.int64), "shape3")]
    g = helper.make_graph(nodes, "const_head",
                          [helper.make_tensor_value_info("images", TensorProto.FLOAT, list(in_shape))],
                          [helper.make_tensor_value_info("output0", TensorProto.FLOAT,
                                                         list(out_shape or head.shape))], inits)
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 13)])
    m.ir_version = 8
    for k, v in (meta or {}).items():
        m.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(m)
    onnx.save(m, str(path))
    return str(path)


def _v8_head() -> np.ndarray:
    """(1, 4 + 3, 8400): a car at (320, 320) 64x32 px (score 0.9), a truck on the same spot (0.6), a person far."""
    h = np.zeros((1, 7, A640), np.float32)
    h[0, :4, 10] = [320, 320, 64, 32]
    h[0, 4, 10] = 0.9
    h[0, :4, 11] = [322, 321, 60, 30]
    h[0, 5, 11] = 0.6
    h[0, :4, 500] = [100, 200, 20, 40]
    h[0, 6, 500] = 0.7
    return h


def _v5_head() -> np.ndarray:
    """(1, 3 x 8400, 5 + 3): one car, objectness 0.8 x class 0.9."""
    h = np.zeros((1, 3 * A640, 8), np.float32)
    h[0, 7, :5] = [320, 320, 64, 32, 0.8]
    h[0, 7, 5] = 0.9
    return h


IMG = np.zeros((720, 1280, 3), np.uint8)  # letterboxed into 640x640: r = 0.5, top pad 140, left pad 0


def _img_box(cx, cy, w, h):
    """Ultralytics scale_boxes for a 1280x720 image in 640x640: (x - 0) / 0.5, (y - 140) / 0.5."""
    return ((cx - w / 2) / 0.5, (cy - h / 2 - 140) / 0.5, (cx + w / 2) / 0.5, (cy + h / 2 - 140) / 0.5)


def test_v8_head_decodes_known_boxes_with_metadata_names(tmp_path):
    path = _const_model(tmp_path / "v8.onnx", _v8_head(), meta={"names": str(NAMES), "imgsz": "[640, 640]"})
    info = inspect_model(path)
    assert (info.format, info.class_names, info.input_hw, info.n_classes) == ("ultralytics", list(NAMES.values()),
                                                                              (640, 640), 3)
    det = build_detector(model_path=path, score_threshold=0.5)
    assert isinstance(det, UltralyticsDetector)
    dets = det.detect(IMG)
    got = {d.class_name: (round(d.score, 4), tuple(round(v, 3) for v in d.box)) for d in dets}
    assert got == {"car": (0.9, _img_box(320, 320, 64, 32)), "truck": (0.6, _img_box(322, 321, 60, 30)),
                   "person": (0.7, _img_box(100, 200, 20, 40))}
    # class-agnostic NMS: the truck on the car is suppressed; a vehicle group does the same and keeps the person
    agn = build_detector(model_path=path, score_threshold=0.5, agnostic_nms=True).detect(IMG)
    assert sorted(d.class_name for d in agn) == ["car", "person"]
    grp = build_detector(model_path=path, score_threshold=0.5, class_groups={"vehicle": ["car", "truck"]}).detect(IMG)
    assert sorted(d.class_name for d in grp) == ["car", "person"]
    # per-class thresholds and a single class given as a plain string
    only = build_detector(model_path=path, score_threshold=0.5, class_thresholds={"person": 0.8}).detect(IMG)
    assert sorted(d.class_name for d in only) == ["car", "truck"]
    assert [d.class_name for d in build_detector(model_path=path, classes="truck", score_threshold=0.5).detect(IMG)] \
        == ["truck"]


def test_v5_head_objectness_times_class_and_user_names(tmp_path):
    path = _const_model(tmp_path / "v5.onnx", _v5_head())
    assert inspect_model(path).format == "ultralytics"  # 3 anchors per cell: not YOLOX
    det = build_detector(model_path=path, format="ultralytics", class_names=["auto", "lorry", "walker"],
                         score_threshold=0.5)
    (d,) = det.detect(IMG)
    assert d.class_name == "auto" and d.score == pytest.approx(0.72, abs=1e-6)
    assert d.box == pytest.approx(_img_box(320, 320, 64, 32))
    # without names in the model or from the user: class0..
    assert build_detector(model_path=path, score_threshold=0.5).detect(IMG)[0].class_name == "class0"


def test_dynamic_axes_need_input_size_and_batch_in_one_call(tmp_path):
    path = _const_model(tmp_path / "dyn.onnx", _v8_head(), in_shape=("batch", 3, "h", "w"),
                        out_shape=("batch", 7, "anchors"), meta={"names": str(NAMES)})
    with pytest.raises(ValueError, match=r"dynamic height/width; give input_size"):
        build_detector(model_path=path, format="ultralytics")
    det = build_detector(model_path=path, format="ultralytics", input_size=(640, 640), score_threshold=0.5)
    assert det.batch_dynamic and det.input_hw == (640, 640)
    out = det.detect_batch([IMG, IMG, IMG])
    assert det.last_batch == 3 and [len(o) for o in out] == [3, 3, 3]
    with pytest.raises(ValueError, match=r"input_size"):
        check_detector_options(model_path=path, input_size=(641, 640))


@needs_data
def test_auto_format_recognises_the_shipped_models():
    assert inspect_model(MODEL_DIR / "yolox_nano.onnx").format == "yolox"
    assert inspect_model(MODEL_DIR / "nanodet_plus_m_416.onnx").format == "nanodet"
    with pytest.raises(ValueError, match=r"format='nanodet' but .* yolox head"):
        inspect_model(MODEL_DIR / "yolox_nano.onnx", "nanodet")


def test_metadata_names_forms():
    assert metadata_names({"names": "{0: 'a', 1: 'b'}"}) == ["a", "b"]
    assert metadata_names({"names": "['a', 'b']"}) == ["a", "b"]
    assert metadata_names({}) is None
    with pytest.raises(ValueError, match="indices"):
        metadata_names({"names": "{0: 'a', 2: 'b'}"})


@needs_data
@pytest.mark.parametrize("kwargs, field", [
    (dict(classes=["Car"]), r"classes: unknown class name\(s\) \['Car'\] \('Car' -> did you mean 'car'"),
    (dict(score_threshold=15), r"score_threshold must be .* got 15"),
    (dict(nms_threshold=-0.1), r"nms_threshold .* got -0.1"),
    (dict(class_thresholds={"car": 30}), r"class_thresholds\['car'\] .* got 30"),
    (dict(class_groups={"vehicle": ["car", "van"]}), r"class_groups\['vehicle'\]: unknown class name\(s\) \['van'\]"),
    (dict(input_size=(320, 320)), r"input_size=\(320, 320\) but the model's input is fixed at \(416, 416\)"),
    (dict(format="yolov8"), r"format must be one of .* got 'yolov8'"),
    (dict(format="nanodet"), r"format='nanodet' but .* yolox head"),
])
def test_object_detector_check_names_field_and_value(kwargs, field):
    """ObjectDetector.check runs in the pre-flight (aerodaas.runtime.preflight.validate) on the driver, before Ray."""
    with pytest.raises(ValueError, match=r"analytics 'detector': " + field):
        ObjectDetector(**kwargs).check()


def test_object_detector_api_defects():
    assert ObjectDetector(classes="car").classes == ["car"]
    with pytest.raises(ValueError, match=r"classes=\[\] names no class"):
        ObjectDetector(classes=[])
    with pytest.raises(RuntimeError, match=r"process\(\) called before setup\(\)"):
        ObjectDetector().process(IMG, None)


@needs_data
def test_object_detector_runs_a_brought_model_end_to_end(tmp_path):
    path = _const_model(tmp_path / "v8.onnx", _v8_head(), meta={"names": str(NAMES)})
    det = ObjectDetector(model_path=path, classes="car", score_threshold=0.5)
    det.check()
    det.setup()
    (d,) = det.process(IMG, None)
    assert d.class_name == "car" and d.box == pytest.approx(_img_box(320, 320, 64, 32))


def test_object_detector_with_tiling_checks_and_runs(tmp_path):
    from aerodaas.perception.tiling import Tiling

    path = _const_model(tmp_path / "v8.onnx", _v8_head(), meta={"names": str(NAMES)})
    with pytest.raises(ValueError, match=r"tiling.overlap must be .* got 0.95"):
        ObjectDetector(model_path=path, tiling=Tiling(overlap=0.95)).check()
    det = ObjectDetector(model_path=path, classes="car", score_threshold=0.5,
                         tiling=Tiling(tile=640, overlap=0.0, full_frame=False, merge="nms"))
    det.check()
    det.setup()
    # 1280x720 -> two rows of two 640x640 slices (the second row shifted back to y=80); each slice of 640x640
    # is its own input (r = 1, no padding): the constant car lands at (288..352, 304..336) of every slice
    dets = det.process(IMG, None)
    assert det.detector.last_slices == 4
    assert sorted(d.box for d in dets) == sorted([(288.0, 304.0, 352.0, 336.0), (928.0, 304.0, 992.0, 336.0),
                                                  (288.0, 384.0, 352.0, 416.0), (928.0, 384.0, 992.0, 416.0)])
