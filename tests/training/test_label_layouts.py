"""Each export layout of CVAT and Label Studio, written here file for file as the tool writes it (tests/training/
exports.py), loads as it is: the boxes in pixels, the classes and the video each frame belongs to; an export that
cannot be read is one error naming the file; Label Studio's upload prefixes never make every frame a video of its
own, so the split by video holds on its exports."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from aerodaas.training.dataset import load_set, split_by_sequence
from aerodaas.training.labels.check import LabelError
from tests.training.exports import (assert_loaded, coco_doc, frames, write_cvat_coco, write_cvat_yolo, write_jpeg,
                                    write_ls_yolo)


@pytest.mark.parametrize("with_images,cache_prefix", [(True, False), (False, False), (True, True)],
                         ids=["yolo_with_images", "yolo_own_images", "snapshot_with_images"])
def test_label_studio_yolo_export(tmp_path, with_images, cache_prefix):
    """Label Studio "YOLO_WITH_IMAGES" (images/<8hex>-<name>), "YOLO" with the user's own frames copied into the
    empty images/ (labels keep the upload prefix, images do not) and an export snapshot's
    <md5>__<8hex>-<name>: notes.json is no COCO file, and each frame's video is its flight."""
    fs = frames()
    items, names = load_set(write_ls_yolo(tmp_path / "export", fs, with_images, cache_prefix))
    assert_loaded(items, names, fs)


def test_a_stray_json_beside_a_yolo_export_is_no_problem_of_the_set(tmp_path):
    fs = frames()
    root = write_ls_yolo(tmp_path / "export", fs, with_images=True)
    (root / "project.json").write_text('{"half written')
    assert_loaded(*load_set(root), fs)


def test_cvat_yolo_export(tmp_path):
    """CVAT "YOLO 1.1": obj.names, obj.data, train.txt and the labels beside the images in obj_train_data/."""
    fs = frames()
    items, names = load_set(write_cvat_yolo(tmp_path / "export", fs))
    assert_loaded(items, names, fs)


def test_cvat_yolo_export_without_images_takes_them_in_images(tmp_path):
    """CVAT "YOLO 1.1" exported without images: the frames put in images/ pair with obj_train_data/'s labels."""
    fs = frames()
    root = write_cvat_yolo(tmp_path / "export", fs)
    for f in fs:
        (root / "images").mkdir(exist_ok=True)
        (root / "obj_train_data" / f.name).rename(root / "images" / f.name)
    assert_loaded(*load_set(root), fs)


@pytest.mark.parametrize("image_dir", ["images", "images/default"])
def test_cvat_coco_export(tmp_path, image_dir):
    """CVAT "COCO 1.0": annotations/instances_default.json, the frames in images/ or images/default/, ids from 1;
    the folder and the json itself both load."""
    fs = frames()
    root = write_cvat_coco(tmp_path / "export", fs, image_dir)
    assert_loaded(*load_set(root), fs)
    assert_loaded(*load_set(root / "annotations" / "instances_default.json"), fs)


@pytest.mark.parametrize("form", ["upload_path", "snapshot", "own_images"])
def test_label_studio_coco_export(tmp_path, form):
    """Label Studio "COCO": result.json whose file_name is relative to the converter's temporary folder
    (``../../…/upload/1/<8hex>-<name>``, the image copied to images/<8hex>-<name> with images, or the user's own
    <name> in images/ without), or ``images/<md5>__<8hex>-<name>`` (an export snapshot); ids from 0."""
    fs = frames()
    root = tmp_path / "export"
    (root / "images").mkdir(parents=True)
    if form == "snapshot":
        fnames = [f"images/{i:08x}__{f.uploaded}" for i, f in enumerate(fs)]
        stored = [Path(n).name for n in fnames]
    else:
        fnames = [f"../../tmp/label-studio/media/upload/1/{f.uploaded}" for f in fs]
        stored = [f.uploaded if form == "upload_path" else f.name for f in fs]
    (root / "result.json").write_text(json.dumps(coco_doc(fs, fnames, 0)).replace("/", "\\/"))  # ujson escapes /
    for f, name in zip(fs, stored):
        write_jpeg(root / "images" / name, f)
    assert_loaded(*load_set(root), fs)


