"""The model a training run starts from (:func:`choose_base`): the user's ``--base-model``, else the shipped aerial
model when it already knows every class of the run, else the COCO YOLOX-Nano; and the output row each class starts
from (:func:`base_rows`). No PyTorch here: the choice is made, and a missing model named, before training starts."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from aerodaas.model.types import COCO_CLASSES
from aerodaas.perception.decoders import inspect_model
from aerodaas.perception.model_files import MODELS, ModelNotFoundError, resolve_model
from aerodaas.training.config import COCO_ALIASES

__all__ = ["BaseModel", "choose_base", "base_rows"]

#: the shipped aerial model (aerodaas/perception/models/MODEL_CARD.md) and the COCO YOLOX-Nano, by registry name
AERIAL, COCO_NANO = "aerial_nano", "yolox_nano"


@dataclass(frozen=True)
class BaseModel:
    """The YOLOX ONNX file a run starts from: ``name`` (``aerial_nano``, ``yolox_nano`` or ``--base-model``'s
    path), ``path``, its ``class_names``, ``rows`` (per class of the run, the output row it starts from) and
    ``why`` it was chosen, in words."""

    name: str
    path: Path
    class_names: list[str]
    rows: list[int]
    why: str

    def as_dict(self) -> dict:
        """The JSON form written to ``report.json`` (``base_model``)."""
        return {"name": self.name, "path": str(self.path), "classes": self.class_names, "rows": self.rows,
                "why": self.why}


def base_rows(names: Sequence[str], base_names: Sequence[str], init_from: dict[str, str]) -> list[int]:
    """For each class name, the base model's output row it starts from (``init_from``, the same name, or
    :data:`~aerodaas.training.config.COCO_ALIASES`). Raises ValueError naming a class that has no row in the base
    model."""
    index = {n: i for i, n in enumerate(base_names)}
    rows = []
    for n in names:
        src = init_from.get(n, n if n in index else COCO_ALIASES.get(n, n))
        if src not in index:
            raise ValueError(f"--init-from: class {n!r} has no start in the base model (its classes: "
                             f"{list(base_names)[:10]}...); pass --init-from {n}=<one of them>")
        rows.append(index[src])
    return rows


def _names_of(path: Path) -> list[str]:
    """The class names of a YOLOX ONNX file: its metadata's, else COCO's 80. Raises ValueError for a file that is
    not a YOLOX detector or that onnxruntime cannot load (not ONNX, a broken graph)."""
    from onnxruntime.capi.onnxruntime_pybind11_state import (  # lazy: heavy onnxruntime
        Fail, InvalidGraph, InvalidProtobuf)

    try:
        return list(inspect_model(path, "yolox").class_names or COCO_CLASSES)
    except (Fail, InvalidGraph, InvalidProtobuf) as e:
        raise ValueError(f"onnxruntime cannot load it: {e}") from None


def choose_base(base_model: Path | None, names: Sequence[str],
                init_from: dict[str, str] | None = None) -> BaseModel:
    """The model a run of classes ``names`` starts from: ``base_model`` when given (a file, or a name of
    :data:`~aerodaas.perception.model_files.MODELS` such as ``yolox_nano``); else the shipped
    ``aerial_nano`` when every name (and every ``init_from`` source) is one of its classes (``car``,
    ``large_vehicle``, ``person``: it has already learnt them from above); else the COCO ``yolox_nano``
    (resolved, and downloaded once, by :func:`~aerodaas.perception.model_files.resolve_model`). Raises
    ModelNotFoundError (a FileNotFoundError) when the file is missing or cannot be fetched, its message saying
    where it was looked for and how to provide it; ValueError for a file that is not a YOLOX ONNX model or a class
    with no row to start from (:func:`base_rows`)."""
    init_from = init_from or {}
    if base_model is not None:
        path = Path(base_model).expanduser()
        if not path.is_file() and str(base_model) in MODELS:  # a registry name: resolved (and checked) as usual
            path = resolve_model(str(base_model))
        if not path.is_file():
            raise ModelNotFoundError(f"--base-model={str(base_model)!r}: no such file (nor one of the models "
                                     f"{sorted(MODELS)})")
        try:
            base_names = _names_of(path)
        except ValueError as e:
            raise ValueError(f"--base-model={str(base_model)!r}: not a YOLOX ONNX detector ({e})") from None
        return BaseModel(str(base_model), path, base_names, base_rows(names, base_names, init_from), "--base-model")
    aerial = resolve_model(AERIAL)
    aerial_names = _names_of(aerial)
    if set(names) | set(init_from.values()) <= set(aerial_names):
        return BaseModel(AERIAL, aerial, aerial_names, base_rows(names, aerial_names, init_from),
                         f"every class of the run is one of the shipped aerial model's {aerial_names}")
    path = resolve_model(COCO_NANO)
    coco_names = _names_of(path)
    other = sorted((set(names) | set(init_from.values())) - set(aerial_names))
    return BaseModel(COCO_NANO, path, coco_names, base_rows(names, coco_names, init_from),
                     f"class(es) {other} are not among the shipped aerial model's {aerial_names}: the COCO model")
