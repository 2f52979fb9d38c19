"""`aerodaas train detector` as a user runs it (the command line, in this process: the run's outputs, its report
and its messages are the point, and the other tests here load PyTorch anyway; the Ray Train job keeps a subprocess):
on a four-image labelled set it takes one step, exports an ONNX model that onnxruntime and the framework's detector
load, with the export checked against PyTorch; `--resume` continues from the checkpoint; bad labels and options end
before training with exit 2, naming the file and value.

The four images are drawn here (grey ground, dark rectangles as cars, small warm blobs as persons), written as a
labelling tool's YOLO export would be.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import MODEL_DIR, needs_data, skip_or_fail


NAMES = ["car", "large_vehicle", "person"]


def _draw_set(root: Path, n: int = 4, seed: int = 0) -> Path:
    """A YOLO folder of ``n`` 640x480 frames (cars 40x20 px, trucks 80x30, persons 8x8) with labels."""
    rng = np.random.default_rng(seed)
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    (root / "classes.txt").write_text("\n".join(NAMES) + "\n")
    for i in range(n):
        im = np.full((480, 640, 3), 120, np.uint8) + rng.integers(0, 20, (480, 640, 3), dtype=np.uint8)
        lines = []
        for k in range(6):
            c = k % 3
            w, h = ((40, 20), (80, 30), (8, 8))[c]
            x, y = int(rng.integers(10, 640 - w - 10)), int(rng.integers(10, 480 - h - 10))
            colour = ((30, 30, 200), (200, 200, 200), (240, 240, 240))[c]
            cv2.rectangle(im, (x, y), (x + w, y + h), colour, -1)
            lines.append(f"{c} {(x + w / 2) / 640:.6f} {(y + h / 2) / 480:.6f} {w / 640:.6f} {h / 480:.6f}")
        cv2.imwrite(str(root / "images" / f"flight{i // 2}_{i:04d}.jpg"), im)
        (root / "labels" / f"flight{i // 2}_{i:04d}.txt").write_text("\n".join(lines) + "\n")
    return root


def _train(*args: str, env_extra: dict | None = None, in_process: bool = False):
    """``aerodaas train detector ARGS`` in a subprocess, or with ``in_process`` (a check of bad input, which ends
    before training, or a training run without Ray) in this process (:func:`tests.inputs.cli_inprocess.run_cli`)."""
    env = {**os.environ, "AERODAAS_MODEL_DIR": str(MODEL_DIR), **(env_extra or {})}
    if in_process:
        return run_cli("train", "detector", *args, env=env)
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "train", "detector", *args], capture_output=True,
                          text=True, env=env, timeout=600)


SMOKE = ("--epochs", "1", "--tiles-per-epoch", "4", "--batch", "2", "--val-tiles", "4", "--tile", "256")


@needs_data
def test_one_step_exports_a_model_that_matches_pytorch(tmp_path):
    if importlib.util.find_spec("torch") is None:
        skip_or_fail('the [train] extra (PyTorch) is not installed: pip install -e ".[train]"')
    data = _draw_set(tmp_path / "set")
    out = tmp_path / "run"
    r = _train("--data", str(data), "--val", str(data), "--out", str(out), "--max-steps", "1", *SMOKE,
               "--object-px", "6", "48", "--oblique", "0.6", in_process=True)
    assert r.returncode == 0, r.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["names"] == NAMES
    # the shipped aerial model knows every class of the set: the run starts from it, and says so
    assert report["base_model"]["name"] == "aerial_nano" and "starting from aerial_nano" in r.stderr
    assert len(report["history"]) == 1
    assert report["export"]["max_abs_diff"] <= 1e-3
    assert (out / "last.pt").is_file() and (out / "best.pt").is_file()
    assert report["config"]["object_px"] == [6.0, 48.0] and report["config"]["p_oblique"] == 0.6  # the options kept
    # the exported file is what the analytics load: the framework's detector reads its classes from its metadata
    from aerodaas.perception.decoders import inspect_model
    from aerodaas.perception.detect import YoloxDetector

    info = inspect_model(out / "model.onnx")
    assert (info.format, info.class_names, info.n_classes) == ("yolox", NAMES, 3)
    det = YoloxDetector(str(out / "model.onnx"), input_size=(256, 320), score_threshold=0.01)
    frame = cv2.imread(str(next((data / "images").iterdir())))
    for d in det.detect(frame):
        assert d.class_name in NAMES
        assert 0 <= d.box[0] <= d.box[2] <= 640 and 0 <= d.box[1] <= d.box[3] <= 480
    # --resume continues from the checkpoint: a second epoch is added to the same history
    r2 = _train("--data", str(data), "--val", str(data), "--out", str(out), "--resume",
                *[a if a != "1" or i != 1 else "2" for i, a in enumerate(SMOKE)], "--max-steps", "4", in_process=True)
    assert r2.returncode == 0, r2.stderr[-3000:]
    report2 = json.loads((out / "report.json").read_text())
    assert [h["epoch"] for h in report2["history"]] == [0, 1]


def _case_outside(root: Path) -> tuple[str, ...]:
    lab = next((root / "labels").iterdir())
    lab.write_text(lab.read_text() + "0 0.99 0.5 0.2 0.1\n")
    return (lab.name, "outside")


def _case_unknown_class(root: Path) -> tuple[str, ...]:
    lab = sorted((root / "labels").iterdir())[1]
    lab.write_text(lab.read_text() + "7 0.5 0.5 0.1 0.1\n")
    return (lab.name, "class 7 is unknown")


def _case_label_without_image(root: Path) -> tuple[str, ...]:
    (root / "labels" / "ghost_0001.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    return ("ghost_0001.txt", "without an image")


def _case_unreadable_image(root: Path) -> tuple[str, ...]:
    bad = root / "images" / "broken_0001.jpg"
    bad.write_bytes(b"not a jpeg")
    return ("broken_0001.jpg", "cannot be read")


def _case_empty(root: Path) -> tuple[str, ...]:
    for p in (root / "images").iterdir():
        p.unlink()
    for p in (root / "labels").iterdir():
        p.unlink()
    return ("no labelled image",)


def _case_no_names(root: Path) -> tuple[str, ...]:
    (root / "classes.txt").unlink()
    return ("no class names", "classes.txt")


def _case_malformed_line(root: Path) -> tuple[str, ...]:
    lab = sorted((root / "labels").iterdir())[2]
    lab.write_text("car 0.5 0.5 0.1\n")
    return (f"{lab.name}:1", "'car 0.5 0.5 0.1'")


@needs_data
@pytest.mark.parametrize("case", [_case_outside, _case_unknown_class, _case_label_without_image,
                                  _case_unreadable_image, _case_empty, _case_no_names, _case_malformed_line],
                         ids=lambda f: f.__name__[6:])
def test_bad_labels_end_before_training_naming_the_file(tmp_path, case):
    data = _draw_set(tmp_path / "set")
    expected = case(data)
    out = tmp_path / "run"
    r = _train("--data", str(data), "--out", str(out), *SMOKE, in_process=True)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    for text in expected:
        assert text in r.stderr, (text, r.stderr[-2000:])
    assert not out.exists(), "nothing may be written before the labels are good"


def test_coco_labels_with_a_missing_image_are_refused(tmp_path):
    (tmp_path / "a.jpg").write_bytes(cv2.imencode(".jpg", np.zeros((40, 60, 3), np.uint8))[1].tobytes())
    doc = {"images": [{"id": 1, "file_name": "a.jpg"}, {"id": 2, "file_name": "gone.jpg"}],
           "categories": [{"id": 1, "name": "car"}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [5, 5, 10, 10]},
                           {"id": 2, "image_id": 1, "category_id": 9, "bbox": [5, 5, 10, 10]}]}
    (tmp_path / "labels.json").write_text(json.dumps(doc))
    from aerodaas.training.dataset import load_set
    from aerodaas.training.labels.check import LabelError

    with pytest.raises(LabelError) as e:
        load_set(tmp_path)
    msg = str(e.value)
    assert "gone.jpg" in msg and "category_id=9" in msg and "2 problem(s)" in msg


@pytest.mark.parametrize("args,field", [(("--tile", "100"), "--tile=100"), (("--epochs", "0"), "--epochs=0"),
                                        (("--init-from", "car"), "--init-from 'car'"),
                                        (("--object-px", "48", "6"), "--object-px=(48.0, 6.0)"),
                                        (("--oblique", "nan"), "--oblique=nan"),
                                        (("--oblique", "1.5"), "--oblique=1.5")])
def test_bad_options_are_named(tmp_path, args, field):
    r = _train("--data", str(tmp_path), "--out", str(tmp_path / "run"), *args, in_process=True)
    assert r.returncode == 2
    assert field in r.stderr, r.stderr


def test_object_px_scales_each_tiles_median_object_into_its_range(tmp_path):
    """``--object-px MIN MAX`` (the altitudes a user's camera flies at): every training tile is scaled so that its
    frame's median object measures MIN..MAX px (square root of the box area). The drawn frames' median object is a
    car (40 x 20 px among cars, 80 x 30 trucks and 8 x 8 persons), so every car fully inside a tile measures that."""
    if importlib.util.find_spec("torch") is None:
        skip_or_fail('the [train] extra (PyTorch) is not installed: pip install -e ".[train]"')
    from aerodaas.training.augment import TileSampler
    from aerodaas.training.config import TrainConfig
    from aerodaas.training.dataset import load_set
    from aerodaas.training.loop import augment_of

    items, _ = load_set(_draw_set(tmp_path / "set"))
    for lo, hi in ((6.0, 9.0), (60.0, 70.0)):
        aug = augment_of(TrainConfig(data=[tmp_path], tile=256, object_px=(lo, hi), p_oblique=0.0))
        assert (aug.tile, aug.object_px, aug.p_oblique) == (256, (lo, hi), 0.0)
        sampler, rng, sizes = TileSampler(items, aug, n_classes=3), np.random.default_rng(0), []
        for _ in range(40):
            _, targets = sampler.sample_plain(rng)
            for c, x0, y0, x1, y1 in targets:
                if c == 0 and x0 > 0 and y0 > 0 and x1 < 256 and y1 < 256:
                    sizes.append(float(np.sqrt((x1 - x0) * (y1 - y0))))
        assert len(sizes) >= 10, sizes
        assert lo * 0.97 <= min(sizes) and max(sizes) <= hi * 1.03, (lo, hi, sorted(sizes))


@needs_data
def test_the_trainer_draws_its_tiles_with_the_runs_object_sizes_and_oblique_share(tmp_path):
    """The options reach the tiles: the Trainer's sampler is built from the run's ``object_px`` and ``p_oblique``."""
    if importlib.util.find_spec("torch") is None:
        skip_or_fail('the [train] extra (PyTorch) is not installed: pip install -e ".[train]"')
    from aerodaas.training.config import TrainConfig
    from aerodaas.training.loop import Trainer
    from aerodaas.training.session import build_model
    from aerodaas.training.sets import load_training_data

    data_dir = _draw_set(tmp_path / "set")
    cfg = TrainConfig(data=[data_dir], val=[data_dir], tile=256, val_tiles=4, object_px=(6.0, 48.0), p_oblique=0.6,
                      out=tmp_path / "run")
    data = load_training_data(cfg)
    aug = Trainer(cfg, data, build_model(cfg, data.names)).sampler.aug
    assert (aug.tile, aug.object_px, aug.p_oblique) == (256, (6.0, 48.0), 0.6)


def test_split_by_sequence_never_splits_a_video(tmp_path):
    from aerodaas.training.dataset import split_by_sequence
    from aerodaas.training.labels.images import LabelledImage

    items = [LabelledImage(Path(f"/x/{v}_{f:05d}.jpg"), (10, 10), np.zeros((0, 4), np.float32),
                           np.zeros(0, np.int64)) for v in ("dji0005", "dji0760", "mos", "harbour") for f in range(5)]
    for seed in range(5):
        train, val = split_by_sequence(items, 0.25, seed)
        assert val and train
        assert not {it.sequence for it in train} & {it.sequence for it in val}
        assert len(train) + len(val) == len(items)


def test_one_recordings_frames_are_split_by_time(tmp_path):
    """A set from one recording (``aerodaas label frames`` names every frame of a flight's camera alike): the
    validation frames are the last ones by frame number, a block no training frame lies in, whatever the order."""
    from aerodaas.training.dataset import split_by_sequence
    from aerodaas.training.labels.images import LabelledImage

    frames = [3, 17, 40, 41, 95, 120, 300, 301, 512, 1000, 4096, 6800]
    names = [f"3f2a9c1e-flight10_quadrotor-base-cam1-{f:06d}.jpg" for f in frames]
    items = [LabelledImage(Path(f"/x/{n}"), (10, 10), np.zeros((0, 4), np.float32), np.zeros(0, np.int64))
             for n in reversed(names)]
    for fraction, n_val in ((0.25, 3), (0.15, 2), (0.01, 1), (0.99, 11)):
        train, val = split_by_sequence(items, fraction, seed=0)
        assert len(val) == n_val and len(train) + len(val) == len(items)
        assert sorted(it.path.name for it in val) == names[-n_val:]
    with pytest.raises(ValueError, match="one image|1 image"):
        split_by_sequence(items[:1], 0.2, seed=0)


@needs_data
@pytest.mark.cluster
def test_workers_run_the_same_training_as_a_ray_train_job(tmp_path):
    """`--workers 2`: a Ray Train TorchTrainer job of two DDP workers on a local Ray (slow: Ray and two PyTorch
    worker processes start); rank 0 writes the checkpoints, the driver exports and checks the model."""
    if importlib.util.find_spec("torch") is None or importlib.util.find_spec("ray.train") is None:
        skip_or_fail('the [train] extra (PyTorch, ray[train]) is not installed: pip install -e ".[train]"')
    data = _draw_set(tmp_path / "set")
    out = tmp_path / "run"
    r = _train("--data", str(data), "--val", str(data), "--out", str(out), "--workers", "2", *SMOKE)
    assert r.returncode == 0, r.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["workers"] == 2
    assert [h["epoch"] for h in report["history"]] == [0]
    assert report["export"]["max_abs_diff"] <= 1e-3
    assert "world_size=2" in r.stderr + r.stdout  # Ray Train's own line: both workers joined the process group
