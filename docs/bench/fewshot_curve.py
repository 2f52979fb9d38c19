#!/usr/bin/env python3
"""The few-shot curve on AU-AIR's sample (docs/results/detection.md, "The few-shot curve"):
how many reviewed frames of one drone's flights does fine-tuning the shipped aerial model need to see that drone's
other flights? A benchmark helper, driven by ``docs/bench/fewshot_runs.sh``; production code never imports it.

Leave-flights-out: split ``A`` or ``B`` holds two of AU-AIR's 8 flights out as the test set; the other 6 flights
(60 frames) are the pool a user would label. ``run`` picks N frames of the pool (``uniform``: evenly over flights
and over time within a flight; ``ranked``: frames the shipped model is least sure of and unlike each other; both by the framework's own
selection, :func:`select`),
fine-tunes ``aerial_nano`` on them with ``aerodaas train detector`` (``--val``: a slice of the pool, never a test
flight), scores the result with ``aerodaas bench detect`` on the test flights (the options of
``docs/bench/detect46_runs.sh oblique2``), picks the best-F1 car threshold on the pool's frames that were NOT
selected, and writes one small JSON report (no per-detection curves) to ``docs/bench/fewshot_*.json``. Weights and
staged frames live in ``$FEWSHOT_CACHE`` (default ``~/.cache/aerodaas/fewshot``); ``clean`` deletes them.

AU-AIR (CC BY-NC-SA 2.0, non-commercial) is used for this measurement only: nothing trained here is kept.

    python docs/bench/fewshot_curve.py run --split A --n 20 --select uniform --seed 0 [--machine-boxed] [-- TRAIN...]
    python docs/bench/fewshot_curve.py rescore --tag A_uniform_n60_s0 --input 1088x1920   # before clean
    python docs/bench/fewshot_curve.py table          # the markdown table of every docs/bench/fewshot_*.json
    python docs/bench/fewshot_curve.py clean
"""
from __future__ import annotations

import argparse
import json
import hashlib
import os
import pickle
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SRC = Path(os.environ.get("AUAIR", Path.home() / ".cache/aerodaas/aerial/auair"))
CACHE = Path(os.environ.get("FEWSHOT_CACHE", Path.home() / ".cache/aerodaas/fewshot"))
OUT = REPO / "docs/bench"
SPLITS = {"A": ("20190905091750", "20190905111947"), "B": ("20190905103112", "20190905142119")}
NAMES = ["car", "large_vehicle", "person"]
BASE = "aerodaas/perception/models/aerial_nano.onnx"
INPUT = "736x1280"  # aerial_nano's own input (its imgsz metadata), as in detect46_runs.sh oblique2
THRESHOLDS = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6, 0.7]
TRAIN = ["--epochs", "2", "--tiles-per-epoch", "160", "--val-tiles", "32"]  # the short schedule (fewshot_runs.sh)


def flight(p: Path) -> str:
    """The flight of an AU-AIR frame ``frame_<flight start>_x_<n>.jpg``."""
    return p.name.split("_")[1]


def frame_no(p: Path) -> int:
    return int(p.stem.split("_")[-1])


def split_frames(split: str) -> tuple[dict[str, list[Path]], list[Path]]:
    """(pool: flight -> its frames by frame number, test frames) of ``split``."""
    pool: dict[str, list[Path]] = {}
    test = []
    for p in sorted((SRC / "images").glob("*.jpg")):
        if flight(p) in SPLITS[split]:
            test.append(p)
        else:
            pool.setdefault(flight(p), []).append(p)
    return {f: sorted(v, key=frame_no) for f, v in sorted(pool.items())}, test


class _CachedDetectors:
    """:class:`aerodaas.labelling.scoring.Detectors` whose two passes are cached on disk per image (the pool is
    scored once per split, not once per run)."""

    def __init__(self, dets) -> None:
        self.dets = dets

    def __getattr__(self, name):
        return getattr(self.dets, name)

    def detect(self, image: np.ndarray):
        key = CACHE / "dets" / (hashlib.sha1(image.tobytes()).hexdigest() + ".pkl")
        if key.is_file():
            return pickle.loads(key.read_bytes())
        out = self.dets.detect(image)
        key.parent.mkdir(parents=True, exist_ok=True)
        key.write_bytes(pickle.dumps(out))
        return out


