"""``aerodaas train detector`` itself (its options: :mod:`aerodaas.commands.train`): the options checked into a
:class:`~aerodaas.training.config.TrainConfig`, the labels loaded, the training here or as a Ray Train job, and
the export. Exit codes: 0 trained and exported; 2 bad input (options, labels, a base model that is missing or no
YOLOX file, a missing PyTorch), named before anything trains; 1 the training or export failed.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pydantic import ValidationError
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from aerodaas.perception.model_files import ModelNotFoundError
from aerodaas.runtime.ray_start import ensure_ray, shutdown_ray
from aerodaas.training.base import choose_base
from aerodaas.training.config import TrainConfig
from aerodaas.training.labels.check import LabelError
from aerodaas.training.sets import load_training_data


def _config(args: argparse.Namespace):
    init = {}
    for item in args.init_from:
        name, sep, base = item.partition("=")
        if not sep or not name or not base:
            raise ValueError(f"--init-from {item!r}: expected CLASS=BASECLASS")
        init[name] = base
    names = [n.strip() for n in args.names.split(",") if n.strip()] if args.names else None
    try:
        return TrainConfig(data=args.data, val=args.val, val_fraction=args.val_fraction, names=names,
                           base_model=args.base_model, init_from=init, out=args.out, epochs=args.epochs,
                           tiles_per_epoch=args.tiles_per_epoch, batch=args.batch, lr=args.lr, tile=args.tile,
                           object_px=tuple(args.object_px), p_oblique=args.oblique,
                           val_tiles=args.val_tiles, seed=args.seed, resume=args.resume, workers=args.workers,
                           use_gpu=args.gpu, quantize=args.quantize, max_steps=args.max_steps,
                           balance_sources=not args.no_balance)
    except ValidationError as e:
        err = e.errors()[0]
        field = {"p_oblique": "--oblique"}.get(str(err["loc"][0]),
                                               "--" + ".".join(str(x) for x in err["loc"]).replace("_", "-"))
        raise ValueError(f"{field}={err.get('input')!r}: {err['msg']}") from None


def cmd_train_detector(args: argparse.Namespace) -> int:
    """Check the options, the labels and the base model (exit 2 naming the problem: a missing base model is named
    with where it was looked for), train, export; print where the model is."""
    try:
        cfg = _config(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    try:
        data = load_training_data(cfg)
        base = choose_base(cfg.base_model, data.names, cfg.init_from)
    except (LabelError, ModelNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        import torch  # noqa: F401  # lazy: optional dependency (PyTorch: the [train] extra)
    except ImportError:
        print('error: aerodaas train needs PyTorch: pip install -e ".[train]" (the CPU build: '
              "pip install torch --index-url https://download.pytorch.org/whl/cpu; docs/training.md)",
              file=sys.stderr)
        return 2
    print(f"training on {len(data.train)} images, validating on {len(data.val)}; classes {data.names}; starting from "
          f"{base.name} ({base.why})", file=sys.stderr)
    if cfg.workers:
        return _on_ray(cfg, data, args.address)
    return _here(cfg, data)


def _here(cfg, data) -> int:
    from aerodaas.training.session import run_training  # lazy: optional dependency (PyTorch: the [train] extra)

    with Progress(TextColumn("[bold]train"), BarColumn(), TextColumn("{task.completed}/{task.total} steps"),
                  TextColumn("{task.fields[info]}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  transient=False) as bar:
        task = bar.add_task("train", total=None, info="")
        report = run_training(
            cfg, data,
            on_step=_StepBar(bar, task),
            on_epoch=_EpochLine(bar))
    exp = report["export"]
    print(f"exported {exp['path']} ({exp['size_bytes'] / 2**20:.2f} MiB, ONNX vs PyTorch max |diff| "
          f"{exp['max_abs_diff']:.2g}); {report['int8_note']}; report: {Path(cfg.out) / 'report.json'}")
    for m in exp["metrics"]:
        print(f"  {m['name']:>14}: recall {m['recall']:.3f} precision {m['precision']:.3f} AP50 {m['ap50']:.3f} "
              f"({m['n_gt']} boxes)")
    return 0


class _StepBar:
    """Progress-bar callback: steps done, loss parts."""

    def __init__(self, bar, task) -> None:
        self.bar, self.task = bar, task

    def __call__(self, step: int, total: int, parts) -> None:
        self.bar.update(self.task, completed=step, total=total,
                        info=f"loss {parts.total:.3f} (iou {parts.iou:.2f} obj {parts.obj:.2f} cls {parts.cls:.2f})")


class _EpochLine:
    """Epoch callback: one line per epoch with validation recall/precision/AP50."""

    def __init__(self, bar) -> None:
        self.bar = bar

    def __call__(self, res) -> None:
        per = "  ".join(f"{m.name} R {m.recall:.2f} P {m.precision:.2f} AP50 {m.ap50:.2f}" for m in res.metrics
                        if m.n_gt)
        self.bar.console.print(f"epoch {res.epoch + 1}: loss {res.loss:.3f}  {per}  ({res.train_s:.0f} s + "
                               f"{res.val_s:.0f} s val)")


def _on_ray(cfg, data, address: str | None) -> int:
    import torch  # lazy: optional dependency (the [train] extra)

    from aerodaas.training.distributed import train_on_ray  # lazy: optional dependency (PyTorch)
    from aerodaas.training.loop import Trainer  # lazy: optional dependency (PyTorch: the [train] extra)
    from aerodaas.training.session import build_model, export_run  # lazy: optional dependency (PyTorch)

    started = time.monotonic()
    ensure_ray(address)
    try:
        metrics = train_on_ray(cfg)
    finally:
        shutdown_ray()
    print(f"Ray Train job finished ({cfg.workers} workers); checkpoints in {cfg.out}"
          + (f"; last mean AP50 {metrics['mean_ap50']:.3f}" if "mean_ap50" in metrics else ""), file=sys.stderr)
    trainer = Trainer(cfg, data, build_model(cfg, data.names))
    trainer.restore(torch.load(Path(cfg.out) / "last.pt", weights_only=False))
    report = export_run(cfg, trainer, started)
    print(f"exported {report['export']['path']} (ONNX vs PyTorch max |diff| {report['export']['max_abs_diff']:.2g})")
    return 0
