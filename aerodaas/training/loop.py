"""The training loop of ``aerodaas train detector``: tiles, SimOTA loss, AdamW with a cosine schedule, an EMA of the
weights, validation each epoch, a checkpoint each epoch (``--resume`` continues from it, bit for bit in its random
streams), and the best epoch's EMA weights exported to ONNX and checked against PyTorch.

One process on the CPU by default; :mod:`aerodaas.training.distributed` runs the same loop as a Ray Train job.
"""
from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from aerodaas.training.augment import Augment, TileSampler
from aerodaas.training.config import TrainConfig
from aerodaas.training.sets import TrainingData, load_training_data
from aerodaas.training.loss import LossParts, YoloxLoss
from aerodaas.training.onnx_module import OnnxYolox
from aerodaas.training.validate import ClassMetrics, ValTiles, evaluate

__all__ = ["Trainer", "EpochResult", "augment_of", "TrainingData", "load_training_data"]


@dataclass(frozen=True)
class EpochResult:
    """One epoch: mean losses, validation metrics per class, seconds of training and of validation."""

    epoch: int
    loss: float
    iou: float
    obj: float
    cls: float
    metrics: list[ClassMetrics]
    train_s: float
    val_s: float

    @property
    def mean_ap50(self) -> float:
        """AP50 averaged over the classes that have validation boxes."""
        aps = [m.ap50 for m in self.metrics if m.n_gt]
        return float(np.mean(aps)) if aps else 0.0


def augment_of(cfg: TrainConfig) -> Augment:
    """The training tiles' augmentation for run ``cfg``: its tile size, object size range and oblique share."""
    return Augment(tile=cfg.tile, object_px=cfg.object_px, p_oblique=cfg.p_oblique)


class _Ema:
    """Exponential moving average of the weights (YOLOX's ``ModelEMA``: decay ramps as d * (1 - exp(-t / 2000)))."""

    def __init__(self, model: torch.nn.Module, decay: float) -> None:
        self.model = copy.deepcopy(model).eval()
        self.decay = decay
        self.updates = 0
        for p in self.model.parameters():
            p.requires_grad_(False)

    def update(self, model: torch.nn.Module) -> None:
        self.updates += 1
        d = self.decay * (1 - math.exp(-self.updates / 2000))
        with torch.no_grad():
            for e, p in zip(self.model.state_dict().values(), model.state_dict().values()):
                if e.dtype.is_floating_point:
                    e.mul_(d).add_(p.detach(), alpha=1 - d)


