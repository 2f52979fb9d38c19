"""The console view of a training run on this machine (``aerodaas train detector`` without ``--workers``): a
progress bar of the optimiser steps with the loss parts, and one line per epoch with the validation recall,
precision and AP50 of each class (:func:`train_with_progress`)."""
from __future__ import annotations

from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from aerodaas.training.config import TrainConfig

__all__ = ["EpochLine", "StepBar", "train_with_progress"]


class StepBar:
    """Step callback of :func:`aerodaas.training.session.run_training`: steps done of the total on ``bar``'s task
    ``task``, with the loss and its parts (IoU, objectness, class)."""

    def __init__(self, bar, task) -> None:
        self.bar, self.task = bar, task

    def __call__(self, step: int, total: int, parts) -> None:
        self.bar.update(self.task, completed=step, total=total,
                        info=f"loss {parts.total:.3f} (iou {parts.iou:.2f} obj {parts.obj:.2f} cls {parts.cls:.2f})")


class EpochLine:
    """Epoch callback of :func:`aerodaas.training.session.run_training`: one line per epoch on ``bar``'s console
    with the loss, each class's validation recall/precision/AP50 and the seconds of training and validation."""

    def __init__(self, bar) -> None:
        self.bar = bar

    def __call__(self, res) -> None:
        per = "  ".join(f"{m.name} R {m.recall:.2f} P {m.precision:.2f} AP50 {m.ap50:.2f}" for m in res.metrics
                        if m.n_gt)
        self.bar.console.print(f"epoch {res.epoch + 1}: loss {res.loss:.3f}  {per}  ({res.train_s:.0f} s + "
                               f"{res.val_s:.0f} s val)")


def train_with_progress(cfg: TrainConfig, data) -> dict:
    """:func:`aerodaas.training.session.run_training` of ``cfg`` on ``data`` (a
    :class:`~aerodaas.training.loop.TrainingData`) under a progress bar on the terminal; returns its report. Raises
    what it raises."""
    from aerodaas.training.session import run_training  # lazy: optional dependency (PyTorch: the [train] extra)

    with Progress(TextColumn("[bold]train"), BarColumn(), TextColumn("{task.completed}/{task.total} steps"),
                  TextColumn("{task.fields[info]}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  transient=False) as bar:
        task = bar.add_task("train", total=None, info="")
        return run_training(cfg, data, on_step=StepBar(bar, task), on_epoch=EpochLine(bar))
