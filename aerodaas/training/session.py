"""One training run from start to shipped file: the model to start from, the loop, the export and its report.

:func:`run_training` is what ``aerodaas train detector`` does on one machine; the report it writes
(``report.json`` in the run folder) names the exact configuration, seed, per-epoch history, the export's parity and
the exported file's metrics, so a model card can be written from it.
"""
from __future__ import annotations

import json
import platform
import time
from dataclasses import asdict
from typing import Callable

import torch

from aerodaas.training.base import choose_base
from aerodaas.training.config import TrainConfig
from aerodaas.training.export import ExportReport, export_checked, quantize_checked
from aerodaas.training.loop import EpochResult, Trainer, TrainingData
from aerodaas.training.loss import LossParts
from aerodaas.training.onnx_module import OnnxYolox

__all__ = ["build_model", "run_training", "export_run", "export_checkpoints"]


def build_model(cfg: TrainConfig, names: list[str]) -> OnnxYolox:
    """The module to fine-tune: the base model :func:`~aerodaas.training.base.choose_base` picks for ``names``
    (``cfg.base_model``, else the shipped aerial model or the COCO YOLOX-Nano), one class row per name. Raises
    as :func:`~aerodaas.training.base.choose_base` does."""
    base = choose_base(cfg.base_model, names, cfg.init_from)
    return OnnxYolox(base.path, base.rows)


def export_run(cfg: TrainConfig, trainer: Trainer, started: float) -> dict:
    """Export the best epoch's EMA weights to ``out/model.onnx`` (checked, scored), quantize when asked, and write
    ``out/report.json`` (with ``base_model``: the model the run started from and why); returns the report."""
    best_state = torch.load(cfg.out / "best.pt", weights_only=False)
    trainer.ema.model.load_state_dict(best_state["ema"])
    base = choose_base(cfg.base_model, trainer.data.names, cfg.init_from)
    meta = {"aerodaas_training": json.dumps({"seed": cfg.seed, "epoch": best_state["epoch"], "base": base.name})}
    rep = export_checked(trainer.ema.model, cfg.out / "model.onnx", trainer.data.names, trainer.val, meta,
                         cfg.score_threshold)
    q_note, q_rep = "not asked (--quantize)", None
    if cfg.quantize:
        q_rep, q_note = quantize_checked(rep, trainer.data.names, trainer.val, cfg.out / "model.int8.onnx",
                                         score_threshold=cfg.score_threshold)

    def _exp(r: ExportReport | None) -> dict | None:
        return None if r is None else {"path": str(r.path), "size_bytes": r.size_bytes,
                                       "max_abs_diff": r.max_abs_diff, "metrics": [asdict(m) for m in r.metrics]}

    report = {"config": cfg.model_dump(mode="json"), "names": trainer.data.names, "base_model": base.as_dict(),
              "train_images": len(trainer.data.train), "val_images": len(trainer.data.val),
              "best_epoch": best_state["epoch"] - 1, "history": [asdict(h) for h in trainer.history],
              "export": _exp(rep), "int8": _exp(q_rep), "int8_note": q_note,
              "seconds": round(time.monotonic() - started, 1),
              "machine": {"cpus": torch.get_num_threads(), "platform": platform.platform(),
                          "torch": torch.__version__}}
    (cfg.out / "report.json").write_text(json.dumps(report, indent=1))
    return report


def export_checkpoints(cfg: TrainConfig, data: TrainingData, started: float) -> dict:
    """Export and report (:func:`export_run`) the run whose checkpoints a Ray Train job wrote to ``cfg.out``
    (``last.pt``: the trainer's state, ``best.pt``: the best epoch); ``started``: its ``time.monotonic()`` start.
    Returns the report. Raises FileNotFoundError when a checkpoint is missing."""
    trainer = Trainer(cfg, data, build_model(cfg, data.names))
    trainer.restore(torch.load(cfg.out / "last.pt", weights_only=False))
    return export_run(cfg, trainer, started)


def run_training(cfg: TrainConfig, data: TrainingData,
                 on_step: Callable[[int, int, LossParts], None] | None = None,
                 on_epoch: Callable[[EpochResult], None] | None = None) -> dict:
    """Train on one machine as ``cfg`` says (``--resume``: from ``out/last.pt``), export and report
    (:func:`export_run`). Raises FileNotFoundError for ``--resume`` without a checkpoint, ValueError for a
    checkpoint of other classes."""
    started = time.monotonic()
    trainer = Trainer(cfg, data, build_model(cfg, data.names), on_step=on_step, on_epoch=on_epoch)
    if cfg.resume:
        last = cfg.out / "last.pt"
        if not last.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint {last} (run without --resume first)")
        trainer.restore(torch.load(last, weights_only=False))
    trainer.fit(cfg.out)
    return export_run(cfg, trainer, started)