def select(pool: dict[str, list[Path]], n: int, how: str, seed: int) -> list[Path]:
    """``n`` pool frames chosen by :func:`aerodaas.labelling.select.select_images` (the framework's selection for
    ``aerodaas label frames``, shipped aerial model against its enlarged-input pass, default weights): ``ranked``
    (informativeness and diversity) or ``uniform`` (evenly over flights and over time within a flight). Every pool
    frame is a candidate (``dedup_bits=0``: AU-AIR's frames are already sparse samples of each flight)."""
    from aerodaas.labelling.scoring import build_detectors
    from aerodaas.labelling.select import SelectOptions, select_images

    flat = [p for v in pool.values() for p in v]
    sel = select_images([str(p) for p in flat], [flight(p) for p in flat],
                        SelectOptions(budget=n, seed=seed, dedup_bits=0, uniform=how == "uniform"),
                        _CachedDetectors(build_detectors("aerial_nano", threads=1)))
    return [Path(c.ref.source) for c in sel.picked]


def link_set(dst: Path, frames: list[Path], labels: Path | None = None) -> Path:
    """A YOLO folder at ``dst``: ``frames`` linked into images/, their labels (from ``labels`` or AU-AIR's own)
    into labels/, and classes.txt."""
    shutil.rmtree(dst, ignore_errors=True)
    (dst / "images").mkdir(parents=True)
    (dst / "labels").mkdir()
    for p in frames:
        (dst / "images" / p.name).symlink_to(p)
        (dst / "labels" / f"{p.stem}.txt").symlink_to((labels or SRC / "labels") / f"{p.stem}.txt")
    (dst / "classes.txt").write_text("\n".join(NAMES) + "\n")
    return dst


def machine_box(dst: Path, frames: list[Path]) -> Path:
    """``frames`` boxed by the shipped model with the pseudo-labeller's recipe (examples/training/
    pseudo_label_video.py: input 928x1600, score >= 0.45, car and large vehicle) as a YOLO folder with an empty
    labelled_classes.txt (its boxes are learnt as objects, its misses never as background)."""
    import cv2
    from aerodaas.perception.detect import AerialDetector

    det = AerialDetector(input_size=(928, 1600), score_threshold=0.45, intra_op_threads=1)
    lab = dst.parent / (dst.name + "_labels")
    shutil.rmtree(lab, ignore_errors=True)
    lab.mkdir(parents=True)
    for p in frames:
        im = cv2.imread(str(p))
        h, w = im.shape[:2]
        lines = [f"{NAMES.index(d.class_name)} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} "
                 f"{(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}\n"
                 for d in det.detect(im) if d.class_name in ("car", "large_vehicle") for x0, y0, x1, y1 in [d.box]]
        (lab / f"{p.stem}.txt").write_text("".join(lines))
    link_set(dst, frames, lab)
    (dst / "labelled_classes.txt").write_text("")
    return dst


def bench(model: str | None, images: Path, out: Path, size: str = INPUT) -> dict:
    """``aerodaas bench detect`` on a YOLO folder with detect46_runs.sh oblique2's options (whole frame, 736x1280,
    every threshold of :data:`THRESHOLDS`), one thread under nice; the report without its PR curve."""
    cmd = ["nice", "-n", "5", "aerodaas", "bench", "detect", "--names", *NAMES, "--repeat", "1", "--sweep",
           "--thresholds", *map(str, THRESHOLDS), "--overlap", "0.2", "--threads", "1", "--tiles", "0",
           "--images", str(images / "images"), "--annotations", str(images / "labels"), "--classes", *NAMES,
           "--out", str(out)]
    cmd += ["--model", "aerial_nano"] if model is None else ["--model-path", model]
    cmd += ["--input-sizes", size] if model is not None or size != INPUT else []
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env={**os.environ, "OMP_NUM_THREADS": "1"})
    rep = json.loads(out.read_text())
    for r in rep["results"]:
        for c in r["classes"].values():
            c.pop("pr_curve@0.5", None)
        for k in [k for k in r if k not in ("input_size", "tile", "score_threshold", "ms_per_frame",
                                             "boxes_per_frame", "classes")]:
            r.pop(k)
    rep.pop("size_buckets_px2", None)
    return rep


def f1(c: dict, iou: str) -> float:
    r, p = c[f"recall@{iou}"], c[f"precision@{iou}"]
    return 2 * r * p / (r + p) if r + p else 0.0


def at(rep: dict, thr: float) -> dict:
    return next(r["classes"]["car"] for r in rep["results"] if abs(r["score_threshold"] - thr) < 1e-9)


def _epochs(train_report: dict) -> list[dict]:
    """Per epoch of a training run's report.json: loss, seconds and the validation car AP50 (tiles of --val)."""
    return [{"epoch": e["epoch"], "loss": round(e["loss"], 3), "train_s": round(e["train_s"]),
             "val_s": round(e["val_s"]), "val_car_ap50": round(next(m["ap50"] for m in e["metrics"]
                                                                   if m["name"] == "car"), 3)}
            for e in train_report.get("history", [])]


