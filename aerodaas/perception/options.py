"""A detector configuration checked on the driver, before Ray starts, and the detector built
from it on the actor.

:func:`check_detector_options` checks every field of an :class:`~aerodaas.analytics.core.ObjectDetector` (thresholds,
class names against the model's own names, class groups, input size, the model's format) and raises ValueError
naming the field and the value; the pre-flight (:func:`aerodaas.runtime.preflight.validate`, through
``ObjectDetector.check``) calls it, so ``aerodaas run`` exits 2 before any actor starts. It opens the model with
onnxruntime (:func:`aerodaas.perception.decoders.inspect_model`), so this module imports cv2 and onnxruntime: the
checks that need no model file are :mod:`aerodaas.perception.detector_values`, which an app imports instead.
"""
from __future__ import annotations

import os
from typing import Any, Iterable

from aerodaas.model.types import COCO_CLASSES
from aerodaas.perception.decoders import DETECTOR_CLASSES, inspect_model
from aerodaas.perception.detect import make_detector
from aerodaas.perception.detector_values import (SHIPPED_FORMAT, check_detector_values, check_input_size,
                                                 normalise_classes)

__all__ = ["check_detector_options", "build_detector"]


def check_detector_options(*, name: str = "detector", model: str = "yolox_nano", model_path: str | None = None,
                           format: str = "auto", classes: Iterable[str] | None = None,
                           score_threshold: float = 0.3, nms_threshold: float = 0.45,
                           class_thresholds: dict[str, float] | None = None,
                           class_groups: dict[str, Iterable[str]] | None = None,
                           input_size: tuple[int, int] | None = None,
                           class_names: list[str] | None = None, threads: int = 1,
                           upscale: Any = True) -> dict[str, Any]:
    """Check a detector configuration without Ray; ``model_path`` (if given) is opened with onnxruntime to read its
    format, input size and class names (:func:`aerodaas.perception.decoders.inspect_model`). Returns
    ``{"format", "class_names", "input_hw"}`` as they will be used. Every error is a ValueError whose message
    starts with ``analytics {name!r}:`` and names the field and the value."""
    check_detector_values(name=name, model=model, model_path=model_path, format=format,
                          score_threshold=score_threshold, nms_threshold=nms_threshold,
                          class_thresholds=class_thresholds, input_size=input_size, threads=threads,
                          upscale=upscale)
    pre = f"analytics {name!r}: "
    try:
        hw = check_input_size(input_size) if input_size is not None else None
        names: list[str] | None = list(class_names) if class_names is not None else None
        fmt = SHIPPED_FORMAT.get(model, "yolox") if format == "auto" and model_path is None else format
        if model_path is not None:
            if not os.path.isfile(model_path):
                raise ValueError(f"model_path={str(model_path)!r} is not a file")
            try:
                info = inspect_model(model_path, format)
            except ValueError:
                raise
            except Exception as e:  # onnxruntime's own load errors (not an ONNX file, unsupported op)
                raise ValueError(f"model_path={str(model_path)!r} cannot be loaded by onnxruntime: {e}") from None
            fmt = info.format
            if names is None:
                names = info.class_names
            if info.input_hw is not None and hw is not None and hw != info.input_hw:
                raise ValueError(f"input_size={tuple(input_size)!r} but the model's input is fixed at {info.input_hw}")
            if info.input_hw is None and hw is None and info.default_hw is not None:
                hw = info.default_hw  # the model's imgsz metadata (the shipped aerial model has one)
            if info.input_hw is None and hw is None and fmt != "ultralytics":
                raise ValueError(f"input_size=None but {model_path} has dynamic height/width; give input_size=(H, W)")
            hw = hw or info.input_hw
            if names is not None and info.n_classes is not None and len(names) != info.n_classes:
                raise ValueError(f"class_names has {len(names)} names but the model outputs {info.n_classes} classes")
        if names is None and fmt in ("yolox", "nanodet"):
            names = list(COCO_CLASSES)
        known = set(names) if names is not None else None

        def _known(field: str, values: Iterable[str]) -> None:
            if known is None:
                return
            bad = [c for c in values if c not in known]
            if bad:
                close = {c: [k for k in known if k.lower() == c.lower()] for c in bad}
                hint = "; ".join(f"{c!r} -> did you mean {v[0]!r}?" for c, v in close.items() if v)
                raise ValueError(f"{field}: unknown class name(s) {bad}" + (f" ({hint})" if hint else "")
                                 + f"; the model's classes: {sorted(known)[:20]}{' ...' if len(known) > 20 else ''}")

        cls = normalise_classes(classes)
        if cls is not None:
            _known("classes", cls)
        _known("class_thresholds", list(class_thresholds or {}))
        for g, members in (class_groups or {}).items():
            m = normalise_classes(members, f"class_groups[{g!r}]")
            _known(f"class_groups[{g!r}]", m or [])
    except ValueError as e:
        raise ValueError(pre + str(e)) from None
    return {"format": fmt, "class_names": names, "input_hw": hw}


def build_detector(model: str = "yolox_nano", model_path: str | os.PathLike | None = None, format: str = "auto",
                   checked_format: str | None = None, **kwargs):
    """The detector for a configuration: a shipped model by name (``model``), or ``model_path`` decoded as
    ``format`` (``"auto"``: recognised from the graph by :func:`~aerodaas.perception.decoders.inspect_model`), or
    as ``checked_format`` when given: the format :func:`check_detector_options` returned for these very bytes (the
    model is then opened once, by the detector, not first by the inspection).
    ``kwargs`` go to the detector's constructor (thresholds, classes, ``agnostic_nms``, ``class_groups``,
    ``input_size``, ``class_names``, ``intra_op_threads``). Raises ValueError as the constructors and
    :func:`check_detector_options` do."""
    if model_path is None:
        if format not in ("auto", SHIPPED_FORMAT.get(model, "")):
            raise ValueError(f"format={format!r} does not match the shipped model {model!r}")
        return make_detector(model, **kwargs)
    if checked_format is not None and checked_format not in DETECTOR_CLASSES:
        raise ValueError(f"checked_format must be one of {sorted(DETECTOR_CLASSES)}, got {checked_format!r}")
    fmt = checked_format or inspect_model(model_path, format).format
    return DETECTOR_CLASSES[fmt](model_path, **kwargs)
