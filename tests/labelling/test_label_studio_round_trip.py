"""The Label Studio round trip against a real Label Studio 1.23.2 server (:mod:`tests.labelling.label_studio_server`):
``aerodaas label push`` makes a project of a frames folder with its pre-labels; a reviewer's work is done through
Label Studio's own API (one frame corrected: a box moved, one deleted, one added; one frame skipped; one uploaded
through Label Studio and boxed; two frames left with the machine boxes); ``aerodaas label pull`` writes the training
sets, which ``aerodaas train detector`` trains on; Label Studio's own JSON, YOLO and COCO exports of the project
load as training sets with the same boxes; a wrong token and bad labels end with exit 2.
"""
from __future__ import annotations

import importlib.util
import io
import json
import os
import shutil
import subprocess
import sys
import time
import urllib.request
import uuid
import zipfile
from pathlib import Path

import numpy as np
import pytest

from aerodaas.training.dataset import load_set
from aerodaas.training.label_studio_export import strip_upload_prefix
from tests.conftest import skip_or_fail
from tests.labelling.frames_folder import FRAME_NAMES, NAMES, SAMPLE, SOURCES, rect, sample_boxes, write_frames_folder
from tests.labelling.label_studio_server import label_studio  # noqa: F401  (the session fixture)

pytestmark = pytest.mark.labelstudio
REPO = Path(__file__).resolve().parents[2]
#: the frame a reviewer uploads through Label Studio itself (its name gets Label Studio's upload prefix)
UPLOADED = "f3_cam0-000010.jpg"


def _cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})


def _api(server, method: str, path: str, body: object = None, raw: bytes | None = None,
         content_type: str = "application/json") -> object:
    """Label Studio's API called directly, as a reviewer's browser would."""
    data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
    req = urllib.request.Request(server.url + path, data=data, method=method,
                                 headers={"Authorization": f"Token {server.token}", "Content-Type": content_type})
    with urllib.request.urlopen(req, timeout=120) as r:
        out = r.read()
    return json.loads(out) if out[:1] in (b"{", b"[") else out


def _upload(server, pid: int, path: Path, name: str) -> None:
    """Import one image file into project ``pid`` through Label Studio's upload (multipart/form-data)."""
    boundary = uuid.uuid4().hex
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\n"
            f"Content-Type: image/jpeg\r\n\r\n").encode() + path.read_bytes() + f"\r\n--{boundary}--\r\n".encode()
    _api(server, "POST", f"/api/projects/{pid}/import", raw=body,
         content_type=f"multipart/form-data; boundary={boundary}")


def _tasks(server, pid: int) -> dict[str, dict]:
    """The project's tasks by image file name (upload prefix stripped)."""
    doc = _api(server, "GET", f"/api/tasks?project={pid}&page_size=100")
    out = {}
    for t in doc["tasks"]:
        name = t["data"].get("aerodaas_name") or t["data"]["image"].rsplit("/", 1)[-1]
        out[strip_upload_prefix(name)] = t
    return out


def _yolo(boxes: list[tuple[int, float, float, float, float]]) -> np.ndarray:
    """(N, 5) class cx cy w h of pixel boxes on a 640x512 frame, rows sorted."""
    rows = [(c, (x0 + x1) / 1280, (y0 + y1) / 1024, (x1 - x0) / 640, (y1 - y0) / 512) for c, x0, y0, x1, y1 in boxes]
    return np.array(sorted(rows), float).reshape(-1, 5)


def _read_yolo(f: Path) -> np.ndarray:
    return np.array(sorted(tuple(float(v) for v in ln.split()) for ln in f.read_text().splitlines() if ln.strip()),
                    float).reshape(-1, 5)


