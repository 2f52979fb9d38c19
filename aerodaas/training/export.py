"""Export a trained module to ONNX, check it against PyTorch, score it with the framework's own detector, and
optionally quantize it to int8.

The exported file is the deployment artefact: it is scored through :class:`aerodaas.perception.detect.YoloxDetector`
(the pre-processing, decoding and NMS the analytics use), not through the training code, so the numbers a training
run reports are the numbers a mission gets. int8 quantization is onnxruntime's static QDQ quantization
(``onnxruntime.quantization.quantize_static``, per-channel weights, calibrated on validation tiles); the int8 file is
kept only when its recall is within ``max_recall_drop`` of the float model's on every class with validation boxes.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from onnx import version_converter
import onnx
import onnxruntime as ort
from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process
import torch

from aerodaas.perception.detect import YoloxDetector
from aerodaas.perception.scoring import GroundTruth, score
from aerodaas.training.onnx_module import OnnxYolox, write_onnx
from aerodaas.training.validate import ClassMetrics, ValTiles

__all__ = ["ExportReport", "export_checked", "score_onnx", "quantize_checked", "ParityError"]

#: largest |ONNX - PyTorch| over the raw outputs accepted as the same model (float32 rounding of ~300 layers)
PARITY_TOLERANCE = 1e-3


class ParityError(RuntimeError):
    """The exported ONNX graph does not compute what the PyTorch module does."""


@dataclass(frozen=True)
class ExportReport:
    """What an export produced: the file, its size in bytes, the max abs difference ONNX vs PyTorch on the check
    tiles, and the file's metrics on the validation tiles."""

    path: Path
    size_bytes: int
    max_abs_diff: float
    metrics: list[ClassMetrics]


def _tiles_nchw(val: ValTiles, n: int) -> np.ndarray:
    return np.ascontiguousarray(val.images[:n].transpose(0, 3, 1, 2), dtype=np.float32)


def export_checked(module: OnnxYolox, path: str | os.PathLike, names: Sequence[str], val: ValTiles,
                   metadata: dict[str, str] | None = None, score_threshold: float = 0.3,
                   n_check: int = 8) -> ExportReport:
    """Write ``module`` to ``path`` (:func:`write_onnx`), compare onnxruntime's output with PyTorch's on the first
    ``n_check`` validation tiles, and score the file (:func:`score_onnx`). Raises :class:`ParityError` when the
    largest difference exceeds :data:`PARITY_TOLERANCE`."""
    path = Path(path)
    module.eval()
    write_onnx(module, path, list(names), metadata)
    x = _tiles_nchw(val, min(n_check, len(val.images)))
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    got = sess.run(None, {sess.get_inputs()[0].name: x})[0]
    with torch.no_grad():
        want = module.inference(torch.from_numpy(x)).numpy()
    diff = float(np.abs(got - want).max())
    if not diff <= PARITY_TOLERANCE:
        raise ParityError(f"{path}: ONNX and PyTorch outputs differ by up to {diff:.3g} "
                          f"(> {PARITY_TOLERANCE}): the export is not the trained model")
    return ExportReport(path, path.stat().st_size, diff, score_onnx(path, names, val, score_threshold))


def score_onnx(path: str | os.PathLike, names: Sequence[str], val: ValTiles,
               score_threshold: float = 0.3) -> list[ClassMetrics]:
    """Recall and precision at ``score_threshold`` and AP50 per class of the ONNX file at ``path`` on ``val``,
    through :class:`YoloxDetector` at the tiles' size (one thread)."""
    tile = val.images.shape[1]
    det = YoloxDetector(str(path), score_threshold=0.01, input_size=(tile, tile), intra_op_threads=1)
    pairs = []
    for k, (im, t) in enumerate(zip(val.images, val.targets)):
        gt = GroundTruth(f"tile{k}", t[:, 1:5].astype(float), [names[int(c)] for c in t[:, 0]])
        pairs.append((det.detect(im), gt))
    out = []
    for name in names:
        full = score(pairs, name, 0.5)
        at = score([([d for d in ds if d.score >= score_threshold], g) for ds, g in pairs], name, 0.5)
        out.append(ClassMetrics(name, full.n_gt, at.recall, at.precision, full.ap))
    return out


class _Calibration:
    """onnxruntime's ``CalibrationDataReader`` protocol over validation tiles (``get_next`` -> feed dict or None)."""

    def __init__(self, input_name: str, x: np.ndarray) -> None:
        self._it = iter([{input_name: x[i:i + 1]} for i in range(len(x))])

    def get_next(self):
        return next(self._it, None)


def quantize_checked(report: ExportReport, names: Sequence[str], val: ValTiles, out: str | os.PathLike,
                     max_recall_drop: float = 0.02, n_calib: int = 64,
                     score_threshold: float = 0.3) -> tuple[ExportReport | None, str]:
    """Quantize ``report.path`` to int8 at ``out`` and score it; returns (its report, "kept ...") when no class's
    recall dropped by more than ``max_recall_drop``, else (None, the reason) and the int8 file is removed."""
    out = Path(out)
    pre = out.with_suffix(".pre.onnx")
    # per-channel weight scales need DequantizeLinear's axis attribute: opset 13 (the YOLOX export is opset 11)
    onnx.save(version_converter.convert_version(onnx.load(str(report.path)), 13), str(pre))
    # symbolic shape inference cannot finish on the dynamic batch/height/width graph: ONNX shape inference and the
    # graph optimisation only (onnxruntime's quantization guide: pre-processing is optional)
    quant_pre_process(str(pre), str(pre), skip_symbolic_shape=True)
    sess = ort.InferenceSession(str(pre), providers=["CPUExecutionProvider"])
    calib = _Calibration(sess.get_inputs()[0].name, _tiles_nchw(val, min(n_calib, len(val.images))))
    quantize_static(str(pre), str(out), calib, quant_format=QuantFormat.QDQ, per_channel=True,
                    activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                    calibrate_method=CalibrationMethod.MinMax)
    pre.unlink(missing_ok=True)
    metrics = score_onnx(out, names, val, score_threshold)
    drops = {f.name: f.recall - q.recall for f, q in zip(report.metrics, metrics) if f.n_gt}
    worst = max(drops.items(), key=lambda kv: kv[1], default=("-", 0.0))
    if worst[1] > max_recall_drop:
        out.unlink(missing_ok=True)
        return None, (f"int8 dropped: {worst[0]} recall fell {worst[1] * 100:.1f} points "
                      f"(> {max_recall_drop * 100:.0f})")
    q = ExportReport(out, out.stat().st_size, float("nan"), metrics)
    return q, f"int8 kept: largest recall drop {worst[1] * 100:.1f} points ({worst[0]})"
