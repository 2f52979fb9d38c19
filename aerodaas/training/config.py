"""The settings of one training run (``aerodaas train detector``), checked before anything is read or trained."""
from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, field_validator

__all__ = ["TrainConfig", "COCO_ALIASES"]

#: class names that start from a COCO class's row of the base model when they are not COCO names themselves
COCO_ALIASES = {"large_vehicle": "truck", "van": "car", "vehicle": "car", "pedestrian": "person",
                "people": "person", "cyclist": "bicycle", "motor": "motorcycle", "minibus": "bus"}


class TrainConfig(BaseModel):
    """One training run. Sizes in pixels, rates per step; paths are folders or files as named.

    ``data``: labelled sets (YOLO folder or COCO JSON, :func:`aerodaas.training.dataset.load_set`), all with the same
    class names; ``val``: held-out sets (default: ``val_fraction`` of ``data`` split by video/sequence);
    ``base_model``: the YOLOX ONNX to start from (default: :func:`~aerodaas.training.base.choose_base`, the shipped
    aerial model when it knows every class, else the COCO YOLOX-Nano); ``init_from``: per class,
    the base model's class whose output row it starts from (default: the same name, or :data:`COCO_ALIASES`);
    ``out``: the run folder (checkpoints ``last.pt`` / ``best.pt``, ``history.json``, ``model.onnx``);
    ``object_px``: the range (pixels, min < max) a tile's median object is scaled into, drawn log-uniformly (the
    altitudes the camera should see, :class:`~aerodaas.training.augment.Augment`); ``p_oblique``: the share of tiles
    warped as a camera pitched towards the horizon sees the ground.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    data: list[Path] = Field(min_length=1)
    val: list[Path] = Field(default_factory=list)
    val_fraction: float = Field(0.15, gt=0.0, lt=0.9)
    names: list[str] | None = None
    base_model: Path | None = None
    init_from: dict[str, str] = Field(default_factory=dict)
    out: Path = Path("runs/detector")
    epochs: int = Field(30, ge=1, le=10_000)
    tiles_per_epoch: int = Field(800, ge=1, le=10_000_000)
    batch: int = Field(8, ge=1, le=512)
    lr: float = Field(1e-3, gt=0.0, le=1.0)
    weight_decay: float = Field(5e-4, ge=0.0, le=1.0)
    ema_decay: float = Field(0.9995, ge=0.0, lt=1.0)
    tile: int = Field(416, ge=64, le=4096)
    object_px: tuple[float, float] = (8.0, 96.0)
    p_oblique: float = Field(0.3, ge=0.0, le=1.0, allow_inf_nan=False)
    val_tiles: int = Field(300, ge=1, le=1_000_000)
    score_threshold: float = Field(0.3, gt=0.0, lt=1.0)
    balance_sources: bool = True
    seed: int = 0
    resume: bool = False
    workers: int = Field(0, ge=0, le=4096)
    use_gpu: bool = False
    quantize: bool = False
    max_steps: int | None = Field(None, ge=1)

    @field_validator("object_px")
    @classmethod
    def _object_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not 2.0 <= v[0] < v[1] <= 4096.0:
            raise ValueError(f"two sizes in pixels are needed, 2 <= MIN < MAX <= 4096, got {list(v)}")
        return v

    @field_validator("tile")
    @classmethod
    def _tile_multiple(cls, v: int) -> int:
        if v % 32:
            raise ValueError(f"tile={v} must be a multiple of 32 (the detector's largest stride)")
        return v
