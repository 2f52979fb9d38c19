"""The example's frame source (examples/plugins/aerodaas_example_plugins/image_folder.py, docs/extending-vehicles.md):
frames from a folder of images with an index of capture times. Without Ray: the frames it hands
over and their times, its refusals of a bad index. Installed as a user installs the package (the fixture of
tests/plugins/test_example_plugins.py): listed by entry point, a bad camera configuration refused before Ray, and the app
(examples/plugins/app/folder_detect.py, the unchanged built-in ObjectDetector) run by ``aerodaas run`` on local Ray
and on a two-node LocalCluster, checked from the recording: each image at its index time, with the detections the
detector finds on that image."""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from aerodaas.model.types import CameraIntrinsics, FramePose
from aerodaas.plugins.frames import FrameSourceContext
from aerodaas.recording.reader import read_messages

from tests.conftest import REPO, needs_data
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp
from tests.plugins.test_example_plugins import _aerodaas, installed  # noqa: F401 - the fixture: the package, pip-installed

pytestmark = needs_data
APP = REPO / "examples" / "plugins" / "app"
INDEX_TIMES = [3.0, 4.5, 6.0, 7.5]  # app/make_frames.py's capture times (s)


def _load(name: str, path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


folder_src = _load("example_image_folder", REPO / "examples" / "plugins" / "aerodaas_example_plugins" / "image_folder.py")
make_frames = _load("example_make_frames", APP / "make_frames.py").make_frames


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    """The app's image folder, made from the shared photos: the index's path."""
    return make_frames(tmp_path_factory.mktemp("frames") / "frames")


def _source(index, width=640, height=480):
    ctx = FrameSourceContext("uav", "cam", {"index": str(index)}, CameraIntrinsics.from_hfov(width, height, 78.0))
    return folder_src.ImageFolderSource(ctx)


def test_the_source_hands_over_each_image_once_at_its_index_time_in_order(frames):
    import cv2

    src = _source(frames)
    pose = FramePose(position=(0.0, 0.0, 10.0))
    assert src.frame_at(2.99, pose) is None  # before the first image's time
    got = [src.frame_at(3.0, pose)]
    assert src.frame_at(3.2, pose) is None  # the next one is due at 4.5 s
    got += [src.frame_at(100.0, pose) for _ in range(3)]  # late ticks: the oldest not delivered yet, none skipped
    assert src.frame_at(100.0, pose) is None  # all delivered
    assert [f.capture_t for f in got] == INDEX_TIMES
    for i, f in enumerate(got):
        ref = cv2.imread(str(frames.parent / f"view{i}.jpg"))  # the file, as OpenCV reads it
        assert f.image.shape == (480, 640, 3) and f.image.dtype == np.uint8 and np.array_equal(f.image, ref)
    small = _source(frames, 320, 240).frame_at(3.0, pose)  # another camera size: resized to it
    assert small.image.shape == (240, 320, 3)
    first = cv2.imread(str(frames.parent / "view0.jpg"))
    assert np.array_equal(small.image, cv2.resize(first, (320, 240), interpolation=cv2.INTER_AREA))


@pytest.mark.parametrize("rows,message", [
    ("file,t\nview0.jpg,1\n", r"line 1 must be the header image,capture_t_s"),
    ("image,capture_t_s\nnope.jpg,1\n", r"line 2: image 'nope.jpg' is not a file"),
    ("image,capture_t_s\n../outside.jpg,1\n", r"line 2: image '../outside.jpg' is not a file in"),
    ("image,capture_t_s\nview0.jpg,2\nview1.jpg,2\n", r"line 3: capture_t_s must be .* after the previous row's, got '2'"),
    ("image,capture_t_s\nview0.jpg,-1\n", r"line 2: capture_t_s must be a finite number of seconds >= 0"),
    ("image,capture_t_s\nview0.jpg,nan\n", r"line 2: capture_t_s .* got 'nan'"),
    ("image,capture_t_s\nindex.csv,1\n", r"line 2: OpenCV cannot read image"),
    ("image,capture_t_s\n", r"lists no image"),
])
def test_a_bad_index_is_refused_naming_the_line_and_value(frames, tmp_path, rows, message):
    import shutil

    for f in frames.parent.glob("view*.jpg"):
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "outside.jpg").write_bytes((tmp_path / "view0.jpg").read_bytes())
    sub = tmp_path / "sub"
    sub.mkdir()
    for f in tmp_path.glob("view*.jpg"):
        shutil.copy(f, sub / f.name)
    (sub / "index.csv").write_text(rows)
    with pytest.raises(ValueError, match=message):
        folder_src.read_index(sub / "index.csv", "robots.0.sensors.0.properties.index")


