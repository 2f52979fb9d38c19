"""The labelling walkthrough of docs/training.md, run end to end and timed: a drone video -> `aerodaas label frames`
-> a real Label Studio (`label push`, a review, a screenshot of the pre-labels, `label pull`) -> `aerodaas train
detector` -> `aerodaas bench detect` on a flight no training frame came from -> the vehicle-tracking app with the
new model.

The video is MEVA's UAV montage (`video/uav-clips.mp4` of Kitware/mevadata, CC BY 4.0; sha256 below), cut into
8-second pieces that stand for flights; the piece holding the cut of `tests/data/meva_uav/uav_parked_cars.mp4` is
held out, and the hand-labelled cars of that clip (`cars.json`) score the models. The review is scripted: each
task's pre-labels are submitted as the reviewer's answer (a person's review time is not part of the measurement).

    python docs/bench/label_walkthrough.py MONTAGE.mp4 WORKDIR [--out docs/results/label_walkthrough.json]
        [--screenshot docs/images/label_studio_prelabels.jpg] [--epochs 6]

Needs Label Studio in its venv (tests/install-rig.sh), Chromium and chromedriver (Debian's chromium,
chromium-driver) and selenium in the venv named by $SHOT_PYTHON (default ~/.cache/aerodaas/shot-venv/bin/python)
for the screenshot. Nothing here is imported by the framework.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import av
import cv2

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
from tests.labelling.label_studio_server import start, stop  # noqa: E402  the tests' own server start

MONTAGE_SHA256 = "95956a110ac987ff29efe2884a92f0d906fced45a9982df83dbb3e882227eab2"
PIECE_S = 8.0
HELD_OUT = "montage-s04"  # 32-40 s: holds the montage's frames 1087-1161, the cut of uav_parked_cars.mp4
CLASSES = ["car", "large_vehicle", "person"]


def split(montage: Path, out: Path) -> list[Path]:
    """``montage`` cut into PIECE_S-second H.264 pieces ``montage-sNN.mp4`` (each one 'flight')."""
    out.mkdir(parents=True, exist_ok=True)
    pieces, writer, cur = [], None, -1
    with av.open(str(montage)) as c:
        for f in c.decode(video=0):
            k = int(f.time // PIECE_S)
            if k != cur:
                if writer:
                    writer[0].mux(writer[1].encode()); writer[0].close()
                p = out / f"montage-s{k:02d}.mp4"
                o = av.open(str(p), "w")
                s = o.add_stream("libx264", rate=30)
                s.width, s.height, s.pix_fmt = f.width, f.height, "yuv420p"
                writer, cur = (o, s), k
                pieces.append(p)
            img = f.to_ndarray(format="bgr24")
            writer[0].mux(writer[1].encode(av.VideoFrame.from_ndarray(img, format="bgr24")))
    if writer:
        writer[0].mux(writer[1].encode()); writer[0].close()
    return pieces


def held_out_set(work: Path) -> Path:
    """Frames 0, 37 and 74 of uav_parked_cars.mp4 with their hand-labelled cars as a YOLO folder."""
    d = work / "held_out"
    (d / "images").mkdir(parents=True, exist_ok=True)
    (d / "labels").mkdir(exist_ok=True)
    (d / "labels" / "classes.txt").write_text("\n".join(CLASSES) + "\n")
    truth = json.loads((REPO / "tests/data/meva_uav/cars.json").read_text())["frames"]
    with av.open(str(REPO / "tests/data/meva_uav/uav_parked_cars.mp4")) as c:
        for i, f in enumerate(c.decode(video=0)):
            if str(i) in truth:
                img = f.to_ndarray(format="bgr24")
                h, w = img.shape[:2]
                cv2.imwrite(str(d / "images" / f"parked-{i:03d}.jpg"), img)
                rows = [f"0 {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} {(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}"
                        for x0, y0, x1, y1 in truth[str(i)].values()]
                (d / "labels" / f"parked-{i:03d}.txt").write_text("\n".join(rows) + "\n")
    return d


def _api(url: str, token: str, method: str, path: str, body: object = None) -> object:
    req = urllib.request.Request(url + path, method=method, data=None if body is None else json.dumps(body).encode(),
                                 headers={"Authorization": f"Token {token}", "Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=120) as r:
        return json.loads(r.read() or b"null")


def review(url: str, token: str, pid: int) -> dict:
    """The scripted reviewer: every task's latest prediction submitted as its annotation."""
    preds = _api(url, token, "GET", f"/api/predictions/?project={pid}")
    by_task: dict[int, dict] = {}
    for p in preds:
        by_task[p["task"]] = p
    for task, p in by_task.items():
        _api(url, token, "POST", f"/api/tasks/{task}/annotations/", {"result": p["result"], "was_cancelled": False})
    return {"tasks": len(by_task), "boxes": sum(len(p["result"]) for p in by_task.values())}


def screenshot(url: str, user: str, password: str, pid: int, task: int, out: Path) -> None:
    """Label Studio's labelling view of one task with its pre-labels, by headless Chromium (selenium)."""
    code = f"""
import time
from selenium import webdriver
from selenium.webdriver.common.by import By
o = webdriver.ChromeOptions()
for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,900", "--disable-background-networking",
          "--disable-component-update", "--disable-sync", "--no-first-run"):
    o.add_argument(a)
o.binary_location = "/usr/bin/chromium"
d = webdriver.Chrome(options=o, service=webdriver.ChromeService("/usr/bin/chromedriver"))
d.get("{url}/user/login/")
d.find_element(By.NAME, "email").send_keys("{user}")
d.find_element(By.NAME, "password").send_keys("{password}")
d.find_element(By.CSS_SELECTOR, "form button[type=submit], form input[type=submit]").click()
time.sleep(3)
d.get("{url}/projects/{pid}/data?task={task}")
time.sleep(12)
d.save_screenshot("{out}")
d.quit()
"""
    py = os.environ.get("SHOT_PYTHON", str(Path.home() / ".cache/aerodaas/shot-venv/bin/python"))
    subprocess.run([py, "-c", code], check=True, timeout=300)


