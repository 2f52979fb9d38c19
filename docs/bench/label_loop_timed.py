"""The labelling loop timed on a simulated 10-minute recording: `aerodaas label frames` (60 frames) -> a real Label
Studio on loopback (`label push`, the scripted review, `label pull`) -> `aerodaas train detector` -> `aerodaas
bench detect` on a held-out flight (shipped model against the fine-tuned one) -> the app with the new model.

The flights are docs/bench/label_loop_app.py's (four simulated cars over the packaged Brighton-beach ground), made
first and not timed here (their flight time is not part of the loop):

    cd ~/.cache/aerodaas/loop
    LOOP_MINUTES=10 aerodaas run REPO/docs/bench/label_loop_app.py --record flight10.mcap --speedup 10
    LOOP_MINUTES=2 LOOP_ALTITUDES=20 LOOP_COLUMNS=1 aerodaas run REPO/docs/bench/label_loop_app.py --record heldout.mcap --speedup 10
    python REPO/docs/bench/label_loop_timed.py flight10.mcap heldout.mcap work [--out REPO/docs/results/label_loop_timed.json]

The held-out flight is given to `label frames` as `--held-out` (never read) and scored on frames whose boxes come
from the simulator's own truth (``/world/targets``: the cars it drew; the ground photo's own people and objects
are not boxed, so precision counts them as false). The review is scripted as in label_walkthrough.py: each task's
pre-labels submitted as the reviewer's answer (a person's review time is not measured). Training runs the few-shot
curve's ``fit200`` schedule (10 epochs of 160 tiles, 200 steps of 8; docs/results/detection.md), at normal priority.
Every step's seconds and the 1-minute load at its start and end go to the JSON. Needs Label Studio in its venv
(tests/install-rig.sh) and PyTorch. Nothing here is imported by the framework.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(BENCH))
from label_walkthrough import review, timed  # noqa: E402  the walkthrough's reviewer and step timer
from tests.labelling.label_studio_server import start, stop  # noqa: E402  the tests' own server start

from aerodaas.labelling.sources import McapSource  # noqa: E402
from aerodaas.perception.boxes import iou_matrix  # noqa: E402
from aerodaas.recording.metrics import load_run, tracking_metrics  # noqa: E402
from aerodaas.recording.reader import read_messages  # noqa: E402

TRAIN = ["--tiles-per-epoch", "160", "--val-tiles", "32"]  # with --epochs 10: fit200 (module docstring)
REVIEW = "review (scripted: pre-labels submitted; not in the total)"
HELD_OUT_EVERY = 10  # one held-out frame a second of the 10 fps camera


def load1() -> float:
    """The machine's 1-minute load average."""
    return round(os.getloadavg()[0], 2)


class Steps(dict):
    """Step name -> {"seconds", "load_1min": [start, end], ...}: the JSON's ``steps``, saved to ``path`` after
    each step (``--resume`` reads them back)."""

    path: Path | None = None

    def __setitem__(self, name: str, value: dict) -> None:
        super().__setitem__(name, value)
        if self.path is not None:
            self.path.write_text(json.dumps(self, indent=1) + "\n")

    def run(self, name: str, argv: list, **kw) -> subprocess.CompletedProcess:
        """``argv`` timed by label_walkthrough.timed, with the load at its start and end."""
        l0 = load1()
        r = timed(self, name, [str(a) for a in argv], **kw)
        self[name]["load_1min"] = [l0, load1()]
        return r

    def block(self, name: str, fn, *args, **kw):
        """``fn(*args, **kw)`` timed in this process, with the load at its start and end."""
        l0, t0 = load1(), time.monotonic()
        out = fn(*args, **kw)
        self[name] = {"seconds": round(time.monotonic() - t0, 1), "load_1min": [l0, load1()]}
        print(f"{name}: {self[name]['seconds']} s", flush=True)
        return out


def truth_boxes(recording: Path) -> tuple[McapSource, dict[int, list[dict]]]:
    """The recording's camera source and, by the camera's frame log time (ns), the simulated targets it saw
    (``/world/targets`` entries with ``in_view``; the camera writes each frame's truth at the frame's own time)."""
    seen = {t_ns: [g for g in m["targets"] if g.get("in_view")]
            for _t, _s, t_ns, m in read_messages(str(recording), topics=["/world/targets"])}
    return McapSource(recording), seen


