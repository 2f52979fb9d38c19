"""Batched inference across drones ("where several drones feed one detector, batch their frames into one
inference call when the model allows").

* The shipped YOLOX-Nano and NanoDet-Plus exports take a fixed batch of 1: ``process_batch`` is then a loop, one
  onnxruntime call per frame, with exactly the single-frame results.
* A model whose input has a dynamic batch dimension runs the drones' frames in one call (chunked by ``batch``), with
  the same detections as frame by frame. The shipped exports cannot be given a dynamic batch (their graphs hold
  batch-1 Reshape constants), so that path is checked with small models built here with the ``onnx`` package that
  follow the same input/output contracts (random convolution weights: the detections are meaningless, but the
  pre-processing, the decoding and the batching under test are the production ones), on the same real frames.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from aerodaas.analytics.core import ObjectDetector

from tests.conftest import DATA_DIR, MODEL_DIR, needs_data

pytestmark = needs_data

VEHICLES = ["car", "truck", "bus"]
# three drones' frames (640x480 windows with parked cars) from three real nadir photos: (file, x, y)
FRAMES = [("DJI_0028.JPG", 3200, 0), ("DJI_0031.JPG", 2240, 480), ("DJI_0033.JPG", 2775, 270)]


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    out = []
    for name, x, y in FRAMES:
        im = cv2.imread(str(DATA_DIR / "imagery" / "brighton_beach" / name))
        assert im is not None, name
        out.append(np.ascontiguousarray(im[y:y + 480, x:x + 640]))
    return out


def _contract_model(path, contract: str, seed: int = 0) -> None:
    """A small ONNX model with the input/output contract of ``contract`` ("yolox_nano": ``images`` (N, 3, 416, 416)
    -> ``output`` (N, 3549, 85), sigmoid; "nanodet_plus_m_416": per stride 8/16/32 scores (N, HW, 80), sigmoid, and
    box distributions (N, HW, 32)) and a dynamic batch N: one strided convolution per stride."""
    import onnx  # the test extra (pyproject), installed by the README and CI
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    nodes, inits, outputs, cat = [], [], [], []
    c = 85 if contract == "yolox_nano" else 80 + 32
    inits.append(numpy_helper.from_array(np.array([0, c, -1], np.int64), "shape"))
    inits.append(numpy_helper.from_array(np.array([80, 32], np.int64), "split"))
    for s in (8, 16, 32):
        hw = (416 // s) ** 2
        w = rng.normal(0.0, 2.0 / (140.0 * np.sqrt(3 * s * s)), (c, 3, s, s)).astype(np.float32)
        b = np.zeros(c, np.float32)
        b[4 if contract == "yolox_nano" else 2] = 2.0  # YOLOX: objectness; NanoDet: class 2 (car)
        inits += [numpy_helper.from_array(w, f"w{s}"), numpy_helper.from_array(b, f"b{s}")]
        nodes += [helper.make_node("Conv", ["x", f"w{s}", f"b{s}"], [f"c{s}"], kernel_shape=[s, s], strides=[s, s]),
                  helper.make_node("Reshape", [f"c{s}", "shape"], [f"r{s}"]),
                  helper.make_node("Transpose", [f"r{s}"], [f"t{s}"], perm=[0, 2, 1])]
        if contract == "yolox_nano":
            cat.append(f"t{s}")
        else:
            nodes += [helper.make_node("Split", [f"t{s}", "split"], [f"l{s}", f"reg{s}"], axis=2),
                      helper.make_node("Sigmoid", [f"l{s}"], [f"cls{s}"])]
            outputs += [helper.make_tensor_value_info(f"cls{s}", TensorProto.FLOAT, ["N", hw, 80]),
                        helper.make_tensor_value_info(f"reg{s}", TensorProto.FLOAT, ["N", hw, 32])]
    name = "images" if contract == "yolox_nano" else "input.1"
    nodes.insert(0, helper.make_node("Identity", [name], ["x"]))
    if contract == "yolox_nano":
        nodes += [helper.make_node("Concat", cat, ["cat"], axis=1), helper.make_node("Sigmoid", ["cat"], ["output"])]
        outputs = [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["N", 3549, 85])]
    graph = helper.make_graph(nodes, contract, [helper.make_tensor_value_info(name, TensorProto.FLOAT,
                                                                             ["N", 3, 416, 416])], outputs, inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def _dynamic_yolox_copy(path) -> None:
    """The shipped YOLOX-Nano with a dynamic batch: input dim 0 named ``N`` and every Reshape target starting with 1
    made to start with 0 (ONNX Reshape: 0 copies that dimension of the input, here the batch)."""
    import onnx  # the test extra (pyproject), installed by the README and CI
    from onnx import numpy_helper

    m = onnx.load(str(MODEL_DIR / "yolox_nano.onnx"))
    inits = {i.name: i for i in m.graph.initializer}
    consts = {n.output[0]: n.attribute[0].t for n in m.graph.node if n.op_type == "Constant"}
    patched = 0
    for node in m.graph.node:
        if node.op_type == "Reshape":
            t = inits.get(node.input[1]) or consts[node.input[1]]
            shape = numpy_helper.to_array(t).copy()
            if shape[0] == 1:
                shape[0] = 0
                t.CopyFrom(numpy_helper.from_array(shape, t.name))
                patched += 1
    assert patched == 3  # the three detection heads' flattening
    m.graph.input[0].type.tensor_type.shape.dim[0].dim_param = "N"
    m.graph.output[0].type.tensor_type.shape.dim[0].dim_param = "N"
    del m.graph.value_info[:]
    onnx.save(m, str(path))


class _RunSpy:
    """Stands in for the onnxruntime session: records the batch size of every ``run`` call."""

    def __init__(self, session) -> None:
        self.session, self.batches = session, []

    def run(self, names, feeds):
        self.batches.append(int(next(iter(feeds.values())).shape[0]))
        return self.session.run(names, feeds)

    def __getattr__(self, k):
        return getattr(self.session, k)


REAL, CONTRACT = 0.15, 0.5  # score thresholds: real weights (as apps/vehicle_tracking.py); random-weight models


def _detector(model: str, path, threshold: float, batch: int = 8) -> tuple[ObjectDetector, _RunSpy]:
    """An ObjectDetector for vehicles on ``path``, set up, its onnxruntime session behind a :class:`_RunSpy`."""
    det = ObjectDetector(model, model_path=str(path), classes=VEHICLES, score_threshold=threshold, batch=batch)
    det.setup()
    spy = _RunSpy(det.detector.session)
    det.detector.session = spy
    return det, spy


def _same(a: list, b: list) -> None:
    """Two frames' detection lists agree (the same boxes, classes and scores, to float32 rounding)."""
    assert len(a) == len(b)
    for p, q in zip(a, b):
        assert p.class_name == q.class_name
        assert p.score == pytest.approx(q.score, abs=1e-5)
        np.testing.assert_allclose(p.box, q.box, atol=1e-3)