@pytest.fixture(scope="module")
def round_trip(label_studio, tmp_path_factory):  # noqa: F811  (the fixture imported above)
    """Push, review through Label Studio's API, pull: (server, project id, frames folder, TRAINDIR, expected
    YOLO rows of the reviewed frames, the pull's result)."""
    server = label_studio
    frames = server.root / f"frames-{uuid.uuid4().hex[:6]}"
    write_frames_folder(frames)
    token_file = tmp_path_factory.mktemp("token") / "token"
    token_file.write_text(server.token + "\n")
    r = _cli("label", "push", str(frames), "--url", server.url, "--token-file", str(token_file),
             "--project", f"review {frames.name}", "--document-root", str(server.root))
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.split("(id ")[1].split(")")[0])
    assert f"{server.url}/projects/{pid}" in r.stdout

    _upload(server, pid, SAMPLE / "images" / SOURCES[0], UPLOADED)
    tasks = _tasks(server, pid)
    assert sorted(tasks) == sorted([*FRAME_NAMES, UPLOADED])
    assert tasks[UPLOADED]["data"]["image"] != f"/data/upload/{pid}/{UPLOADED}"  # Label Studio prefixed it
    # the reviewer: frame 0 corrected (first box moved 15 px right, second deleted, third kept, a person added)
    (c0, *b0), _, (c2, *b2) = sample_boxes(SOURCES[0])
    moved = (c0, b0[0] + 15, b0[1], b0[2] + 15, b0[3])
    added = (2, 300.0, 300.0, 312.0, 322.0)
    corrected = [moved, (c2, *b2), added]
    result = [rect(*b[1:], 640, 512, NAMES[b[0]]) for b in corrected]
    _api(server, "POST", f"/api/tasks/{tasks[FRAME_NAMES[0]]['id']}/annotations", {"result": result})
    # frame 2 skipped; the uploaded frame boxed from scratch; frames 1 and 3 keep the machine boxes
    _api(server, "POST", f"/api/tasks/{tasks[FRAME_NAMES[2]]['id']}/annotations", {"result": [], "was_cancelled": True})
    uploaded_box = (0, 100.0, 120.0, 140.0, 150.0)
    _api(server, "POST", f"/api/tasks/{tasks[UPLOADED]['id']}/annotations",
         {"result": [rect(*uploaded_box[1:], 640, 512, "car")]})

    out = tmp_path_factory.mktemp("pulled") / "traindir"
    r = _cli("label", "pull", "--url", server.url, "--token-file", str(token_file), "--project", str(pid),
             "--out", str(out))
    assert r.returncode == 0, r.stderr
    expected = {FRAME_NAMES[0]: _yolo(corrected), UPLOADED: _yolo([uploaded_box])}
    return server, pid, frames, out, expected, token_file


def test_pull_keeps_the_reviewers_corrections_and_the_machine_boxes_apart(round_trip):
    server, pid, frames, out, expected, _ = round_trip
    reviewed, machine = out / "reviewed", out / "machine"
    assert sorted(p.name for p in (reviewed / "images").iterdir()) == sorted(expected)  # upload prefix stripped
    for name, rows in expected.items():
        got = _read_yolo(reviewed / "labels" / f"{Path(name).stem}.txt")
        np.testing.assert_allclose(got, rows, atol=2e-6)
    assert (reviewed / "classes.txt").read_text().split() == NAMES
    assert not (reviewed / "labelled_classes.txt").exists()  # reviewed frames are exhaustive
    # the machine frames: the predictions as pushed, and an empty labelled_classes.txt (misses are no background)
    assert sorted(p.name for p in (machine / "images").iterdir()) == sorted([FRAME_NAMES[1], FRAME_NAMES[3]])
    assert (machine / "labelled_classes.txt").read_text() == ""
    for i in (1, 3):
        got = _read_yolo(machine / "labels" / f"{Path(FRAME_NAMES[i]).stem}.txt")
        np.testing.assert_allclose(got, _yolo(sample_boxes(SOURCES[i])), atol=2e-6)
        assert (machine / "images" / FRAME_NAMES[i]).read_bytes() == (frames / "images" / FRAME_NAMES[i]).read_bytes()
    # the skipped frame is nowhere; nothing half-written beside the output
    assert not any(p.name == FRAME_NAMES[2] for p in out.rglob("*.jpg"))
    assert sorted(p.name for p in out.parent.iterdir()) == [out.name]
    # both are sets training reads: the machine set's mask says no class is exhaustive
    from aerodaas.training.dataset import labelled_classes

    assert labelled_classes(machine, NAMES).tolist() == [False, False, False]
    assert labelled_classes(reviewed, NAMES) is None


def test_the_pulled_sets_train_a_detector(round_trip, tmp_path):
    if importlib.util.find_spec("torch") is None:
        skip_or_fail('the [train] extra (PyTorch) is not installed: pip install -e ".[train]"')
    _, _, _, out, _, _ = round_trip
    run = tmp_path / "run"
    r = _cli("train", "detector", "--data", str(out / "reviewed"), "--data", str(out / "machine"),
             "--val", str(out / "reviewed"), "--base-model", str(REPO / "aerodaas/perception/models/aerial_nano.onnx"),
             "--out", str(run), "--max-steps", "2", "--epochs", "1", "--tiles-per-epoch", "4", "--batch", "2",
             "--val-tiles", "4", "--tile", "256")
    assert r.returncode == 0, r.stderr[-3000:]
    assert (run / "model.onnx").is_file()
    assert json.loads((run / "report.json").read_text())["names"] == NAMES


