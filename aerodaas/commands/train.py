"""``aerodaas train detector``: fine-tune the detector on labelled aerial imagery (yours or the project's) on the CPU,
or with ``--workers N`` as a Ray Train job on your cluster; export a checked ONNX file the analytics load by path.

Needs the ``[train]`` extra (PyTorch, CPU build: ``pip install -e ".[train]"``; docs/training.md). Exit codes: 0
trained and exported; 2 bad input (options, labels, a missing or unusable base model, a missing PyTorch), named
before anything trains; 1 the training or export failed.
"""
from __future__ import annotations

import argparse
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
    d.set_defaults(func=cmd_train_detector)


def cmd_train_detector(args: argparse.Namespace) -> int:
    """``aerodaas train detector``: :func:`aerodaas.commands.train_main.cmd_train_detector` (PyTorch, pydantic and
    the training code are imported there)."""
    from aerodaas.commands.train_main import cmd_train_detector as train  # lazy: CLI start-up (pydantic, training)

    return train(args)
