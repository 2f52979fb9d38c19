#!/usr/bin/env python3
"""Pseudo-label a drone video for `aerodaas train detector`: every STEP-th frame of each shot, boxed by a detector
run at an enlarged input (slow, but it finds more of the far, small objects than the model will at its own input),
written as a YOLO folder whose ``labelled_classes.txt`` is empty, so training learns the boxes as objects but never
learns an unboxed object as background (the pseudo-labels miss many; ``docs/training.md``, "Your labels").

How the stage-4 candidate of ``docs/results/detection.md`` ("Stages 3 and 4") was made:

    python3 examples/training/pseudo_label_video.py uav-clips.mp4 OUT --model runs/v3/model.onnx \\
        --input 928x1600 --score 0.45 --step 5 --skip 0:30 --skip 1087:1162 --skip 1464:1539

(``runs/v3`` was that experiment's stage 3; without ``--model`` the shipped ``aerial_nano`` boxes the frames).

``--skip A:B`` leaves frames A..B-1 out (a shot kept for evaluation or tests, or a title). Shots are found where
the mean absolute difference of two consecutive 160x90 grey frames exceeds 25 (of 255). Only the classes ``--keep``
are written, under the model's own class names (from its metadata). Every option is checked before the video is
read: a bad one ends the script with exit 2, naming it and its value. Needs PyAV and OpenCV (installed with the
framework).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import av
import cv2
import numpy as np

from aerodaas.perception.detect import AerialDetector


def _options(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line, checked (``parser.error``: exit 2 naming the option and the value)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("video", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--model", type=Path, help="a YOLOX ONNX with class names in its metadata (default: aerial_nano)")
    ap.add_argument("--input", default="928x1600", help="detector input HxW, multiples of 32")
    ap.add_argument("--score", type=float, default=0.45)
    ap.add_argument("--step", type=int, default=5)
    ap.add_argument("--skip", action="append", default=[], metavar="A:B")
    ap.add_argument("--keep", nargs="+", default=["car", "large_vehicle"])
    a = ap.parse_args(argv)
    if not a.video.is_file():
        ap.error(f"video {str(a.video)!r}: no such file")
    if a.model is not None and not a.model.is_file():
        ap.error(f"--model {str(a.model)!r}: no such file")
    try:
        a.hw = tuple(int(v) for v in a.input.lower().split("x"))
    except ValueError:
        ap.error(f"--input {a.input!r} must be HxW, each a multiple of 32")
    try:
        a.skips = [tuple(int(v) for v in s.split(":")) for s in a.skip]
    except ValueError:
        ap.error(f"--skip {a.skip}: each must be A:B (frame numbers)")
    if len(a.hw) != 2 or min(a.hw) < 32 or any(v % 32 for v in a.hw):
        ap.error(f"--input {a.input!r} must be HxW, each a multiple of 32")
    if any(len(r) != 2 or not 0 <= r[0] < r[1] for r in a.skips):
        ap.error(f"--skip {a.skip}: each must be A:B with 0 <= A < B")
    if a.step < 1:
        ap.error(f"--step {a.step}: must be >= 1")
    if not 0.0 < a.score < 1.0:
        ap.error(f"--score {a.score}: must be within (0, 1)")
    return a


def main(argv: list[str] | None = None) -> None:
    a = _options(argv)
    det = AerialDetector(model_path=None if a.model is None else str(a.model), input_size=a.hw,
                         score_threshold=a.score)
    names = list(det.class_names)
    unknown = [k for k in a.keep if k not in names]
    if unknown:
        print(f"error: --keep {unknown}: not classes of the model (it has {names})", file=sys.stderr)
        sys.exit(2)
    (a.out / "images").mkdir(parents=True, exist_ok=True)
    (a.out / "labels").mkdir(exist_ok=True)
    (a.out / "classes.txt").write_text("\n".join(names) + "\n")
    (a.out / "labelled_classes.txt").write_text("")  # no class is boxed exhaustively
    shot, prev, n_img, n_box = 0, None, 0, 0
    with av.open(str(a.video)) as c:
        for i, frame in enumerate(c.decode(video=0)):
            im = frame.to_ndarray(format="bgr24")
            grey = cv2.resize(cv2.cvtColor(im, cv2.COLOR_BGR2GRAY), (160, 90)).astype(np.float32)
            if prev is not None and float(np.abs(grey - prev).mean()) > 25:
                shot = i
            prev = grey
            if any(lo <= i < hi for lo, hi in a.skips) or (i - shot) % a.step:
                continue
            h, w = im.shape[:2]
            stem = f"{a.video.stem}_shot{shot:05d}-{i:05d}"  # one shot = one sequence: split by shot, never by frame
            cv2.imwrite(str(a.out / "images" / f"{stem}.jpg"), im, [cv2.IMWRITE_JPEG_QUALITY, 95])
            lines = [f"{names.index(d.class_name)} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} "
                     f"{(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}"
                     for d in det.detect(im) if d.class_name in a.keep for x0, y0, x1, y1 in [d.box]]
            (a.out / "labels" / f"{stem}.txt").write_text("".join(ln + "\n" for ln in lines))
            n_img, n_box = n_img + 1, n_box + len(lines)
    print(f"{n_img} frames, {n_box} boxes in {a.out}")


if __name__ == "__main__":
    main()