@pytest.mark.parametrize("export_type", ["JSON", "YOLO", "YOLO_WITH_IMAGES", "COCO", "COCO_WITH_IMAGES"])
def test_label_studios_own_exports_load_as_training_sets(round_trip, export_type, tmp_path):
    """Label Studio's exports of the reviewed project, as a user downloads them, give ``load_set`` the boxes the
    pull wrote (for every reviewed frame). Label Studio 1.23.2's COCO_WITH_IMAGES leaves an uploaded frame out of
    its zip and names it by a path relative to its own media folder."""
    server, pid, _, out, expected, _ = round_trip
    data = _api(server, "GET", f"/api/projects/{pid}/export?exportType={export_type}")
    folder = tmp_path / export_type.lower()
    folder.mkdir()
    if export_type == "JSON":
        (folder / "export.json").write_text(json.dumps(data))
        (folder / "classes.txt").write_text("\n".join(NAMES) + "\n")
        shutil.copytree(out / "reviewed" / "images", folder / "images")
    else:
        zipfile.ZipFile(io.BytesIO(data)).extractall(folder)
        if export_type in ("YOLO", "COCO"):  # labels only: the user adds the frames they own, under their names
            (folder / "images").mkdir(exist_ok=True)
            for src in (out / "reviewed" / "images").glob("*.jpg"):
                shutil.copyfile(src, folder / "images" / src.name)
    items, names = load_set(folder)
    assert names == NAMES
    by_name = {strip_upload_prefix(it.path.name): it for it in items}
    for name, rows in expected.items():
        it = by_name[name]
        h, w = it.hw
        got = np.array(sorted((int(c), (b[0] + b[2]) / 2 / w, (b[1] + b[3]) / 2 / h, (b[2] - b[0]) / w,
                               (b[3] - b[1]) / h) for b, c in zip(it.boxes.tolist(), it.classes.tolist())))
        np.testing.assert_allclose(got.reshape(-1, 5), rows, atol=1e-3)


def test_a_second_push_of_the_same_project_is_refused(round_trip):
    server, pid, frames, _, _, token_file = round_trip
    before = len(_tasks(server, pid))
    r = _cli("label", "push", str(frames), "--url", server.url, "--token-file", str(token_file),
             "--project", f"review {frames.name}", "--document-root", str(server.root))
    assert r.returncode == 2
    assert f"--project 'review {frames.name}': already a project" in r.stderr and f"(id {pid})" in r.stderr
    assert len(_tasks(server, pid)) == before


def test_a_wrong_token_is_refused_with_exit_2_and_not_echoed(round_trip, tmp_path):
    server, pid, _, _, _, _ = round_trip
    wrong = "0" * 40
    r = _cli("label", "pull", "--url", server.url, "--token", wrong, "--project", str(pid),
             "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    assert r.stderr.startswith("error: token: refused by Label Studio") and "401" in r.stderr
    assert wrong not in r.stderr + r.stdout
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bad, said", [
    ({"x": 90.0, "width": 20.0, "rectanglelabels": ["car"]}, "lies outside the 640x512 image"),
    ({"x": 10.0, "width": 5.0, "rectanglelabels": ["boat"]}, "rectanglelabels=['boat'] is not one of the classes"),
])
def test_pull_refuses_labels_it_cannot_train_on(round_trip, bad, said, tmp_path):
    """A reviewer's box that reaches out of the image, or a label the project's classes do not have (Label Studio
    accepts both through its API): pull ends with exit 2 naming the task, and writes nothing."""
    server, _, frames, _, _, token_file = round_trip
    folder = server.root / f"bad-{uuid.uuid4().hex[:6]}"
    write_frames_folder(folder)
    r = _cli("label", "push", str(folder), "--url", server.url, "--token-file", str(token_file),
             "--project", folder.name, "--document-root", str(server.root))
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.split("(id ")[1].split(")")[0])
    task = _tasks(server, pid)[FRAME_NAMES[0]]
    res = rect(10, 10, 50, 50, 640, 512, "car")
    res["value"].update(bad)
    _api(server, "POST", f"/api/tasks/{task['id']}/annotations", {"result": [res]})
    out = tmp_path / "out"
    r = _cli("label", "pull", "--url", server.url, "--token-file", str(token_file), "--project", folder.name,
             "--out", str(out))
    assert r.returncode == 2, r.stdout
    assert said in r.stderr and f"task {task['id']} annotation" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_personal_access_token_pulls_the_same_sets(round_trip, tmp_path):
    """A personal access token (what Label Studio 1.23's Account & Settings page gives: a JWT refresh token) works
    as the legacy token does: the pull is the same."""
    server, pid, _, out, _, _ = round_trip
    pat = _api(server, "POST", "/api/token/")["token"]
    (tmp_path / "pat").write_text(pat)
    r = _cli("label", "pull", "--url", server.url, "--token-file", str(tmp_path / "pat"), "--project", str(pid),
             "--out", str(tmp_path / "again"), "--reviewed-only")
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "again" / "machine").exists()
    for f in sorted((out / "reviewed").rglob("*")):
        g = tmp_path / "again" / "reviewed" / f.relative_to(out / "reviewed")
        assert g.exists() and (f.is_dir() or f.read_bytes() == g.read_bytes()), f