CHECKS = textwrap.dedent('''
    import copy, json, sys
    from aerodaas.config import ConfigError, load_environment_config
    base = json.load(open(sys.argv[1]))
    for change in ({"folder": "frames"}, {"index": 3}, {"index": "frames/missing.csv"}, {"mcap": "x.mcap"}):
        cfg = copy.deepcopy(base)
        cfg["robots"][0]["sensors"][0]["properties"].update(change)
        open(sys.argv[2], "w").write(json.dumps(cfg))
        try:
            load_environment_config(sys.argv[2])
            print("ACCEPTED", change)
        except ConfigError as e:
            print("REFUSED", str(e).replace(chr(10), " "))
''')


def _app_dir(frames, tmp_path):
    """The app, its environment and its image folder in one folder (as make_frames.py makes it next to the app)."""
    import shutil

    tmp_path.mkdir(parents=True, exist_ok=True)
    for name in ("folder_detect.py", "folder_detect.json"):
        shutil.copy(APP / name, tmp_path / name)
    shutil.copytree(frames.parent, tmp_path / "frames")
    return tmp_path


def test_the_installed_package_lists_it_and_bad_camera_settings_stop_before_ray(installed, frames, tmp_path):  # noqa: F811
    _, env = installed
    p = _aerodaas(["plugins", "--json"], env, tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = {(r["kind"], r["name"]): r for r in json.loads(p.stdout)}
    mine = rows[("frame_source", "image_folder")]
    assert mine["origin"] == "entry point aerodaas-example-plugins" and mine["config"] == ["index"], mine
    assert {n for k, n in rows if k == "frame_source"} >= {"sim", "backend", "mcap", "stream", "mavlink"}
    assert rows[("frame_source", "sim")]["origin"] == "entry point aerodaas (built-in)"
    app = _app_dir(frames, tmp_path / "app")
    p = subprocess.run([sys.executable, "-c", CHECKS, str(app / "folder_detect.json"), str(app / "bad.json")],
                       capture_output=True, text=True, env=env, cwd=app, timeout=120)
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith(("REFUSED", "ACCEPTED"))]
    assert len(lines) == 4 and all(ln.startswith("REFUSED") for ln in lines), p.stdout + p.stderr[-3000:]
    where = "sensors.0.properties"  # under "robots.0: ..." (or its full path)
    assert f"{where}.folder: unknown camera property" in lines[0], lines[0]
    assert f"{where}.index" in lines[1] and "3" in lines[1], lines[1]
    assert f"{where}.index: file 'frames/missing.csv' not found" in lines[2], lines[2]
    assert "properties.mcap is only used with properties.source 'mcap', but source is 'image_folder'" in lines[3]
    # a bad row of the index: `aerodaas run` exits 2 naming it, and no Ray session was started
    (app / "frames" / "index.csv").write_text("image,capture_t_s\nview0.jpg,3\nview1.jpg,2\n")
    ray_tmp = fresh_ray_tmp(tmp_path)
    p = _aerodaas(["run", str(app / "folder_detect.py"), "--quiet"], dict(env, RAY_TMPDIR=str(ray_tmp)), app)
    err = p.stdout + p.stderr
    assert p.returncode == 2 and f"{where}.index" in err and "line 3: capture_t_s" in err, err[-3000:]
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []


def _expected_detections(frames) -> list[list[tuple]]:
    """What the built-in detector finds on each image of the folder, run here on the files (no framework):
    (class, box) per detection, in the app's settings."""
    from aerodaas.analytics.detector import ObjectDetector

    det = ObjectDetector("yolox_nano", classes=["car", "truck", "bus"], score_threshold=0.15)
    det.setup()
    out = []
    for i in range(len(INDEX_TIMES)):
        img = folder_src.load_bgr(frames.parent / f"view{i}.jpg", 640, 480)
        out.append(sorted((d.class_name, tuple(d.box)) for d in det.process(img, None)))
    return out


