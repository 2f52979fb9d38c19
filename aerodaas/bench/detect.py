"""``aerodaas bench detect``: score a detector configuration on an annotated image set.

Per class: recall and precision at IoU 0.5 and 0.3, AP50 (:mod:`aerodaas.perception.scoring`); per frame: ms (wall
time of ``detect``, onnxruntime on ``--threads`` threads) and boxes. ``--sweep`` runs every combination of
``--input-sizes`` (for a model with dynamic axes), ``--tiles`` (0: no tiling) and ``--thresholds``; a threshold
sweep reuses the detections at the lowest threshold (filtering by score gives exactly what a higher threshold
would). Every row also breaks the scores down by object size and, where the set records it, by view angle and
altitude (:mod:`aerodaas.bench.detect_breakdown`). JSON out (``--out``), a PR-curve PNG (``--plot``), a rich
progress bar.

Example (our own hand-made annotations of three shared photos, ``tests/data/brighton_beach_cars.json``)::

    aerodaas bench detect --images $AERODAAS_DATA_DIR/imagery/brighton_beach \\
        --annotations tests/data/brighton_beach_cars.json --classes car --sweep --tiles 0 640 960 \\
        --thresholds 0.1 0.15 0.2 0.3 --out detect.json --plot detect_pr.png
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path

from rich.progress import Progress

from aerodaas.bench.detect_breakdown import breakdown, breakdown_lines
from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import print_report
from aerodaas.perception.breakdown import SIZE_BUCKETS, frame_meta
from aerodaas.perception.options import build_detector
from aerodaas.perception.scoring import load_annotations, score
from aerodaas.perception.tiling import TiledDetector, Tiling


def _configs(a: argparse.Namespace) -> list[dict]:
    sizes = a.input_sizes if a.sweep else a.input_sizes[:1]
    tiles = a.tiles if a.sweep else a.tiles[:1]
    return [{"input_size": s, "tile": t} for s, t in itertools.product(sizes, tiles)]


def parse_groups(specs: list[str] | None) -> dict[str, str]:
    """``["vehicle=car,truck,bus"]`` -> ``{"car": "vehicle", "truck": "vehicle", "bus": "vehicle"}``: each member
    class (annotated or detected) is scored as the group. Raises ValueError naming a malformed spec."""
    out: dict[str, str] = {}
    for spec in specs or []:
        name, _, members = spec.partition("=")
        names = [m.strip() for m in members.split(",") if m.strip()]
        if not name.strip() or not names:
            raise ValueError(f"--group {spec!r}: expected NAME=class,class,...")
        out.update({m: name.strip() for m in names})
    return out


def parse_input_size(size: str | int) -> tuple[int, int] | None:
    """``--input-sizes`` item: ``0`` (the model's own), ``N`` (N x N) or ``HxW`` pixels -> (H, W) or None. Raises
    ValueError naming the value."""
    text = str(size).lower()
    try:
        if "x" in text:
            h, w = (int(v) for v in text.split("x"))
            return (h, w)
        n = int(text)
    except ValueError:
        raise ValueError(f"--input-sizes {size!r}: expected N or HxW pixels") from None
    return (n, n) if n else None


def _relabel(dets: list, group_of: dict[str, str]) -> list:
    return [d.model_copy(update={"class_name": group_of[d.class_name]}) if d.class_name in group_of else d
            for d in dets]


def _score_row(per: list, thr: float, with_curve: bool, classes: list[str], metas: dict, row: dict) -> dict:
    """One result row: ``row`` (configuration fields) plus boxes per frame, per-class scores of the detections at
    score >= ``thr`` (the PR curve when ``with_curve``) and the breakdowns (:mod:`aerodaas.bench.detect_breakdown`)."""
    kept = [([d for d in ds if d.score >= thr], g) for ds, g in per]
    row = {**row, "boxes_per_frame": round(sum(len(d) for d, _ in kept) / len(kept), 2), "classes": {}}
    for c in classes:
        s5, s3 = score(kept, c, 0.5), score(kept, c, 0.3)
        row["classes"][c] = {"n_gt": s5.n_gt, "n_det": s5.n_det, "recall@0.5": round(s5.recall, 3),
                             "precision@0.5": round(s5.precision, 3), "recall@0.3": round(s3.recall, 3),
                             "precision@0.3": round(s3.precision, 3), "ap50": round(s5.ap, 3)}
        if with_curve:
            row["classes"][c]["pr_curve@0.5"] = {"recall": s5.curve_recall, "precision": s5.curve_precision}
    row.update(breakdown(kept, classes, metas))
    return row


def run_detect(a: argparse.Namespace) -> dict:
    """Run the benchmark described by the parsed arguments; returns the JSON report (dict)."""
    import cv2  # lazy: heavy dependency (OpenCV)

    gts = load_annotations(a.annotations, a.images, a.names, a.annotation_format)
    group_of = parse_groups(a.group)
    for g in gts:
        g.classes = [group_of.get(c, c) for c in g.classes]
    if a.limit:
        gts = gts[:a.limit]
    classes = a.classes or sorted({c for g in gts for c in g.classes})
    metas = frame_meta([g.file for g in gts], a.frame_meta)
    thresholds = sorted(a.thresholds if a.sweep else a.thresholds[:1])
    configs = _configs(a)
    images = {}
    load_start = os.getloadavg()[0]
    results = []
    with Progress(transient=not sys.stderr.isatty()) as prog:
        task = prog.add_task("detect", total=len(configs) * len(gts))
        for cfg in configs:
            size = cfg["input_size"]
            det = build_detector(a.model if not a.model_path else "yolox_nano", model_path=a.model_path,
                                 format=a.format, score_threshold=min(thresholds),
                                 classes=None if group_of else classes,
                                 intra_op_threads=a.threads, agnostic_nms=a.agnostic_nms,
                                 input_size=parse_input_size(size))
            if cfg["tile"]:
                det = TiledDetector(det, Tiling(tile=cfg["tile"], overlap=a.overlap, full_frame=not a.no_full_frame,
                                                merge=a.merge))
            per, ms = [], []
            for g in gts:
                if g.file not in images:
                    im = cv2.imread(str(Path(a.images) / g.file))
                    if im is None:
                        raise ValueError(f"image {Path(a.images) / g.file} cannot be read")
                    if a.frame_width and im.shape[1] != a.frame_width:  # as a camera of that width would see it
                        f = a.frame_width / im.shape[1]
                        im = cv2.resize(im, (a.frame_width, int(round(im.shape[0] * f))), interpolation=cv2.INTER_AREA)
                        g.boxes = g.boxes * f
                    images[g.file] = im
                det.detect(images[g.file])  # warm-up run is not timed (first call allocates)
                runs = []
                for _ in range(max(1, a.repeat)):
                    t0 = time.perf_counter()
                    dets = det.detect(images[g.file])
                    runs.append((time.perf_counter() - t0) * 1e3)
                ms.append(sorted(runs)[len(runs) // 2])  # median of the repeats: less of the neighbours' load
                per.append((_relabel(dets, group_of), g))
                prog.update(task, advance=1, description=f"size {size if size != '0' else 'model'} tile {cfg['tile'] or '-'}")
            for thr in thresholds:
                results.append(_score_row(per, thr, thr == thresholds[0], classes, metas,
                                          {"input_size": list(getattr(det, "input_hw", ())), "tile": cfg["tile"],
                                           "score_threshold": thr, "ms_per_frame": round(sum(ms) / len(ms), 1)}))
    return {"benchmark": "detect", "machine": machine_info(), "load_avg_1min_start": round(load_start, 2),
            "load_avg_1min_end": round(os.getloadavg()[0], 2), "images": str(a.images),
            "annotations": str(a.annotations), "n_images": len(gts), "model": a.model_path or a.model,
            "threads": a.threads, "repeat": a.repeat, "frame_width": a.frame_width or None, "overlap": a.overlap,
            "merge": a.merge, "full_frame": not a.no_full_frame, "groups": a.group or [],
            "agnostic_nms": a.agnostic_nms, "frame_meta": a.frame_meta if metas else "none",
            "size_buckets_px2": {n: [lo, None if hi == float("inf") else hi] for n, lo, hi in SIZE_BUCKETS},
            "results": results}


def best(report: dict, cls: str, min_precision: float, max_ms: float) -> dict | None:
    """The configuration with the highest ``recall@0.5`` of ``cls`` at ``precision@0.5 >= min_precision`` within
    ``max_ms`` per frame (None if none qualifies)."""
    ok = [r for r in report["results"] if cls in r["classes"] and r["classes"][cls]["precision@0.5"] >= min_precision
          and r["ms_per_frame"] <= max_ms]
    return max(ok, key=lambda r: (r["classes"][cls]["recall@0.5"], -r["ms_per_frame"]), default=None)


def plot_pr(report: dict, path: str) -> None:
    """PR curves (IoU 0.5) of each configuration at its lowest threshold, one panel per class, to a PNG."""
    import matplotlib  # lazy: heavy dependency (matplotlib)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: heavy dependency (matplotlib)

    rows = [r for r in report["results"] if any("pr_curve@0.5" in c for c in r["classes"].values())]
    classes = sorted({c for r in rows for c in r["classes"]})
    fig, axes = plt.subplots(1, len(classes), figsize=(5 * len(classes), 4), squeeze=False)
    for ax, c in zip(axes[0], classes):
        for r in rows:
            cur = r["classes"][c]["pr_curve@0.5"]
            ax.plot(cur["recall"], cur["precision"], label=f"in {r['input_size']} tile {r['tile'] or '-'} "
                                                           f"({r['ms_per_frame']:.0f} ms)")
        ax.set(title=f"{c} (IoU 0.5)", xlabel="recall", ylabel="precision", xlim=(0, 1), ylim=(0, 1.02))
        ax.legend(fontsize=7)
    fig.suptitle(f"{report['model']} on {report['n_images']} images, load {report['load_avg_1min_start']}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench detect`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    for t in a.thresholds:
        if not 0.0 <= t <= 1.0:
            print(f"aerodaas bench detect: --thresholds must be within [0, 1], got {t}", file=sys.stderr)
            return 2
    if not Path(a.images).is_dir():
        print(f"aerodaas bench detect: --images {a.images!r} is not a folder", file=sys.stderr)
        return 2
    try:
        report = run_detect(a)
    except (ValueError, FileNotFoundError) as e:
        print(f"aerodaas bench detect: {e}", file=sys.stderr)
        return 2
    text = json.dumps(report, indent=1)
    if a.out:
        Path(a.out).write_text(text)
    if a.plot:
        plot_pr(report, a.plot)

    lines = [f"size {r['input_size']} tile {r['tile'] or '-'} thr {r['score_threshold']}: "
             + " ".join(f"{c}: R {v['recall@0.5']:.2f} P {v['precision@0.5']:.2f} AP50 {v['ap50']:.2f}"
                        for c, v in r["classes"].items())
             + f" | {r['ms_per_frame']:.0f} ms/frame, {r['boxes_per_frame']} boxes/frame"
             + "".join("\n" + ln for ln in breakdown_lines(r))
             for r in report["results"]]
    lines.append(f"load average (1 min) {report['load_avg_1min_start']} -> {report['load_avg_1min_end']}")
    if a.json:  # the summary is for people: on stderr, so stdout is the JSON document alone
        print_report(text)
        print("\n".join(lines), file=sys.stderr)
    else:
        print_report("\n".join(lines))
    return 0