def run(a: argparse.Namespace) -> dict:
    """One point of the curve; returns (and writes) its report."""
    pool, test = split_frames(a.split)
    flat = [p for v in pool.values() for p in v]
    chosen = select(pool, a.n, a.select, a.seed) if 0 < a.n < len(flat) else flat if a.n else []
    rest = [p for p in flat if p not in chosen]
    tag = f"{a.split}_{a.select}_n{a.n}_s{a.seed}" + ("_mb" if a.machine_boxed else "") + (f"_{a.tag}" if a.tag else "")
    out = OUT / f"fewshot_{tag}.json"
    claim = CACHE / "claims" / tag
    claim.parent.mkdir(parents=True, exist_ok=True)
    try:  # several queues can run this same list side by side: each run is taken by one of them, done ones skipped
        os.close(os.open(claim, os.O_CREAT | os.O_EXCL))
    except FileExistsError:
        print(f"{tag}: taken or done, skipped")
        return {}
    if out.is_file():
        print(f"{tag}: {out} exists, skipped")
        return {}
    work = CACHE / tag
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    rep = {"benchmark": "fewshot", "split": a.split, "test_flights": list(SPLITS[a.split]), "n": a.n,
           "select": a.select, "seed": a.seed, "machine_boxed": a.machine_boxed, "tag": a.tag,
           "selected": sorted(p.name for p in chosen), "train": None}
    model = None
    if a.n:
        val = rest[:: max(1, len(rest) // 12)][:12] if rest else [v[len(v) // 2] for v in pool.values()]
        cmd = ["nice", "-n", "5", "aerodaas", "train", "detector", "--data", str(link_set(work / "train", chosen))]
        if a.machine_boxed and rest:
            cmd += ["--data", str(machine_box(work / "machine", rest))]
        cmd += ["--val", str(link_set(work / "val", val)), "--base-model", BASE, "--seed", str(a.seed),
                "--out", str(work / "run"), *(a.train or TRAIN)]
        t0 = time.time()
        log = (work / "train.log").open("w")
        subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT, cwd=REPO,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
        tr = json.loads((work / "run" / "report.json").read_text())
        rep["train"] = {"command": " ".join(c.replace(str(CACHE), "$FEWSHOT_CACHE") for c in cmd[3:]),
                        "wall_s": round(time.time() - t0, 1), "val_frames": len(val),
                        "val_is_training_frames": not rest,
                        "best_epoch": tr.get("best_epoch"), "epochs": _epochs(tr)}
        model = str(work / "run" / "model.onnx")
    rep["test"] = bench(model, link_set(work / "test", test), work / "test.json")
    if rest:
        pool_rep = bench(model, link_set(work / "rest", rest), work / "rest.json")
        pick = {}
        for iou in ("0.5", "0.3"):
            thr = max(THRESHOLDS, key=lambda t: (f1(at(pool_rep, t), iou), t))
            pick[iou] = {"threshold": thr, "pool_f1": round(f1(at(pool_rep, thr), iou), 3),
                         "test_car": at(rep["test"], thr)}
        rep["pool_frames_unselected"] = len(rest)
        rep["best_f1_on_pool"] = pick
    else:  # the whole pool trained on: how well the model fits its own frames (capacity and schedule, not data)
        fit = bench(model, link_set(work / "fit", chosen), work / "fit.json")
        rep["train_fit_car_at_0.3"] = at(fit, 0.3)
    rep["test_car_at_0.3"] = at(rep["test"], 0.3)
    for f in (work / "run").glob("*"):
        if f.suffix in (".pt", ".onnx"):
            f.unlink()  # throwaway weights (AU-AIR is non-commercial): scored, then gone
    out.write_text(json.dumps(rep, indent=1) + "\n")
    c = rep["test_car_at_0.3"]
    print(f"{tag}: car R/P@0.5 {c['recall@0.5']:.3f}/{c['precision@0.5']:.3f} @0.3 {c['recall@0.3']:.3f}/"
          f"{c['precision@0.3']:.3f} AP50 {c['ap50']:.3f} -> {out}")
    return rep


def rescore(a: argparse.Namespace) -> None:
    """A finished run's model (kept in CACHE/keep/<tag>.onnx; the shipped model for N=0) scored again on its test
    flights at another input size; written as fewshot_<tag>_in<size>.json (no threshold picked on the pool)."""
    src = json.loads((OUT / f"fewshot_{a.tag}.json").read_text())
    model = None if src["n"] == 0 else str(CACHE / "keep" / f"{a.tag}.onnx")
    work = CACHE / f"{a.tag}_in{a.input}"
    work.mkdir(parents=True, exist_ok=True)
    rep = {k: src[k] for k in ("benchmark", "split", "test_flights", "n", "select", "seed", "machine_boxed",
                               "selected", "train")}
    rep["tag"] = "+".join(t for t in (src.get("tag"), f"input {a.input}") if t)
    rep["test"] = bench(model, link_set(work / "test", split_frames(src["split"])[1]), work / "test.json", a.input)
    rep["test_car_at_0.3"] = at(rep["test"], 0.3)
    out = OUT / f"fewshot_{a.tag}_in{a.input}.json"
    out.write_text(json.dumps(rep, indent=1) + "\n")
    c = rep["test_car_at_0.3"]
    print(f"{out.name}: car R/P@0.5 {c['recall@0.5']:.3f}/{c['precision@0.5']:.3f} AP50 {c['ap50']:.3f}")


def _ms(v: list[float]) -> str:
    """mean ± half the range (over seeds and splits)."""
    if len(v) == 1:
        return f"{v[0]:.2f}"
    return f"{np.mean(v):.2f} ± {(max(v) - min(v)) / 2:.2f}"


def _cars(name: str) -> int:
    """Car boxes in AU-AIR's label of frame ``name`` (what a reviewer checked)."""
    f = SRC / "labels" / (Path(name).stem + ".txt")
    return sum(1 for ln in f.read_text().splitlines() if ln.split()[:1] == ["0"]) if f.is_file() else 0


def table(_: argparse.Namespace) -> None:
    """Markdown rows (N x selection x variant, mean ± half range over seeds/splits) of every fewshot_*.json."""
    reps = [json.loads(p.read_text()) for p in sorted(OUT.glob("fewshot_*.json"))]
    groups: dict[tuple, list] = {}
    for r in reps:
        sel = "shipped" if r["n"] == 0 else r["select"] + (" + machine-boxed rest" if r["machine_boxed"] else "")
        groups.setdefault((r["n"], sel, r.get("tag") or ""), []).append(r)
    print("| N | selection | runs (split, seed): AP50 | cars boxed in the N | score ≥ 0.3: R/P IoU 0.5 | R/P IoU 0.3 | AP50 | "
          "best-F1 thr on pool: R/P IoU 0.5 | R/P IoU 0.3 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (n, sel, tag), rs in sorted(groups.items(), key=lambda kv: (kv[0][2] != "", kv[0][0], kv[0][1], kv[0][2])):
        c = [r["test_car_at_0.3"] for r in rs]
        cars = [sum(_cars(f) for f in r["selected"]) for r in rs]
        row = [str(n), sel + (f" ({tag})" if tag else ""), ", ".join(f"{r['split']}{r['seed']} {r['test_car_at_0.3']['ap50']:.3f}" for r in rs),
               f"{np.mean(cars):.0f}",
               f"{_ms([x['recall@0.5'] for x in c])} / {_ms([x['precision@0.5'] for x in c])}",
               f"{_ms([x['recall@0.3'] for x in c])} / {_ms([x['precision@0.3'] for x in c])}",
               _ms([x["ap50"] for x in c])]
        for iou in ("0.5", "0.3"):
            b = [r["best_f1_on_pool"][iou] for r in rs if r.get("best_f1_on_pool")]
            row.append(f"{_ms([x['test_car'][f'recall@{iou}'] for x in b])} / "
                       f"{_ms([x['test_car'][f'precision@{iou}'] for x in b])} "
                       f"(thr {'/'.join(sorted({str(x['threshold']) for x in b}))})" if b else "—")
        print("| " + " | ".join(row) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--split", choices=sorted(SPLITS), required=True)
    r.add_argument("--n", type=int, required=True, choices=range(0, 61), metavar="0..60")
    r.add_argument("--select", choices=("uniform", "ranked"), default="uniform")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--machine-boxed", action="store_true", help="add the unselected pool frames, machine-boxed")
    r.add_argument("--tag", default="", help="suffix of the report name for a changed training schedule")
    r.add_argument("train", nargs="*", help="after --: aerodaas train detector options replacing the schedule")
    rs = sub.add_parser("rescore")
    rs.add_argument("--tag", required=True, help="a finished run, e.g. A_uniform_n60_s0")
    rs.add_argument("--input", required=True, help="HxW, e.g. 1088x1920")
    sub.add_parser("table")
    sub.add_parser("clean")
    a = ap.parse_args()
    if a.cmd == "run":
        if not (SRC / "images").is_dir():
            sys.exit(f"AU-AIR not staged at {SRC} (examples/training/prepare_aerial_data.py auair)")
        run(a)
    elif a.cmd == "rescore":
        rescore(a)
    elif a.cmd == "table":
        table(a)
    else:
        shutil.rmtree(CACHE, ignore_errors=True)


if __name__ == "__main__":
    main()