@dataclass
class Trainer:
    """Trains one :class:`OnnxYolox` on :class:`TrainingData` as ``cfg`` says; ``on_step(step, total, parts)`` is
    called after every optimiser step (the progress bar), ``on_epoch(result)`` after every epoch."""

    cfg: TrainConfig
    data: TrainingData
    model: OnnxYolox
    rank: int = 0
    world: int = 1
    on_step: Callable[[int, int, LossParts], None] | None = None
    on_epoch: Callable[[EpochResult], None] | None = None
    history: list[EpochResult] = field(default_factory=list)

    def __post_init__(self) -> None:
        torch.manual_seed(self.cfg.seed)
        self.model = self.model.to(memory_format=torch.channels_last)
        self.net: torch.nn.Module = self.model  # what the steps call: the model, or its DDP wrapper on Ray Train
        self.loss = YoloxLoss(len(self.data.names))
        self.opt = torch.optim.AdamW(self.model.parameters(), lr=self.cfg.lr, weight_decay=self.cfg.weight_decay)
        self.ema = _Ema(self.model, self.cfg.ema_decay)
        self.sampler = TileSampler(self.data.train, augment_of(self.cfg), weights=self.data.weights,
                                   n_classes=len(self.data.names))
        self.rng = np.random.default_rng([self.cfg.seed, self.rank])
        self.val = ValTiles.cut(self.data.val, self.cfg.val_tiles, self.cfg.tile, self.cfg.seed + 7919)
        self.steps_per_epoch = max(1, self.cfg.tiles_per_epoch // (self.cfg.batch * self.world))
        self.start_epoch = 0
        self.best = -1.0

    def _lr(self, step: int) -> float:
        total = self.steps_per_epoch * self.cfg.epochs
        warm = max(1, min(200, total // 10))
        if step < warm:
            return self.cfg.lr * (step + 1) / warm
        return self.cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * (step - warm) / max(1, total - warm))))

    def batch(self) -> tuple[torch.Tensor, list[torch.Tensor], torch.Tensor]:
        """One batch of augmented tiles ``(B, 3, tile, tile)`` float32 BGR 0-255, their targets, and ``(B, nc)``
        bool: which classes each tile's source labels exhaustively."""
        ims, tg, lab = zip(*(self.sampler.sample_labelled(self.rng) for _ in range(self.cfg.batch)))
        x = torch.from_numpy(np.stack(ims)).permute(0, 3, 1, 2).float()
        return (x.contiguous(memory_format=torch.channels_last), [torch.from_numpy(t) for t in tg],
                torch.from_numpy(np.stack(lab)))

    def train_epoch(self, epoch: int) -> EpochResult:
        """One epoch of training, then validation of the EMA weights."""
        self.model.train()
        t0 = time.monotonic()
        sums = np.zeros(4)
        for k in range(self.steps_per_epoch):
            step = epoch * self.steps_per_epoch + k
            for g in self.opt.param_groups:
                g["lr"] = self._lr(step)
            x, targets, labelled = self.batch()
            loss, parts = self.loss(self.net(x), targets, labelled)
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.model.parameters(), 10.0)
            self.opt.step()
            self.ema.update(self.model)
            sums += (parts.total, parts.iou, parts.obj, parts.cls)
            if self.on_step:
                self.on_step(step + 1, self.steps_per_epoch * self.cfg.epochs, parts)
            if self.cfg.max_steps and step + 1 >= self.cfg.max_steps:
                break
        n = k + 1
        t1 = time.monotonic()
        metrics = evaluate(self.ema.model, self.val, self.data.names, self.cfg.score_threshold)
        res = EpochResult(epoch, *(sums / n), metrics, t1 - t0, time.monotonic() - t1)
        self.history.append(res)
        return res

    def state(self) -> dict:
        """Everything ``--resume`` needs: weights, EMA, optimiser, epoch, random streams, best score, history."""
        return {"model": self.model.state_dict(), "ema": self.ema.model.state_dict(), "ema_updates": self.ema.updates,
                "opt": self.opt.state_dict(), "epoch": len(self.history) + self.start_epoch,
                "rng": self.rng.bit_generator.state, "torch_rng": torch.get_rng_state(), "best": self.best,
                "history": [asdict(h) for h in self.history], "names": self.data.names,
                "class_rows": self.model.class_rows, "config": self.cfg.model_dump(mode="json")}

    def restore(self, state: dict) -> None:
        """Continue from :meth:`state` (raises ValueError when the checkpoint's classes differ)."""
        if state["names"] != self.data.names:
            raise ValueError(f"--resume: the checkpoint's classes {state['names']} differ from {self.data.names}")
        self.model.load_state_dict(state["model"])
        self.ema.model.load_state_dict(state["ema"])
        self.ema.updates = state["ema_updates"]
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        self.best = state["best"]
        self.history = [EpochResult(**{**h, "metrics": [ClassMetrics(**m) for m in h["metrics"]]})
                        for h in state["history"]]
        self.start_epoch = 0 if self.history else state["epoch"]

    def fit(self, out: Path) -> EpochResult:
        """Train from the current epoch to ``cfg.epochs``, writing ``last.pt`` each epoch and ``best.pt`` when the
        mean AP50 improves, and ``history.json``; returns the best epoch."""
        out.mkdir(parents=True, exist_ok=True)
        for epoch in range(len(self.history), self.cfg.epochs):
            res = self.train_epoch(epoch)
            if self.rank == 0:
                if res.mean_ap50 > self.best:
                    self.best = res.mean_ap50
                    torch.save(self.state(), out / "best.pt")
                torch.save(self.state(), out / "last.pt")
                (out / "history.json").write_text(json.dumps([asdict(h) for h in self.history], indent=1))
            if self.on_epoch:
                self.on_epoch(res)
            if self.cfg.max_steps and (epoch + 1) * self.steps_per_epoch >= self.cfg.max_steps:
                break
        return max(self.history, key=lambda h: h.mean_ap50)