def test_a_label_studio_yolo_export_is_split_by_flight_never_by_frame(tmp_path):
    """Frames named <8hex>-<flight>_<camera>-<frame>.jpg: the split keeps every flight's frames on one side."""
    fs = frames()
    items, _ = load_set(write_ls_yolo(tmp_path / "export", fs, with_images=True))
    assert {it.sequence for it in items} == {f.flight for f in fs}
    for seed in range(6):
        train, val = split_by_sequence(items, 0.3, seed)
        assert train and val and len(train) + len(val) == len(fs)
        assert not {it.sequence for it in train} & {it.sequence for it in val}, seed
        flights_val = {f.flight for f in fs if any(it.path.name.endswith(f.name) for it in val)}
        assert all(any(it.path.name.endswith(f.name) for it in val) for f in fs if f.flight in flights_val)


def _notes_only(root: Path) -> tuple[Path, str]:
    write_ls_yolo(root, frames(), with_images=False)
    shutil.rmtree(root / "labels")
    shutil.rmtree(root / "images")
    return root, "notes.json: Label Studio's notes.json of a YOLO export, but no label file"


def _notes_as_data(root: Path) -> tuple[Path, str]:
    write_ls_yolo(root, frames(), with_images=True)
    return root / "notes.json", "notes.json: not a COCO detection file"


def _not_detection(root: Path) -> tuple[Path, str]:
    root.mkdir()
    (root / "captions.json").write_text(json.dumps({"images": [], "captions": []}))
    return root, "captions.json: not a COCO detection file"


def _task_list(root: Path) -> tuple[Path, str]:
    root.mkdir()
    (root / "project-1.json").write_text(json.dumps([{"id": 1, "data": {"image": "/data/upload/1/a.jpg"}}]))
    return root / "project-1.json", "project-1.json: a Label Studio export has no class list"


def _broken_json(root: Path) -> tuple[Path, str]:
    root.mkdir()
    (root / "result.json").write_text('{"images": [')
    return root, "result.json: cannot be read as JSON"


def _ambiguous_image(root: Path) -> tuple[Path, str]:
    fs = frames()[:2]
    root.mkdir()
    (root / "result.json").write_text(json.dumps(coco_doc(fs, ["../gone/x.jpg", fs[1].name], 0)))
    for sub in ("a", "b"):
        write_jpeg(root / "images" / sub / "x.jpg", fs[0])
    write_jpeg(root / "images" / fs[1].name, fs[1])
    return root, "file_name='../gone/x.jpg': several images fit it"


def _missing_image(root: Path) -> tuple[Path, str]:
    fs = frames()[:1]
    (root / "annotations").mkdir(parents=True)
    (root / "annotations" / "instances_default.json").write_text(json.dumps(coco_doc(fs, [fs[0].name], 1)))
    return root, f"file_name='{fs[0].name}': no such image"


def _label_fits_two_images(root: Path) -> tuple[Path, str]:
    fs = frames()
    write_ls_yolo(root, fs, with_images=False)
    (root / "labels" / f"0badcafe-{fs[0].stem}.txt").write_text("0 0.5 0.5 0.1 0.1\n")  # uploaded twice
    return root, "keep one of each"


def _polygon_line(root: Path) -> tuple[Path, str]:
    fs = frames()
    write_cvat_yolo(root, fs)
    (root / "obj_train_data" / f"{fs[1].stem}.txt").write_text("0 0.1 0.1 0.2 0.1 0.2 0.2\n")
    return root, f"{fs[1].stem}.txt:1: expected 'class cx cy w h'"


@pytest.mark.parametrize("case", [_notes_only, _notes_as_data, _not_detection, _task_list, _broken_json,
                                  _ambiguous_image, _missing_image, _label_fits_two_images, _polygon_line],
                         ids=lambda f: f.__name__[1:])
def test_an_export_that_cannot_be_read_is_one_error_naming_the_file(tmp_path, case):
    data, expected = case(tmp_path / "export")
    with pytest.raises(LabelError) as e:
        load_set(data)
    assert expected in str(e.value), str(e.value)
    assert "Traceback" not in str(e.value)