def timed(steps: dict, name: str, argv: list[str], **kw) -> subprocess.CompletedProcess:
    t0 = time.monotonic()
    r = subprocess.run(argv, capture_output=True, text=True, **kw)
    steps[name] = {"seconds": round(time.monotonic() - t0, 1), "command": " ".join(map(str, argv)),
                   "exit": r.returncode}
    print(f"{name}: {steps[name]['seconds']} s, exit {r.returncode}", flush=True)
    if r.returncode != 0:
        raise SystemExit(f"{name} failed:\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("montage", type=Path)
    ap.add_argument("work", type=Path)
    ap.add_argument("--out", type=Path, default=REPO / "docs/results/label_walkthrough.json")
    ap.add_argument("--screenshot", type=Path, default=REPO / "docs/images/label_studio_prelabels.jpg")
    ap.add_argument("--budget", type=int, default=40)
    ap.add_argument("--epochs", type=int, default=6)
    a = ap.parse_args()
    if hashlib.sha256(a.montage.read_bytes()).hexdigest() != MONTAGE_SHA256:
        raise SystemExit(f"{a.montage}: not MEVA's uav-clips.mp4 (sha256 {MONTAGE_SHA256})")
    work = a.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    steps: dict = {}
    aer = [sys.executable, "-m", "aerodaas.cli"]
    t0 = time.monotonic()
    pieces = split(a.montage, work / "flights")
    (work / "root").mkdir(exist_ok=True)
    steps["split the video into 8 s flights"] = {"seconds": round(time.monotonic() - t0, 1), "pieces": len(pieces)}
    timed(steps, "label frames", [*aer, "label", "frames", *map(str, pieces), "--budget", str(a.budget), "--held-out",
                                  HELD_OUT, "--out", str(work / "root/frames"), "--document-root", str(work / "root"),
                                  "--threads", "2"])
    t0 = time.monotonic()
    password = os.urandom(9).hex()
    server = start(work / "ls", password=password)
    steps["start Label Studio"] = {"seconds": round(time.monotonic() - t0, 1)}
    try:
        # the walkthrough's frames live below the server's local-files root
        os.replace(work / "root/frames", server.root / "frames")
        tok = work / "token"
        tok.write_text(server.token)
        tok.chmod(0o600)
        common = ["--url", server.url, "--token-file", str(tok), "--document-root", str(server.root)]
        timed(steps, "label push", [*aer, "label", "push", str(server.root / "frames"), "--project", "walkthrough",
                                    *common])
        pid = next(p["id"] for p in _api(server.url, server.token, "GET", "/api/projects/")["results"]
                   if p["title"] == "walkthrough")
        first_task = _api(server.url, server.token, "GET", f"/api/projects/{pid}/tasks/?page_size=1")[0]["id"]
        if a.screenshot:
            a.screenshot.parent.mkdir(parents=True, exist_ok=True)
            try:
                png = work / "screenshot.png"  # Chromium writes PNG; the docs keep a JPEG
                screenshot(server.url, "reviewer@example.test", password, pid, first_task, png)
                cv2.imwrite(str(a.screenshot), cv2.imread(str(png)), [cv2.IMWRITE_JPEG_QUALITY, 82])
            except Exception as e:  # noqa: BLE001 - the screenshot is an illustration, the timings stand
                steps["screenshot"] = {"error": f"{type(e).__name__}: {e}"}
        steps["review (scripted: pre-labels submitted)"] = review(server.url, server.token, pid)
        timed(steps, "label pull", [*aer, "label", "pull", "--project", "walkthrough", "--out", str(work / "train"),
                                    *common])
    finally:
        stop(server)
    timed(steps, "train detector", [*aer, "train", "detector", "--data", str(work / "train/reviewed"),
                                    "--epochs", str(a.epochs), "--tiles-per-epoch", "320", "--val-tiles", "60",
                                    "--out", str(work / "run")], env={**os.environ, "OMP_NUM_THREADS": "2"})
    held = held_out_set(work)
    scores = {}
    for name, model in (("shipped aerial_nano", ["--model-path", str(REPO / "aerodaas/perception/models/aerial_nano.onnx")]),
                        ("fine-tuned", ["--model-path", str(work / "run/model.onnx")])):
        out = work / f"bench_{name.split()[0]}.json"
        timed(steps, f"bench detect ({name})", [*aer, "bench", "detect", "--images", str(held / "images"),
                                               "--annotations", str(held / "labels"), *model, "--classes", "car",
                                               "--thresholds", "0.3", "--input-sizes", "480x640", "--out", str(out)])
        scores[name] = json.loads(out.read_text())
    total = sum(s.get("seconds", 0) for s in steps.values() if isinstance(s, dict))
    report = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                          "load_1min_at_end": os.getloadavg()[0]},
              "montage_sha256": MONTAGE_SHA256, "held_out": HELD_OUT, "steps": steps, "total_seconds": round(total, 1),
              "held_out_scores": {k: v.get("results", v) if isinstance(v, dict) else v for k, v in scores.items()}}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1))
    print(json.dumps({k: v for k, v in report.items() if k != "held_out_scores"}, indent=1))


if __name__ == "__main__":
    main()