def _check_recording(rec: str, frames) -> None:
    """The camera's images at the index's times (on the run clock: log time minus the epoch the odometry's ``t``
    gives), one annotation message per image with the boxes the detector finds on that file."""
    msgs: dict[str, list] = {}
    for topic, _, log_ns, m in read_messages(rec):
        msgs.setdefault(topic, []).append((log_ns, m))
    assert msgs["/mission/result"][-1][1]["outcome"] == "success"
    log_ns, odo = msgs["/uav/odometry"][0]
    epoch = log_ns - round(odo["t"] * 1e9)
    images = msgs["/uav/camera/cam"]
    assert [round((t - epoch) / 1e9, 6) for t, _ in images] == INDEX_TIMES, [t - epoch for t, _ in images]
    anns = msgs["/uav/detector/detections"]
    assert [round((t - epoch) / 1e9, 6) for t, _ in anns] == INDEX_TIMES
    got = []
    for _, a in anns:
        boxes = []
        for p in a.points:
            meta = {e.key: e.value for e in p.metadata}
            xs, ys = [q.x for q in p.points], [q.y for q in p.points]
            boxes.append((meta["class_name"], (min(xs), min(ys), max(xs), max(ys))))
        got.append(sorted(boxes))
    expected = _expected_detections(frames)
    assert [len(g) for g in got] == [len(e) for e in expected] and sum(map(len, got)) >= 3, (got, expected)
    assert [len(e) > 0 for e in expected] == [True, False, True, True], expected  # cars in views 0, 2 and 3
    for g, e in zip(got, expected):
        for (cg, bg), (ce, be) in zip(g, e):
            assert cg == ce and np.allclose(bg, be, atol=0.5), (g, e)


@pytest.mark.e2e
def test_the_app_runs_the_unchanged_detector_on_the_folder_on_local_ray(installed, frames, tmp_path):  # noqa: F811
    _, env = installed
    app = _app_dir(frames, tmp_path / "app")
    rec = tmp_path / "folder.mcap"
    p = _aerodaas(["run", str(app / "folder_detect.py"), "--record", str(rec), "--quiet", "--timeout", "300"], env,
                  app, timeout=600)
    assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    _check_recording(str(rec), frames)


CLUSTER = textwrap.dedent('''
    import json, os, subprocess, sys
    from aerodaas.clusters.local import LocalCluster

    app, rec, site = sys.argv[1], sys.argv[2], sys.argv[3]
    # the nodes were started without the package; the driver, where it is installed, ships it to the job
    with LocalCluster(cloud_nodes=0, edge_nodes=2, edge_labels=[{"aerodaas/site": "a"}, {"aerodaas/site": "b"}],
                      connect=False, worker_niceness=0) as lc:
        p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", app, "--record", rec, "--quiet",
                            "--timeout", "300", "--address", lc.address], capture_output=True, text=True,
                           timeout=900, env=dict(os.environ, PYTHONPATH=site), cwd=os.path.dirname(app))
        print("RESULT " + json.dumps({"rc": p.returncode, "out": p.stdout[-3000:], "err": p.stderr[-3000:]}))
''')


@pytest.mark.cluster
def test_the_app_runs_on_a_two_node_local_cluster(installed, frames, tmp_path):  # noqa: F811
    """The drone actor (with the camera and its image-folder source) on site a, the detector on site b: the frame
    source is shipped to the nodes with the package and its frames cross nodes to the unchanged detector."""
    _, env = installed
    app = _app_dir(frames, tmp_path / "app")
    cfg = json.loads((app / "folder_detect.json").read_text())
    cfg["compute"] = [{"id": "base", "tier": "edge", "labels": {"aerodaas/site": "a"}},
                      {"id": "edge", "tier": "edge", "labels": {"aerodaas/site": "b"}}]
    cfg["robots"][0]["compute"] = "base"
    (app / "folder_detect.json").write_text(json.dumps(cfg))
    p = _aerodaas(["plan", str(app / "folder_detect.py"), "--json"], env, app)
    assert p.returncode == 0, p.stderr[-3000:]
    sel = {a["role"]: a["label_selector"].get("aerodaas/site") for a in json.loads(p.stdout)["actors"]}
    assert (sel["drone"], sel["analytics"]) == ("a", "b"), sel
    rec = tmp_path / "cluster.mcap"
    script = tmp_path / "cluster_run.py"
    script.write_text(CLUSTER)
    site = env["PYTHONPATH"].split(os.pathsep)[0]
    cluster_env = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    p = subprocess.run([sys.executable, str(script), str(app / "folder_detect.py"), str(rec), site],
                       capture_output=True, text=True, env=cluster_env, cwd=tmp_path, timeout=1800)
    out = [json.loads(ln[len("RESULT "):]) for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(out) == 1 and out[0]["rc"] == 0, (out, p.stdout[-3000:], p.stderr[-3000:])
    _check_recording(str(rec), frames)
