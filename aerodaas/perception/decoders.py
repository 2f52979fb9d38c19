"""Decoding the Ultralytics ONNX detector exports (YOLOv5, YOLOv8, YOLO11), and recognising a model's format.

Ultralytics export contract (``ultralytics/engine/exporter.py``, ``ultralytics/nn/autobackend.py``,
``ultralytics/data/augment.py`` ``LetterBox``, ``ultralytics/utils/ops.py`` ``scale_boxes`` of the
``ultralytics/ultralytics`` repository):

* input ``images`` float32 ``(N, 3, H, W)``, **RGB**, ``/ 255`` (no mean/std);
* letterbox: resize keeping the aspect ratio by ``r = min(H / h, W / w)`` to ``(round(w r), round(h r))`` with
  ``INTER_LINEAR``, **centred**, padded with 114: ``top = round(dh / 2 - 0.1)``, ``left = round(dw / 2 - 0.1)``
  (``LetterBox(center=True)``); boxes map back as ``(x - left) / r``, ``(y - top) / r`` (``scale_boxes``);
* output ``output0``: YOLOv8 / YOLO11 ``(N, 4 + nc, A)`` -- ``cx, cy, w, h`` in input pixels then ``nc`` class
  scores (already sigmoid, no objectness); YOLOv5 ``(N, A, 5 + nc)`` -- ``cx, cy, w, h, objectness, nc`` class
  probabilities, score ``obj * cls`` (the YOLOv5 ``non_max_suppression``);
* metadata (``custom_metadata_map``, values written with ``str()`` and read back with ``ast.literal_eval``):
  ``names`` ``"{0: 'person', 1: 'bicycle', ...}"``, ``imgsz`` ``"[640, 640]"``, ``stride`` ``"32"``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from aerodaas.perception.detect import NanoDetDetector, YoloxDetector, _OnnxDetector
from aerodaas.perception.model_meta import metadata_imgsz, metadata_names
from aerodaas.perception.detector_values import FORMATS  # the output formats inspect_model recognises / format= accepts

__all__ = ["UltralyticsDetector", "ModelInfo", "inspect_model", "FORMATS", "metadata_names"]


def _anchors(hw: tuple[int, int], strides=(8, 16, 32)) -> int:
    return sum((hw[0] // s) * (hw[1] // s) for s in strides)


@dataclass
class ModelInfo:
    """What a detector ONNX file says about itself: ``format`` (``yolox`` / ``nanodet`` / ``ultralytics``),
    ``input_hw`` (H, W pixels, None when dynamic), ``batch_dynamic``, ``class_names`` (from the metadata, None if
    absent) and ``n_classes`` (from the output shape, None if dynamic)."""

    format: str
    input_hw: tuple[int, int] | None
    batch_dynamic: bool
    class_names: list[str] | None
    n_classes: int | None
    default_hw: tuple[int, int] | None = None  # a dynamic model's own default: its imgsz metadata


def inspect_model(path: str | os.PathLike, format: str = "auto") -> ModelInfo:
    """Open ``path`` with onnxruntime (no inference) and recognise its output head:

    * several outputs with per-stride ``(1, A, nc)`` scores and ``(1, A, 32)`` distributions: ``nanodet``;
    * one ``(1, A, 5 + nc)`` output with ``A`` = anchors of strides 8/16/32 (one per cell): ``yolox``; with three
      per cell (YOLOv5's anchors) or metadata ``names``: ``ultralytics`` (v5 head);
    * one ``(1, 4 + nc, A)`` output (channels before anchors): ``ultralytics`` (v8/11 head);
    * metadata ``head`` = ``yolox`` (what ``aerodaas train detector`` writes, with ``names``): ``yolox``.

    ``format`` other than ``"auto"`` is taken as given (and checked against the graph where the shape is known).
    Raises ValueError naming the field and value for an unknown ``format``, an input that is not NCHW, or a head
    that matches none of the formats (or not the ``format`` given)."""
    import onnxruntime as ort  # lazy: heavy onnxruntime

    if format not in FORMATS:
        raise ValueError(f"format must be one of {list(FORMATS)}, got {format!r}")
    so = ort.SessionOptions()
    so.log_severity_level = 3
    # nothing runs in this session: no graph optimisation (the graph's inputs, outputs and metadata are the same)
    # and no thread pools. The default options cost 0.45-0.58 s wall (0.07 s CPU) for yolox_nano on the driver
    # before Ray started, these 0.06-0.10 s (0.011 s CPU), measured at load 46 on 2 cores
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    so.intra_op_num_threads = so.inter_op_num_threads = 1
    sess = ort.InferenceSession(str(path), sess_options=so, providers=["CPUExecutionProvider"])
    inp = sess.get_inputs()[0]
    if len(inp.shape) != 4:
        raise ValueError(f"model {path}: expected an NCHW image input, got {inp.name} {inp.shape}")
    hw = (inp.shape[2], inp.shape[3])
    input_hw = (int(hw[0]), int(hw[1])) if all(isinstance(d, int) for d in hw) else None
    meta = sess.get_modelmeta().custom_metadata_map
    names = metadata_names(meta)
    outs = [o.shape for o in sess.get_outputs()]
    found, nc = None, None
    if meta.get("head") == "yolox" and len(outs) == 1 and len(outs[0]) == 3:  # written by `aerodaas train detector`
        found, nc = "yolox", (outs[0][2] - 5 if isinstance(outs[0][2], int) else None)
    elif len(outs) > 1 and all(len(s) == 3 for s in outs):
        found = "nanodet"
        nc = next((s[-1] for s in outs if isinstance(s[-1], int) and s[-1] != 32), None)
    elif len(outs) >= 1 and len(outs[0]) == 3:
        _, a, b = outs[0]
        if isinstance(a, int) and isinstance(b, int):
            if a < b and a > 4 and (input_hw is None or b in (_anchors(input_hw),)):
                found, nc = "ultralytics", a - 4
            elif b > 5 and input_hw is not None and a == _anchors(input_hw):
                found, nc = ("ultralytics" if names is not None else "yolox"), b - 5
            elif b > 5 and input_hw is not None and a == 3 * _anchors(input_hw):
                found, nc = "ultralytics", b - 5
        elif names is not None:
            found = "ultralytics"
    if format == "auto":
        if found is None:
            raise ValueError(f"format='auto': cannot recognise the head of {path} (outputs {outs}); give "
                             f"format='yolox', 'nanodet' or 'ultralytics'")
        format = found
    elif found is not None and found != format and not (found == "ultralytics" and format == "yolox"
                                                         and names is None):
        raise ValueError(f"format={format!r} but the outputs of {path} ({outs}) are a {found} head")
    if names is not None and nc is not None and len(names) != nc:
        raise ValueError(f"model {path}: metadata names has {len(names)} classes but the output has {nc}")
    return ModelInfo(format, input_hw, not isinstance(inp.shape[0], int), names, nc, metadata_imgsz(meta))


class UltralyticsDetector(_OnnxDetector):
    """An Ultralytics YOLOv5 / YOLOv8 / YOLO11 ONNX export (CPU, onnxruntime); interface as
    :class:`aerodaas.perception.detect.YoloxDetector`. Pre-processing, decoding and box mapping as the module docstring
    cites. Class names come from ``class_names=`` or the model's metadata ``names`` (else ``class0..``);
    ``input_size=(H, W)`` is required when the export has dynamic height/width and no ``imgsz`` metadata.

    Images ``(H, W, 3)`` uint8 BGR in, :class:`~aerodaas.model.types.Detection` out (pixels of the image). Raises
    ValueError as the base class, and RuntimeError at ``detect`` when the output is neither head."""

    model_name = "yolox_nano"  # only used by resolve_model's name check; the path is what is loaded

    def __init__(self, model_path: str | os.PathLike, **kwargs) -> None:
        if model_path is None:
            raise ValueError("UltralyticsDetector needs model_path (an Ultralytics ONNX export)")
        super().__init__(model_path, **kwargs)

    def _meta(self) -> dict[str, str]:
        return self.session.get_modelmeta().custom_metadata_map

    def _model_class_names(self) -> Sequence[str]:
        names = metadata_names(self._meta())
        if names is not None:
            return names
        shp = self.session.get_outputs()[0].shape
        nc = None
        if len(shp) == 3 and isinstance(shp[1], int) and isinstance(shp[2], int):
            nc = shp[1] - 4 if shp[1] < shp[2] else shp[2] - 5
        if nc is None or nc < 1:
            raise ValueError(f"{self.model_path}: no metadata names and a dynamic output {shp}; give class_names")
        return [f"class{i}" for i in range(nc)]

    def _preprocess(self, image: np.ndarray):
        h, w = image.shape[:2]
        r, (ih, iw) = self._scale_and_canvas(h, w)
        nw, nh = int(round(w * r)), int(round(h * r))
        dw, dh = (iw - nw) / 2, (ih - nh) / 2
        top, left = int(round(dh - 0.1)), int(round(dw - 0.1))
        canvas = np.full((ih, iw, 3), 114, dtype=np.uint8)
        resized = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR) if (nw, nh) != (w, h) else image
        canvas[top:top + nh, left:left + nw] = resized
        blob = canvas[:, :, ::-1].transpose(2, 0, 1)[None].astype(np.float32) * np.float32(1 / 255.0)
        return np.ascontiguousarray(blob), (left, top, r)

    def _rows(self, outputs) -> tuple[np.ndarray, bool]:
        """``(A, 4 + nc [+1])`` rows of the first image and whether they carry objectness (v5)."""
        p = outputs[0][0]
        nc = len(self.class_names)
        if p.ndim == 2 and p.shape[0] == 4 + nc and p.shape[1] != 4 + nc:
            return p.T, False
        if p.ndim == 2 and p.shape[1] == 5 + nc:
            return p, True
        if p.ndim == 2 and p.shape[1] == 4 + nc:
            return p, False
        raise RuntimeError(f"{self.model_path}: output shape {outputs[0].shape} is neither (1, 4+{nc}, A) nor "
                           f"(1, A, 5+{nc}) for {nc} classes")

    def _candidates(self, outputs, min_score: float, ctx=None):
        rows, has_obj = self._rows(outputs)
        if has_obj:
            idx = np.flatnonzero(rows[:, 4] >= min_score)
            return idx, rows[idx, 4:5] * rows[idx, 5:]
        cls = rows[:, 4:]
        idx = np.flatnonzero(cls.max(axis=1) >= min_score)
        return idx, cls[idx]

    def _boxes(self, outputs, idx: np.ndarray, ctx=None) -> np.ndarray:
        rows, _ = self._rows(outputs)
        p = rows[idx, :4]
        return np.concatenate([p[:, :2] - p[:, 2:4] / 2, p[:, :2] + p[:, 2:4] / 2], axis=1)

    @staticmethod
    def _unmap(boxes: np.ndarray, ctx) -> np.ndarray:
        left, top, r = ctx
        boxes[:, 0::2] = (boxes[:, 0::2] - left) / r
        boxes[:, 1::2] = (boxes[:, 1::2] - top) / r
        return boxes


#: detector class per format
DETECTOR_CLASSES = {"yolox": YoloxDetector, "nanodet": NanoDetDetector, "ultralytics": UltralyticsDetector}
