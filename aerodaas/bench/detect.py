"""``aerodaas bench detect``: score a detector configuration on an annotated image set (issue 28, item 5).

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
import sys
import time
from pathlib import Path

from aerodaas.bench import machine_info


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
    from aerodaas.bench.detect_breakdown import breakdown
    from aerodaas.perception.scoring import score

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
    import cv2
    import os
    from rich.progress import Progress

    from aerodaas.perception.breakdown import SIZE_BUCKETS, frame_meta
    from aerodaas.perception.options import build_detector
    from aerodaas.perception.scoring import load_annotations
    from aerodaas.perception.tiling import TiledDetector, Tiling

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
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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


def add_parser(sub: argparse._SubParsersAction) -> None:
    from aerodaas.perception.breakdown import FRAME_META_SOURCES

    p = sub.add_parser("detect", help="score a detector on annotated images (COCO JSON or YOLO txt): recall/precision, "
                                      "AP50, ms/frame; --sweep over input size, tiling, threshold")
    p.add_argument("--images", required=True, help="folder of the images")
    p.add_argument("--annotations", required=True,
                   help="COCO .json file, folder of YOLO .txt labels, or VisDrone-DET annotations folder")
    p.add_argument("--annotation-format", default="auto", choices=["auto", "coco", "yolo", "visdrone"],
                   help="auto: a .json file is COCO, a folder YOLO; visdrone: a VisDrone-DET annotations folder")
    p.add_argument("--names", nargs="+", help="class names of YOLO labels (else classes.txt in the label folder)")
    p.add_argument("--model", default="yolox_nano", help="shipped model name (yolox_nano, nanodet_plus_m_416)")
    p.add_argument("--model-path", help="bring your own ONNX model")
    p.add_argument("--format", default="auto", choices=["auto", "yolox", "nanodet", "ultralytics"])
    p.add_argument("--classes", nargs="+", help="classes to score (default: those annotated)")
    p.add_argument("--group", action="append",
                   help="NAME=a,b,c: score annotated and detected classes a, b, c as one class NAME (e.g. "
                        "vehicle=car,truck,bus,minibus: a car the model calls a truck is found); repeatable")
    p.add_argument("--thresholds", nargs="+", type=float, default=[0.15])
    p.add_argument("--input-sizes", nargs="+", default=["0"],
                   help="input sizes for a dynamic-axes model: N (N x N) or HxW pixels (0: the model's own)")
    p.add_argument("--tiles", nargs="+", type=int, default=[0], help="tile sizes in pixels (0: whole frame)")
    p.add_argument("--overlap", type=float, default=0.2)
    p.add_argument("--merge", default="greedynmm", choices=["nms", "greedynmm"])
    p.add_argument("--no-full-frame", action="store_true", help="tiles only, without the whole frame")
    p.add_argument("--agnostic-nms", action="store_true")
    p.add_argument("--sweep", action="store_true", help="every combination of sizes, tiles and thresholds")
    p.add_argument("--threads", type=int, default=1,
                   help="onnxruntime intra-op threads (1: on a shared, loaded machine 2 threads spin and run slower)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per frame (the median is kept)")
    p.add_argument("--frame-width", type=int, default=0,
                   help="resize each image to this width first (e.g. 1920), boxes scaled alike (0: as stored)")
    p.add_argument("--limit", type=int, default=0, help="score only the first N annotated images")
    p.add_argument("--frame-meta", default="auto", choices=list(FRAME_META_SOURCES),
                   help="per-frame view angle and altitude for the breakdowns: hit-uav (from HIT-UAV file names "
                        "T_H_A_S_N.jpg), auto (hit-uav when every file name has that form), none")
    p.add_argument("--out", help="write the JSON report here")
    p.add_argument("--plot", help="write the PR-curve PNG here")
    p.add_argument("--json", action="store_true", help="print the JSON report")

    def run(a: argparse.Namespace) -> int:
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
        from aerodaas.bench.detect_breakdown import breakdown_lines
        from aerodaas.bench.output import print_report

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

    p.set_defaults(func=run)
