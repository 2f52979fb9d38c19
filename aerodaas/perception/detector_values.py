"""The checks of a detector configuration that need no model file: thresholds, class names, ``format``, input size,
the shipped model's name. Cheap, without cv2 or onnxruntime: an
:class:`~aerodaas.analytics.core.ObjectDetector` runs them where the app builds it, and the detectors
(:mod:`aerodaas.perception.detect`, :mod:`aerodaas.perception.decoders`) check their own input size with them.
The checks that open the model (:func:`aerodaas.perception.options.check_detector_options`) build on these.
"""
from __future__ import annotations

import math
import os
from typing import Any

__all__ = ["FORMATS", "SHIPPED_FORMAT", "normalise_classes", "check_input_size", "check_detector_values"]

#: the ONNX output heads the decoders read (:mod:`aerodaas.perception.decoders`); ``"auto"``: from the graph
FORMATS = ("auto", "yolox", "nanodet", "ultralytics")

#: the output format of each shipped model name (:data:`aerodaas.perception.model_files.MODELS`)
SHIPPED_FORMAT = {"yolox_nano": "yolox", "yolox": "yolox", "nanodet_plus_m_416": "nanodet", "nanodet": "nanodet",
                   "aerial_nano": "yolox", "aerial": "yolox"}


def normalise_classes(classes: Any, field: str = "classes") -> list[str] | None:
    """``None`` -> None (all classes); a plain string -> that one class; an iterable of strings -> a list.
    Raises ValueError for an empty list (it would silently mean nothing or everything) or a non-string item."""
    if classes is None:
        return None
    if isinstance(classes, str):
        return [classes]
    try:
        out = list(classes)
    except TypeError:
        raise ValueError(f"{field} must be a class name or a list of class names, got {classes!r}") from None
    if not out:
        raise ValueError(f"{field}=[] names no class; give at least one class name, or None for all classes")
    bad = [c for c in out if not isinstance(c, str)]
    if bad:
        raise ValueError(f"{field}: class names must be strings, got {bad!r}")
    return out


def _unit(field: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a number within [0, 1], got {v!r}") from None
    if isinstance(v, bool) or not math.isfinite(f) or not 0.0 <= f <= 1.0:
        raise ValueError(f"{field} must be a number within [0, 1] (a score, not a percentage), got {v!r}")
    return f


def check_input_size(input_size: Any) -> tuple[int, int]:
    """``(H, W)`` in pixels, both positive multiples of 32 (the largest stride of the supported heads), at most
    4096. Raises ValueError naming the value."""
    try:
        ih, iw = (int(v) for v in input_size)
        ok = all(float(v) == int(v) for v in input_size)
    except (TypeError, ValueError):
        raise ValueError(f"input_size must be (H, W) in pixels, got {input_size!r}") from None
    if not ok or not (32 <= ih <= 4096 and 32 <= iw <= 4096) or ih % 32 or iw % 32:
        raise ValueError(f"input_size must be (H, W) with each a multiple of 32 within [32, 4096], got {input_size!r}")
    return ih, iw


def check_detector_values(*, name: str = "detector", model: str = "yolox_nano", model_path: Any = None,
                          format: str = "auto", score_threshold: float = 0.3, nms_threshold: float = 0.45,
                          class_thresholds: dict[str, float] | None = None, input_size: Any = None,
                          threads: int = 1, upscale: Any = True) -> None:
    """The checks of a detector configuration that need no model file (thresholds in [0, 1], ``format``, a known
    shipped ``model`` name or a ``model_path`` string, ``input_size`` multiples of 32, ``threads`` an integer >= 0
    (onnxruntime intra-op threads; 0 is its default), ``upscale`` a bool): cheap, without cv2 or onnxruntime, so
    :class:`~aerodaas.analytics.detector.ObjectDetector` runs them where the app builds it. Raises ValueError
    starting with ``analytics {name!r}:`` and naming the field and the value."""
    try:
        _unit("score_threshold", score_threshold)
        _unit("nms_threshold", nms_threshold)
        for c, v in (class_thresholds or {}).items():
            _unit(f"class_thresholds[{c!r}]", v)
        if format not in FORMATS:
            raise ValueError(f"format must be one of {list(FORMATS)}, got {format!r}")
        if input_size is not None:
            check_input_size(input_size)
        if model_path is None and model not in SHIPPED_FORMAT:
            raise ValueError(f"model must be one of {sorted(SHIPPED_FORMAT)} or model_path must name an ONNX file, "
                             f"got model={model!r}")
        if model_path is not None and not isinstance(model_path, (str, os.PathLike)):
            raise ValueError(f"model_path must be a file path, got {model_path!r}")
        if not isinstance(upscale, bool):
            raise ValueError(f"upscale must be True or False (enlarge a frame smaller than the input), got {upscale!r}")
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 0:
            raise ValueError(f"threads must be an integer >= 0 (onnxruntime intra-op threads, 0: its default), "
                             f"got {threads!r}")
    except ValueError as e:
        raise ValueError(f"analytics {name!r}: {e}") from None
