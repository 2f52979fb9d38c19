"""``aerodaas label frames`` end to end on real drone footage (the repository's MEVA clip and a recording of the
held-out aerial sample frames) with the shipped detector: the pre-label files parse with third-party readers and
agree with each other; bad input exits 2 naming the problem, with nothing written; a failure leaves nothing."""
from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import defusedxml.ElementTree as DET
import pytest

from aerodaas import cli
from aerodaas.labelling import frames as frames_mod
from aerodaas.recording.writer import McapRecorder
from aerodaas.training.dataset import load_set
from aerodaas.training.labels.images import sequence_of
from tests.labelling.footage import SIZE, write_recording, write_video

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "tests" / "data" / "meva_uav" / "uav_parked_cars.mp4"
SAMPLE = REPO / "tests" / "data" / "aerial_sample" / "images"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    imgs = [cv2.resize(cv2.imread(str(p)), (SIZE[1], SIZE[0])) for p in sorted(SAMPLE.glob("DJI*.jpg"))]
    return write_recording(tmp_path_factory.mktemp("rec") / "DJI_0762.mcap", imgs, period_s=2.0)


@pytest.fixture(scope="module")
def labelled(tmp_path_factory, recording) -> tuple[Path, int]:
    """One run: the clip and the recording, 3 frames, pool of 1 per pick (the model on 3 frames of 640x480)."""
    root = tmp_path_factory.mktemp("labels")
    out = root / "batch 1"
    code = cli.main(["label", "frames", str(CLIP), str(recording), "--budget", "3", "--out", str(out), "--seed", "5",
                     "--pool-factor", "1", "--document-root", str(root.parent)])
    return out, code


def test_the_run_writes_every_file_and_names_that_map_to_their_flights(labelled):
    out, code = labelled
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["annotations.xml", "classes.txt", "coco.json", "images", "poses",
                                                     "selection.json", "tasks.json"]
    assert (out / "classes.txt").read_text().split() == ["car", "large_vehicle", "person"]
    sel = json.loads((out / "selection.json").read_text())
    assert sel["parameters"]["seed"] == 5 and sel["parameters"]["budget"] == 3
    frames = sel["frames"]
    assert len(frames) == 3 and {f["flight"] for f in frames} == {"uav-parked-cars", "DJI-0762"}
    for f in frames:
        img = cv2.imread(str(out / f["file"]))
        assert img is not None and img.shape[:2] == (f["height"], f["width"]) == SIZE
        assert sequence_of(Path(f["file"])) == f"{f['flight']}_{f['camera']}"
        assert f["scores"]["informativeness"] >= 0 and f["reason"]
        if f["flight"] == "DJI-0762":  # recorded frames carry the pose beside them
            assert f["pose"]["position"][0] == pytest.approx(10.0 * f["t_s"])
            side = json.loads((out / "poses" / (Path(f["file"]).stem + ".json")).read_text())
            assert side["pose"] == f["pose"] and side["frame"] == f["frame"]
        else:
            assert f["pose"] is None and f["source"] == str(CLIP)
    assert not list(out.parent.glob(".*partial*"))


def _boxes_of_tasks(out: Path) -> dict[str, list[tuple]]:
    tasks = json.loads((out / "tasks.json").read_text())
    got = {}
    for t in tasks:
        name = t["data"]["aerodaas_name"]
        assert t["data"]["image"] == f"/data/local-files/?d={out.parent.name}/batch%201/images/{name}"
        (pred,) = t["predictions"]
        assert pred["model_version"].startswith("aerial_nano@") and len(pred["model_version"]) == 12 + 12
        scores = [r["score"] for r in pred["result"]]
        assert pred["score"] == pytest.approx(sum(scores) / len(scores) if scores else 0.0)
        rows = []
        for r in pred["result"]:
            assert {k: r[k] for k in ("type", "from_name", "to_name", "image_rotation")} == {
                "type": "rectanglelabels", "from_name": "label", "to_name": "image", "image_rotation": 0}
            v, w, h = r["value"], r["original_width"], r["original_height"]
            assert (h, w) == SIZE and v["rotation"] == 0 and 0 < r["score"] <= 1
            assert 0 <= v["x"] < v["x"] + v["width"] <= 100 + 1e-6 and 0 <= v["y"] < v["y"] + v["height"] <= 100 + 1e-6
            rows.append((v["rectanglelabels"][0], v["x"] * w / 100, v["y"] * h / 100,
                         (v["x"] + v["width"]) * w / 100, (v["y"] + v["height"]) * h / 100))
        got[name] = rows
    return got