def test_label_studio_gets_pre_labels_from_the_served_detector(round_trip, tmp_path):
    """``aerodaas label serve`` connected to a project as its ML backend: Label Studio's "Retrieve Predictions"
    stores the detector's boxes on every task, in the project's classes, boxes that pull accepts."""
    server, _, _, _, _, token_file = round_trip
    folder = server.root / f"serve-{uuid.uuid4().hex[:6]}"
    write_frames_folder(folder)
    (folder / "tasks.json").write_text(json.dumps([{"data": t["data"]} for t in
                                                   json.loads((folder / "tasks.json").read_text())]))
    r = _cli("label", "push", str(folder), "--url", server.url, "--token-file", str(token_file),
             "--project", folder.name, "--document-root", str(server.root))
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.split("(id ")[1].split(")")[0])
    log = tmp_path / "serve.log"
    with open(log, "w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "label", "serve", "--port", "0",
                                 "--document-root", str(server.root)], stdout=out, stderr=subprocess.STDOUT,
                                cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, start_new_session=True)
    try:
        url = None
        for _ in range(240):  # the detector loads, then the address is printed
            m = [ln for ln in log.read_text().splitlines() if ln.startswith("ML backend ")]
            if m or proc.poll() is not None:
                url = m[0].split(" at ")[1].split()[0] if m else None
                break
            time.sleep(0.5)
        assert url, log.read_text()
        _api(server, "POST", "/api/ml", {"url": url, "project": pid, "title": "aerodaas"})
        done = _api(server, "POST", f"/api/dm/actions?id=retrieve_tasks_predictions&project={pid}",
                    {"selectedItems": {"all": True, "excluded": []}})
        assert done["processed_items"] == len(FRAME_NAMES), done
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    preds = _api(server, "GET", f"/api/predictions?project={pid}")
    assert len(preds) == len(FRAME_NAMES)
    from aerodaas.training.label_studio_export import tasks_to_boxes

    kept, problems = tasks_to_boxes([{"id": p["task"], "data": {"image": "x.jpg"}, "annotations": [],
                                      "predictions": [p]} for p in preds], NAMES, "served")
    assert problems == []
    assert sum(len(k.boxes) for k in kept) > 0  # the sample frames hold cars and persons the model finds
    assert all(k.hw == (512, 640) for k in kept if len(k.boxes))


def test_a_push_label_studio_refuses_leaves_no_project(round_trip, tmp_path):
    """Frames outside Label Studio's document root (the user's ``--document-root`` is not the server's): Label
    Studio refuses the storage, push ends with exit 2 naming it and deletes the project it had made."""
    server, _, _, _, _, token_file = round_trip
    folder = tmp_path / "elsewhere"
    write_frames_folder(folder)
    title = f"outside {uuid.uuid4().hex[:6]}"
    r = _cli("label", "push", str(folder), "--url", server.url, "--token-file", str(token_file), "--project", title,
             "--document-root", str(tmp_path))
    assert r.returncode == 2
    assert "POST /api/storages/localfiles" in r.stderr and "LOCAL_FILES_DOCUMENT_ROOT" in r.stderr, r.stderr
    projects = _api(server, "GET", "/api/projects?page_size=100")["results"]
    assert title not in [p["title"] for p in projects]
