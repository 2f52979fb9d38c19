"""``aerodaas train detector``: fine-tune the detector on labelled aerial imagery (yours or the project's) on the CPU,
or with ``--workers N`` as a Ray Train job on your cluster; export a checked ONNX file the analytics load by path.

Needs the ``[train]`` extra (PyTorch, CPU build: ``pip install -e ".[train]"``; docs/training.md). Exit codes: 0
trained and exported; 2 bad input (options, labels, a missing or unusable base model, a missing PyTorch), named
before anything trains; 1 the training or export failed. Handler: :func:`run_detector`; the work is in
:mod:`aerodaas.training` (PyTorch, pydantic and the training code are imported when it runs).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def add_parser(sub) -> None:
    """Register ``train detector`` on the CLI's sub-parsers ``sub``."""
    tp = sub.add_parser("train", help="train or fine-tune a model on labelled imagery (needs the [train] extra)")
    tsub = tp.add_subparsers(dest="what", required=True)
    d = tsub.add_parser("detector", help="fine-tune the YOLOX detector on YOLO-txt or COCO-JSON labels, export ONNX")
    d.add_argument("--data", action="append", required=True, type=Path, metavar="DIR",
                   help="a labelled set: a YOLO folder (images/, labels/, classes.txt) or a COCO .json; repeat for "
                        "several sets (each drawn equally often unless --no-balance)")
    d.add_argument("--val", action="append", default=[], type=Path, metavar="DIR",
                   help="a held-out set (repeatable); default: --val-fraction of --data, split by video/sequence")
    d.add_argument("--val-fraction", type=float, default=0.15)
    d.add_argument("--names", help="class names in label order, comma-separated (default: the set's own)")
    d.add_argument("--base-model", type=Path, metavar="FILE|NAME",
                   help="YOLOX ONNX file (or model name: aerial_nano, yolox_nano) to start from (default: the shipped "
                        "aerial model, aerial_nano, when every class is one of its car, large_vehicle, person; else "
                        "the COCO YOLOX-Nano, yolox_nano)")
    d.add_argument("--init-from", action="append", default=[], metavar="CLASS=BASECLASS",
                   help="start a class from the base model's class row (default: same name or a COCO alias)")
    d.add_argument("--out", type=Path, default=Path("runs/detector"), help="run folder (checkpoints, model.onnx)")
    d.add_argument("--epochs", type=int, default=30)
    d.add_argument("--tiles-per-epoch", type=int, default=800)
    d.add_argument("--batch", type=int, default=8)
    d.add_argument("--lr", type=float, default=1e-3)
    d.add_argument("--tile", type=int, default=416, help="training tile size in pixels (multiple of 32)")
    d.add_argument("--object-px", type=float, nargs=2, default=(8.0, 96.0), metavar=("MIN", "MAX"),
                   help="the size range (pixels) a training tile's median object is scaled into, log-uniformly: "
                        "the altitudes your camera flies at (default 8 96)")
    d.add_argument("--oblique", type=float, default=0.3, metavar="P",
                   help="share of training tiles (0 to 1, default 0.3) warped to an oblique view (the camera "
                        "pitched towards the horizon)")
    d.add_argument("--val-tiles", type=int, default=300)
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    d.add_argument("--quantize", action="store_true",
                   help="also write an int8 model, kept only if no class loses more than 2 points of recall")
    d.add_argument("--workers", type=int, default=0,
                   help="run as a Ray Train job with N workers on the Ray cluster (0: this process)")
    d.add_argument("--gpu", action="store_true", help="with --workers: one GPU per worker")
    d.add_argument("--address", help="with --workers: the Ray cluster to join (default: aerodaas up, else local)")
    d.add_argument("--max-steps", type=int, help="stop after this many optimiser steps (smoke runs)")
    d.add_argument("--no-balance", action="store_true", help="draw images uniformly instead of set by set")
    d.set_defaults(func=run_detector)


def _config(args: argparse.Namespace):
    """The options as a :class:`~aerodaas.training.config.TrainConfig`. Raises ValueError naming the option and
    its value."""
    from pydantic import ValidationError  # lazy: CLI start-up (pydantic)

    from aerodaas.training.config import TrainConfig  # lazy: CLI start-up (pydantic)

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


def run_detector(args: argparse.Namespace) -> int:
    """``aerodaas train detector``: check the options, the labels (:func:`aerodaas.training.sets.load_training_data`)
    and the base model (:func:`aerodaas.training.base.choose_base`), exit 2 naming the problem (a missing base model
    with where it was looked for); then train here (:func:`aerodaas.training.progress.train_with_progress`) or as a
    Ray Train job (:func:`aerodaas.training.distributed.train_on_ray`), export, and print where the model is."""
    from aerodaas.perception.model_files import ModelNotFoundError  # lazy: CLI start-up (the model files)
    from aerodaas.training.base import choose_base  # lazy: CLI start-up (pydantic, the training)
    from aerodaas.training.labels.check import LabelError  # lazy: CLI start-up (the label readers)
    from aerodaas.training.sets import load_training_data  # lazy: CLI start-up (cv2, numpy, pydantic)

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
    """Train in this process under a progress bar; print the exported model and its metrics."""
    from aerodaas.training.progress import train_with_progress  # lazy: CLI start-up (rich, the training)

    report = train_with_progress(cfg, data)
    exp = report["export"]
    print(f"exported {exp['path']} ({exp['size_bytes'] / 2**20:.2f} MiB, ONNX vs PyTorch max |diff| "
          f"{exp['max_abs_diff']:.2g}); {report['int8_note']}; report: {Path(cfg.out) / 'report.json'}")
    for m in exp["metrics"]:
        print(f"  {m['name']:>14}: recall {m['recall']:.3f} precision {m['precision']:.3f} AP50 {m['ap50']:.3f} "
              f"({m['n_gt']} boxes)")
    return 0


def _on_ray(cfg, data, address: str | None) -> int:
    """Train as a Ray Train job on the cluster at ``address`` (None: ``aerodaas up``'s, else a local Ray), then
    export its checkpoints here; print where the model is."""
    from aerodaas.runtime.ray_start import ensure_ray, shutdown_ray  # lazy: CLI start-up (the runtime)
    from aerodaas.training.distributed import train_on_ray  # lazy: optional dependency (PyTorch)
    from aerodaas.training.session import export_checkpoints  # lazy: optional dependency (PyTorch)

    started = time.monotonic()
    ensure_ray(address)
    try:
        metrics = train_on_ray(cfg)
    finally:
        shutdown_ray()
    print(f"Ray Train job finished ({cfg.workers} workers); checkpoints in {cfg.out}"
          + (f"; last mean AP50 {metrics['mean_ap50']:.3f}" if "mean_ap50" in metrics else ""), file=sys.stderr)
    report = export_checkpoints(cfg, data, started)
    print(f"exported {report['export']['path']} (ONNX vs PyTorch max |diff| {report['export']['max_abs_diff']:.2g})")
    return 0