def test_the_three_pre_label_files_parse_and_hold_the_same_boxes(labelled):
    out, _ = labelled
    ls = _boxes_of_tasks(out)
    assert sum(map(len, ls.values())) > 0  # the parked cars are boxed somewhere
    root = DET.parse(out / "annotations.xml").getroot()
    assert root.tag == "annotations" and root.findtext("version") == "1.1"
    assert [e.text for e in root.iter("name") if e.text in ("car", "large_vehicle", "person")] == [
        "car", "large_vehicle", "person"]
    cvat = {}
    for im in root.iter("image"):
        assert (int(im.get("height")), int(im.get("width"))) == SIZE and (out / "images" / im.get("name")).is_file()
        cvat[im.get("name")] = [(b.get("label"), *(float(b.get(k)) for k in ("xtl", "ytl", "xbr", "ybr")))
                                for b in im.iter("box") if b.get("source") == "auto" and b.get("occluded") == "0"]
    coco = json.loads((out / "coco.json").read_text())
    cats = {c["id"]: c["name"] for c in coco["categories"]}
    files = {i["id"]: Path(i["file_name"]).name for i in coco["images"]}
    from_coco: dict[str, list] = {n: [] for n in files.values()}
    for a in coco["annotations"]:
        x, y, w, h = a["bbox"]
        assert w > 0 and h > 0 and x >= 0 and y >= 0 and x + w <= SIZE[1] + 1e-6 and y + h <= SIZE[0] + 1e-6
        assert a["area"] == pytest.approx(w * h) and 0 < a["score"] <= 1
        from_coco[files[a["image_id"]]].append((cats[a["category_id"]], x, y, x + w, y + h))
    assert set(ls) == set(cvat) == set(from_coco) == {p.name for p in (out / "images").iterdir()}
    for name in ls:
        for a, b, c in zip(ls[name], cvat[name], from_coco[name], strict=True):
            assert a[0] == b[0] == c[0]
            assert a[1:] == pytest.approx(b[1:], abs=0.01) and a[1:] == pytest.approx(c[1:], abs=1e-6)
    items, names = load_set(out / "coco.json")  # what aerodaas train detector --data reads
    assert len(items) == 3 and names == ["car", "large_vehicle", "person"]


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("small")
    write_video(d / "A.mp4", [0, 0, 1, 1, 2, 2], fps=1)
    with McapRecorder(d / "no_camera.mcap") as rec:
        rec.write_pose("/drone1/pose", 1_000, (0.0, 0.0, 10.0), 0.0)
    (d / "broken.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 8)
    return d


@pytest.mark.parametrize("args, message", [
    (["no_camera.mcap"], r"no_camera\.mcap'.*no camera channel"),
    (["broken.mp4"], r"video .*broken\.mp4'.*"),
    (["A.mp4", "--budget", "4"], r"--budget 4: only 3 candidate frame\(s\) available .*A 3"),
    (["A.mp4", "--held-out", "B"], r"--held-out 'B': matches no input flight"),
    (["A.mp4", "--classes", "car,boat"], r"--classes car,boat: unknown class\(es\) \['boat'\].*'person'"),
    (["A.mp4", "--model", "nope"], r"--model 'nope': not a known model"),
    (["A.mp4", "--per-flight-quota", "0"], r"--per-flight-quota 0: must be >= 1"),
], ids=["recording-without-camera", "undecodable-video", "budget-above-candidates", "unknown-held-out",
        "unknown-class", "unknown-model", "quota-0"])
def test_bad_input_exits_2_naming_it_before_anything_is_written(small, tmp_path, capsys, args, message):
    out = tmp_path / "out"
    argv = [str(small / args[0]), *args[1:]]
    if "--budget" not in argv:
        argv += ["--budget", "1"]
    assert cli.main(["label", "frames", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and re.search(message, err), err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_an_output_folder_that_is_not_new_is_refused(small, tmp_path, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("mine")
    assert cli.main(["label", "frames", str(small / "A.mp4"), "--budget", "1", "--out", str(tmp_path / "out")]) == 2
    assert "--out" in capsys.readouterr().err and (tmp_path / "out" / "keep.txt").read_text() == "mine"


def test_a_failure_while_writing_leaves_nothing(small, tmp_path, monkeypatch, capsys):
    def broken(*a, **k):
        raise RuntimeError("disk gone")

    monkeypatch.setattr(frames_mod, "coco_json", broken)
    code = cli.main(["label", "frames", str(small / "A.mp4"), "--budget", "2", "--out", str(tmp_path / "out"),
                     "--uniform"])
    assert code == 1 and "disk gone" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_uniform_picks_evenly_spaced_frames(small, tmp_path):
    out = tmp_path / "u"
    assert cli.main(["label", "frames", str(small / "A.mp4"), "--budget", "3", "--out", str(out), "--uniform"]) == 0
    sel = json.loads((out / "selection.json").read_text())
    assert sel["parameters"]["uniform"] is True
    assert [f["frame"] for f in sel["frames"]] == [0, 2, 4]  # one per scene: the repeats were dropped
    assert all(f["reason"] == "evenly spaced (uniform)" for f in sel["frames"])


class _InputShapes:
    """An onnxruntime session stand-in that passes every call through and keeps the input shapes it was given."""

    def __init__(self, session) -> None:
        self.session, self.shapes = session, []

    def run(self, names, feed):
        self.shapes += [v.shape[2:] for v in feed.values()]
        return self.session.run(names, feed)

    def __getattr__(self, name):
        return getattr(self.session, name)


def test_both_passes_see_a_small_frame_as_the_app_does(detectors, monkeypatch):
    """A 640x480 camera's frame is not enlarged to the model's 736x1280 input (as the apps run it, upscale=False):
    the normal pass sees it at 480x640, the enlarged pass at 1.5 times that (720x960, in a 736x960 input), and the
    enlarged pass's boxes come back in the frame's pixels; a 1080p frame is shrunk to the model's input as before."""
    img = cv2.imread(str(sorted(SAMPLE.glob("DJI*.jpg"))[0]))
    model = getattr(detectors.strong, "detector", detectors.strong)  # the enlarged pass's own model
    base, strong = _InputShapes(detectors.base.session), _InputShapes(model.session)
    monkeypatch.setattr(detectors.base, "session", base)
    monkeypatch.setattr(model, "session", strong)
    small = cv2.resize(img, (640, 480))
    _b, s = detectors.detect(small)
    assert base.shapes == [(480, 640)] and strong.shapes == [(736, 960)]
    assert s and all(0 <= d.box[0] < d.box[2] <= 640 and 0 <= d.box[1] < d.box[3] <= 480 for d in s)
    detectors.detect(cv2.resize(img, (1920, 1080)))
    assert base.shapes[1] == detectors.base.input_hw == (736, 1280) and strong.shapes[1] == (1088, 1920)