def held_out_set(recording: Path, out: Path) -> dict:
    """Every HELD_OUT_EVERY-th frame of ``recording`` in which every simulated car the camera sees is wholly in
    view (at least one), as a YOLO folder ``out/{images,labels}`` of class ``car`` boxed by the simulator's truth."""
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(exist_ok=True)
    (out / "labels" / "classes.txt").write_text("car\n")
    src, truth = truth_boxes(recording)
    kept = boxes = 0
    for ref, img in src.frames(lambda r: r.index % HELD_OUT_EVERY == 0):
        seen = truth[src.start_ns + round(ref.t_s * 1e9)]
        if not seen or not all(g.get("fully_in_view") for g in seen):
            continue
        h, w = img.shape[:2]
        cv2.imwrite(str(out / "images" / f"{ref.name}.jpg"), img)
        rows = [f"0 {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} {(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}"
                for x0, y0, x1, y1 in (g["bbox_px"] for g in seen)]
        (out / "labels" / f"{ref.name}.txt").write_text("\n".join(rows) + "\n")
        kept, boxes = kept + 1, boxes + len(rows)
    return {"frames": kept, "cars": boxes, "every_nth_frame": HELD_OUT_EVERY}


def prelabels_against_truth(recording: Path, frames: Path) -> dict:
    """The pre-labels ``label frames`` wrote (``frames/selection.json``, ``frames/coco.json``) against the cars the
    simulator drew in those frames (every ``in_view`` car, its box clipped to the frame), matched at IoU >= 0.5:
    what the scripted review, which accepts them all, taught the model."""
    sel = json.loads((frames / "selection.json").read_text())["frames"]
    coco = json.loads((frames / "coco.json").read_text())
    ids = {im["file_name"].split("/")[-1]: im["id"] for im in coco["images"]}
    by_image: dict[int, list] = {}
    for an in coco["annotations"]:
        x, y, w, h = an["bbox"]
        by_image.setdefault(an["image_id"], []).append([x, y, x + w, y + h])
    src, truth = truth_boxes(recording)
    want = {f["frame"]: f["file"].split("/")[-1] for f in sel}
    n_pred = n_true = hit_pred = hit_true = 0
    for ref, _img in src.frames(lambda r: r.index in want):
        gt = np.array([g["bbox_px"] for g in truth[src.start_ns + round(ref.t_s * 1e9)]], np.float32).reshape(-1, 4)
        pr = np.array(by_image.get(ids[want[ref.index]], []), np.float32).reshape(-1, 4)
        n_pred, n_true = n_pred + len(pr), n_true + len(gt)
        if len(pr) and len(gt):
            ok = iou_matrix(pr, gt) >= 0.5
            hit_pred, hit_true = hit_pred + int(ok.any(1).sum()), hit_true + int(ok.any(0).sum())
    return {"frames": len(want), "prelabel_boxes": n_pred, "simulated_cars_in_view": n_true,
            "prelabels_on_a_car": hit_pred, "cars_with_a_prelabel": hit_true,
            "precision": round(hit_pred / n_pred, 3) if n_pred else None,
            "recall": round(hit_true / n_true, 3) if n_true else None}


def summary(bench: dict) -> dict:
    """The car row of an `aerodaas bench detect` report, without its precision-recall curve."""
    row = bench["results"][0]
    car = {k: v for k, v in row["classes"]["car"].items() if not k.startswith("pr_curve")}
    return {"input_size": row["input_size"], "score_threshold": row["score_threshold"],
            "ms_per_frame": row["ms_per_frame"], **car}


