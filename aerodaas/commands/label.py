"""``aerodaas label ...``: turn your own footage into labelled frames. ``label frames`` picks the frames worth
labelling out of recordings (``aerodaas run --record``) and videos within a budget and writes them with the shipped
detector's boxes as pre-labels (Label Studio tasks, CVAT XML, COCO JSON; docs/training.md, "Frames worth
labelling"). ``push``, ``pull`` and ``serve`` carry the frames and pre-labels to a Label Studio project and the
reviewed boxes back as training sets (:mod:`aerodaas.commands.label_studio`). Exit codes: 0 written; 2 bad input
(files, options, classes), named before anything is written; 1 the run failed (nothing is left half-written).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from aerodaas.commands.label_studio import add_label_studio_parsers


def add_parser(sub) -> None:
    """Register the ``label`` group and its sub-command ``frames`` on the CLI's sub-parsers ``sub``; more
    sub-commands go on the ``what`` sub-parsers the same way."""
    lp = sub.add_parser("label", help="label your own footage: pick frames, Label Studio push, pull and serve")
    what = lp.add_subparsers(dest="what", required=True)
    _add_frames(what)
    add_label_studio_parsers(what)


def _add_frames(what) -> None:
    f = what.add_parser("frames", help="frames worth labelling out of recordings and videos, with pre-labels")
    f.add_argument("inputs", nargs="+", type=Path, metavar="RUN.mcap|VIDEO",
                   help="MCAP recordings (aerodaas run --record) and video files; each file is one flight, "
                        "named by its stem")
    f.add_argument("--budget", type=int, required=True, help="frames to pick in all")
    f.add_argument("--out", type=Path, required=True, help="output folder (new or empty)")
    f.add_argument("--held-out", action="append", default=[], metavar="FLIGHT",
                   help="a flight (file stem) never drawn from, kept for evaluation (repeatable)")
    f.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    f.add_argument("--classes", help="classes to pre-label, comma-separated (default: all of the model's)")
    f.add_argument("--model", default="aerial_nano", help="detector name or YOLOX .onnx path (default aerial_nano)")
    f.add_argument("--per-flight-quota", type=int, metavar="Q", help="at most Q frames from one flight")
    f.add_argument("--uniform", action="store_true",
                   help="evenly spaced frames (same budget and quotas) instead of the ranked choice")
    f.add_argument("--rate", type=float, default=1.0, help="candidate frames per second of footage, at most (1)")
    f.add_argument("--dedup-bits", type=int, default=6,
                   help="a frame within this many bits of difference hash of the previous candidate is a "
                        "near-duplicate (0-64, default 6)")
    f.add_argument("--score", type=float, default=0.3, help="detector score threshold of the pre-labels (0.3)")
    f.add_argument("--margin", type=float, default=0.15,
                   help="detections within this of --score count as uncertain (0.15)")
    f.add_argument("--strong", choices=("enlarged", "tiles"), default="enlarged",
                   help="the stronger pass: the model at 1.5x its input, or 640 px tiles (default enlarged)")
    f.add_argument("--pool-factor", type=int, default=3,
                   help="frames scored per frame picked, spread by appearance (default 3)")
    f.add_argument("--diversity-weight", type=float, default=0.5,
                   help="weight of appearance diversity against informativeness, 0-1 (0.5)")
    f.add_argument("--document-root", type=Path,
                   help="Label Studio's LOCAL_FILES_DOCUMENT_ROOT the task image URLs are relative to "
                        "(default: the parent of --out)")
    f.add_argument("--threads", type=int, default=1, help="onnxruntime threads (default 1)")
    f.set_defaults(func=cmd_label_frames)


def cmd_label_frames(args: argparse.Namespace) -> int:
    """``aerodaas label frames``: :func:`aerodaas.commands.label_main.cmd_label_frames` (OpenCV, PyAV, MCAP and
    onnxruntime are imported there)."""
    from aerodaas.commands.label_main import cmd_label_frames as run  # lazy: CLI start-up (cv2, av, onnxruntime)

    return run(args)