@pytest.mark.parametrize("model", ["yolox_nano", "nanodet_plus_m_416"])
def test_shipped_models_take_a_fixed_batch_so_process_batch_loops(model, frames):
    det, spy = _detector(model, MODEL_DIR / f"{model}.onnx", REAL)
    assert det.detector.batch_dynamic is False and det.max_batch == 1
    want = [det.process(f, None) for f in frames]
    assert sum(len(d) for d in want) >= 1  # real cars: the comparison below is not between empty lists
    spy.batches.clear()
    got = det.process_batch([(f, None) for f in frames])
    assert spy.batches == [1, 1, 1]  # one onnxruntime call per frame: the model allows no more
    for a, b in zip(got, want):
        _same(a, b)
    assert det.stats()["frames_batched"] == 0


@pytest.mark.parametrize("contract", ["yolox_nano", "nanodet_plus_m_416"])
def test_a_dynamic_batch_model_runs_the_drones_frames_in_one_call(contract, frames, tmp_path):
    path = tmp_path / f"dynamic_{contract}.onnx"
    _contract_model(path, contract)
    det, spy = _detector(contract, path, CONTRACT, batch=4)
    assert det.detector.batch_dynamic is True and det.max_batch == 4
    want = [det.process(f, None) for f in frames]
    assert all(want)  # every frame has detections to compare
    spy.batches.clear()
    got = det.process_batch([(f, None) for f in frames])
    assert spy.batches == [3]  # the three drones' frames in one inference call
    for a, b in zip(got, want):
        _same(a, b)
    st = det.stats()
    assert st["frames"] == 6 and st["frames_batched"] == 3
    assert det.last_timing["batch"] == 3.0 and det.last_timing["inference_ms"] > 0


def test_yolox_nano_with_a_dynamic_batch_finds_the_same_cars_in_one_call(frames, tmp_path):
    path = tmp_path / "yolox_nano_dynamic.onnx"
    _dynamic_yolox_copy(path)
    det, spy = _detector("yolox_nano", path, REAL)
    assert det.max_batch == 8
    shipped, _ = _detector("yolox_nano", MODEL_DIR / "yolox_nano.onnx", REAL)
    want = [shipped.process(f, None) for f in frames]
    assert sum(len(d) for d in want) >= 1 and all(d.class_name in VEHICLES for w in want for d in w)
    got = det.process_batch([(f, None) for f in frames])
    assert spy.batches == [3]
    for a, b in zip(got, want):
        _same(a, b)


def test_batches_are_chunked_to_the_detectors_batch_size(frames, tmp_path):
    path = tmp_path / "dynamic_yolox_nano.onnx"
    _contract_model(path, "yolox_nano")
    det, spy = _detector("yolox_nano", path, CONTRACT, batch=2)
    items = [(f, None) for f in frames + frames[:1]]
    want = [det.process(f, None) for f, _ in items]
    spy.batches.clear()
    got = det.process_batch(items)
    assert spy.batches == [2, 2]
    for a, b in zip(got, want):
        _same(a, b)


def test_a_bad_frame_in_a_batch_is_named_before_any_inference(frames, tmp_path):
    path = tmp_path / "dynamic_yolox_nano.onnx"
    _contract_model(path, "yolox_nano")
    det, spy = _detector("yolox_nano", path, CONTRACT)
    spy.batches.clear()
    with pytest.raises(ValueError, match=r"images\[1\]: image must have shape \(H, W, 3\)"):
        det.process_batch([(frames[0], None), (frames[1][:, :, 0], None)])
    assert spy.batches == []


def test_detector_batch_size_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="batch must be an integer >= 1"):
        ObjectDetector(batch=0)