def machine() -> dict:
    """CPUs, memory, PyTorch and onnxruntime versions of this machine."""
    mem = next(int(x.split()[1]) for x in Path("/proc/meminfo").read_text().splitlines() if x.startswith("MemTotal"))
    torch = subprocess.run([sys.executable, "-c", "import torch; print(torch.__version__)"], capture_output=True,
                           text=True).stdout.strip()
    import onnxruntime
    return {"cpus": os.cpu_count(), "memory_gib": round(mem / 2**20, 1), "python": platform.python_version(),
            "torch": torch, "onnxruntime": onnxruntime.__version__, "gpu": None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("flight", type=Path, help="the 10-minute recording")
    ap.add_argument("held_out", type=Path, help="the held-out flight's recording")
    ap.add_argument("work", type=Path)
    ap.add_argument("--out", type=Path, default=REPO / "docs/results/label_loop_timed.json")
    ap.add_argument("--budget", type=int, default=60)
    ap.add_argument("--app-minutes", type=float, default=1.0, help="planned flight of the last step's app run")
    ap.add_argument("--epochs", type=int, default=10, help="training epochs of 160 tiles (10: fit200)")
    ap.add_argument("--resume", action="store_true", help="keep WORK/steps.json's steps up to the review and go on "
                                                          "from training (after a failed step was fixed; training "
                                                          "itself resumes from WORK/run/last.pt when there is one)")
    a = ap.parse_args()
    work = a.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    flight, held = a.flight.resolve(), a.held_out.resolve()
    aer = [sys.executable, "-m", "aerodaas.cli"]
    steps = Steps()
    saved = work / "steps.json"
    if a.resume and saved.is_file():
        steps.update({n: v for n, v in json.loads(saved.read_text()).items() if n != "train detector"})
    steps.path = saved
    report: dict = {"machine": machine(), "load_1min_at_start": load1(), "steps": steps}
    info = subprocess.run([*aer, "info", str(flight), "--json"], capture_output=True, text=True)
    report["recording"] = {"file": flight.name, "bytes": flight.stat().st_size, "info_exit": info.returncode}
    if info.returncode == 0:
        s = json.loads(info.stdout)
        cam = [c for c in s["channels"] if c["topic"].endswith("/camera/cam1")]
        report["recording"].update(duration_s=round(s["duration_s"], 1), camera_frames=cam[0]["count"],
                                   camera_rate_hz=round(cam[0]["rate_hz"], 2))
    if "label pull" not in steps:
        (work / "root").mkdir(exist_ok=True)
        steps.run("label frames", [*aer, "label", "frames", flight, held, "--held-out", held.stem, "--budget", a.budget,
                                   "--classes", "car", "--out", work / "root/frames", "--document-root", work / "root",
                                   "--threads", "2"])
        password = os.urandom(9).hex()
        server = steps.block("start Label Studio", start, work / "ls", password=password)
        try:
            os.replace(work / "root/frames", server.root / "frames")  # the frames below the server's local-files root
            tok = work / "token"
            tok.write_text(server.token)
            tok.chmod(0o600)
            common = ["--url", server.url, "--token-file", tok, "--document-root", server.root]
            steps.run("label push", [*aer, "label", "push", server.root / "frames", "--project", "loop", *common])
            from label_walkthrough import _api
            pid = next(p["id"] for p in _api(server.url, server.token, "GET", "/api/projects/")["results"]
                       if p["title"] == "loop")
            got = steps.block(REVIEW, review, server.url, server.token, pid)
            steps[REVIEW] = {**steps[REVIEW], **got}
            steps.run("label pull", [*aer, "label", "pull", "--project", "loop", "--out", work / "train", *common])
        finally:
            steps.block("stop Label Studio", stop, server)
    data = [x for d in ("reviewed", "machine") if (work / "train" / d / "classes.txt").exists()
            for x in ("--data", work / "train" / d)]
    again = ["--resume"] if a.resume and (work / "run/last.pt").is_file() else []
    steps.run("train detector", [*aer, "train", "detector", *data, "--epochs", a.epochs, *TRAIN, *again,
                                 "--out", work / "run"])
    report["review"] = {k: v for k, v in steps[REVIEW].items() if k not in ("seconds", "load_1min")}
    report["prelabels_against_truth"] = prelabels_against_truth(flight, work / "ls/root/frames")
    report["train"] = {k: v for k, v in json.loads((work / "run/report.json").read_text()).items()
                       if k in ("base_model", "best_epoch", "train_images", "val_images", "seed", "classes")}
    report["held_out"] = steps.block("held-out frames boxed from the simulator's truth", held_out_set, held,
                                     work / "held_out")
    scores = {}
    for name, model in (("shipped aerial_nano", REPO / "aerodaas/perception/models/aerial_nano.onnx"),
                        ("fine-tuned", work / "run/model.onnx")):
        out = work / f"bench_{name.split()[0]}.json"
        steps.run(f"bench detect ({name})", [*aer, "bench", "detect", "--images", work / "held_out/images",
                                             "--annotations", work / "held_out/labels", "--model-path", model,
                                             "--classes", "car", "--thresholds", "0.3", "--input-sizes", "480x640",
                                             "--out", out])
        scores[name] = json.loads(out.read_text())
    report["held_out"]["scores"] = {k: summary(v) for k, v in scores.items()}
    report["app"] = {}
    for name, model in (("fine-tuned", work / "run/model.onnx"),
                        ("shipped aerial_nano", REPO / "aerodaas/perception/models/aerial_nano.onnx")):
        step = f"app with the {name} model" + ("" if name == "fine-tuned" else " (comparison; not in the total)")
        rec = work / f"app_{name.split()[0]}.mcap"
        rec.unlink(missing_ok=True)
        r = steps.run(step, [*aer, "run", BENCH / "label_loop_app.py", "--record", rec, "--quiet"],
                      env={**os.environ, "LOOP_MODEL": str(model), "LOOP_MINUTES": str(a.app_minutes)})
        steps[step]["outcome"] = next(
            (ln.split("outcome:")[1].split()[0] for ln in r.stdout.splitlines() if "mission outcome:" in ln), None)
        run = load_run(str(rec))
        cars = {c["id"]: tracking_metrics(run, c["id"]) for c in run["targets"][0][1]["targets"]}
        full = sum(m["frames_fully_in_view"] for m in cars.values())
        hit = sum(m["frames_detected"] for m in cars.values())
        report["app"][name] = {"frames_with_a_car_fully_in_view": full, "of_them_detected": hit,
                               "detection_rate": round(hit / full, 3) if full else None}
    report["total_seconds_excluding_review"] = round(sum(
        s["seconds"] for n, s in steps.items() if "seconds" in s and "not in the total" not in n), 1)
    report["load_1min_at_end"] = load1()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps({k: v for k, v in report.items() if k != "held_out"}, indent=1))


if __name__ == "__main__":
    main()
