"""Tiled inference (SAHI slicing and merging) and detection scoring."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from aerodaas.model.types import Detection
from aerodaas.perception.scoring import GroundTruth, load_annotations, match, score
from aerodaas.perception.tiling import TiledDetector, Tiling, merge_detections, slice_boxes


def test_slices_cover_the_frame_and_end_on_the_border():
    sl = slice_boxes(1080, 1920, 640, 0.2)
    cover = np.zeros((1080, 1920), bool)
    for x0, y0, x1, y1 in sl:
        assert x1 - x0 == 640 and y1 - y0 == 640
        cover[y0:y1, x0:x1] = True
    assert cover.all()
    assert max(s[2] for s in sl) == 1920 and max(s[3] for s in sl) == 1080
    assert slice_boxes(300, 500, 640, 0.2) == [(0, 0, 500, 300)]  # smaller than a tile: one slice


def _d(box, score=0.9, cls="car", cid=2):
    return Detection(class_id=cid, class_name=cls, score=score, box=box)


def test_greedy_nmm_joins_an_object_cut_at_a_slice_border_and_nms_keeps_the_best():
    left, right = _d((100, 100, 200, 150), 0.8), _d((190, 100, 260, 150), 0.6)  # IoU 0.06, IOS 0.14
    other = _d((500, 500, 550, 550), 0.7, "truck", 7)
    merged = merge_detections([left, right, other], "greedynmm", 0.1)
    assert [m.box for m in merged] == [(100, 100, 260, 150), other.box]
    assert merged[0].score == 0.8
    kept = merge_detections([left, _d((102, 101, 199, 151), 0.5, "truck", 7)], "nms", 0.5, agnostic=True)
    assert [(k.class_name, k.box) for k in kept] == [("car", left.box)]
    both = merge_detections([left, _d((102, 101, 199, 151), 0.5, "truck", 7)], "nms", 0.5, agnostic=False)
    assert len(both) == 2


class _FakeDetector:
    """Reports one box at a fixed position of every image it is given: where it lands in the frame shows the
    slice offsets; ``calls`` records the image shapes."""

    last_timing = {"preprocess_ms": 0.0, "inference_ms": 0.0, "postprocess_ms": 0.0}
    last_batch = 1

    def __init__(self):
        self.calls = []

    def detect_batch(self, images, max_batch=8):
        self.calls.append([im.shape for im in images])
        return [[_d((10, 10, 20, 20))] for _ in images]


def test_tiled_detector_shifts_boxes_to_frame_pixels_and_adds_the_full_frame():
    fake = _FakeDetector()
    det = TiledDetector(fake, Tiling(tile=500, overlap=0.0, full_frame=True, merge="nms", match_threshold=0.5))
    out = det.detect(np.zeros((500, 1000, 3), np.uint8))
    assert fake.calls == [[(500, 500, 3), (500, 500, 3), (500, 1000, 3)]]  # two slices + the frame, one call
    # the full frame's box (10..20) equals slice 0's: merged; slice 1's lands at 510..520
    assert sorted(d.box for d in out) == [(10, 10, 20, 20), (510, 10, 520, 20)]


@pytest.mark.parametrize("kw, msg", [(dict(tile=16), r"tiling.tile .* got 16"),
                                     (dict(overlap=0.95), r"tiling.overlap .* got 0.95"),
                                     (dict(merge="wbf"), r"tiling.merge .* got 'wbf'")])
def test_tiling_options_are_checked(kw, msg):
    with pytest.raises(ValueError, match=msg):
        Tiling(**kw).check()


def test_scoring_recall_precision_ap_on_known_matches():
    gt = GroundTruth("a.jpg", np.array([[0, 0, 10, 10], [20, 20, 30, 30]], float), ["car", "car"])
    dets = [_d((0, 0, 10, 10), 0.9), _d((0, 0, 10, 10), 0.8),  # a duplicate: false positive
            _d((21, 21, 31, 31), 0.7),  # IoU 81/119 = 0.68 with the 2nd car
            _d((100, 100, 110, 110), 0.6)]
    assert match(np.array([d.box for d in dets]), np.array([d.score for d in dets]), gt.boxes, 0.5).tolist() \
        == [True, False, True, False]
    s = score([(dets, gt)], "car", 0.5)
    assert (s.n_gt, s.n_det, s.recall, s.precision) == (2, 4, 1.0, 0.5)
    # PR points (0.5, 1), (0.5, 0.5), (1, 2/3), (1, 0.5): all-point AP = 0.5 * 1 + 0.5 * 2/3
    assert s.ap == pytest.approx(0.5 + 0.5 * 2 / 3)


def test_yolo_and_coco_annotations_read_the_same_boxes(tmp_path):
    import cv2

    cv2.imwrite(str(tmp_path / "f.png"), np.zeros((100, 200, 3), np.uint8))
    (tmp_path / "labels").mkdir()
    (tmp_path / "labels" / "f.txt").write_text("0 0.25 0.5 0.1 0.2\n")
    (tmp_path / "labels" / "classes.txt").write_text("car\n")
    coco = {"images": [{"id": 1, "file_name": "f.png"}], "categories": [{"id": 3, "name": "car"}],
            "annotations": [{"id": 1, "image_id": 1, "category_id": 3, "bbox": [40, 40, 20, 20]}]}
    (tmp_path / "a.json").write_text(json.dumps(coco))
    (y,) = load_annotations(tmp_path / "labels", tmp_path)
    (c,) = load_annotations(tmp_path / "a.json", tmp_path)
    assert y.classes == c.classes == ["car"]
    assert y.boxes.tolist() == c.boxes.tolist() == [[40.0, 40.0, 60.0, 60.0]]
    coco["annotations"][0]["bbox"] = [40, 40, 0, 20]
    (tmp_path / "b.json").write_text(json.dumps(coco))
    with pytest.raises(ValueError, match=r"annotations\[0\].bbox=\[40, 40, 0, 20\] has a non-positive size"):
        load_annotations(tmp_path / "b.json", tmp_path)


def test_bench_detect_cli_scores_our_annotations(tmp_path):
    """``aerodaas bench detect`` end to end on one shared photo and our hand-made annotations: the JSON report holds
    the three annotated cars of that photo and consistent counts; a bad threshold exits 2 before any inference."""
    from pathlib import Path

    from aerodaas.cli import main

    from tests.conftest import DATA_DIR, skip_or_fail

    images = DATA_DIR / "imagery" / "brighton_beach"
    if not (images / "DJI_0028.JPG").is_file():
        skip_or_fail("shared imagery not available")
    ann = Path(__file__).parents[1] / "data" / "brighton_beach_cars.json"
    out = tmp_path / "r.json"
    assert main(["bench", "detect", "--images", str(images), "--annotations", str(ann), "--limit", "1",
                 "--threads", "1", "--thresholds", "0.1", "0.3", "--sweep", "--out", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert [r["score_threshold"] for r in rep["results"]] == [0.1, 0.3]
    for r in rep["results"]:
        car = r["classes"]["car"]
        assert car["n_gt"] == 3 and 0.0 <= car["recall@0.5"] <= car["recall@0.3"] <= 1.0
        assert r["boxes_per_frame"] == car["n_det"]  # one image, only cars scored
    assert rep["results"][0]["classes"]["car"]["n_det"] >= rep["results"][1]["classes"]["car"]["n_det"]
    assert main(["bench", "detect", "--images", str(images), "--annotations", str(ann), "--thresholds", "15"]) == 2


def test_bench_detect_groups_score_member_classes_as_one():
    """``--group vehicle=car,truck``: a car the model calls a truck counts as a found vehicle; a malformed spec is a
    ValueError naming it (the CLI exits 2)."""
    from aerodaas.bench.detect import _relabel, parse_groups

    group_of = parse_groups(["vehicle=car, truck,bus", "human=person"])
    assert group_of == {"car": "vehicle", "truck": "vehicle", "bus": "vehicle", "person": "human"}
    gt = GroundTruth("a.jpg", np.array([[0, 0, 10, 10], [20, 20, 30, 30]], float),
                     [group_of.get(c, c) for c in ("car", "truck")])
    dets = _relabel([_d((0, 0, 10, 10), 0.9, "truck"), _d((20, 20, 30, 30), 0.8, "car"),
                     _d((50, 50, 60, 60), 0.7, "traffic light")], group_of)
    assert [d.class_name for d in dets] == ["vehicle", "vehicle", "traffic light"]
    s = score([(dets, gt)], "vehicle", 0.5)
    assert (s.n_gt, s.n_det, s.recall, s.precision) == (2, 2, 1.0, 1.0)
    for bad in ("vehicle", "=car", "vehicle="):
        with pytest.raises(ValueError, match=re.escape(f"--group {bad!r}: expected NAME=class,class,...")):
            parse_groups([bad])


def test_visdrone_annotations_read_as_the_toolkit_defines_them(tmp_path):
    """VisDrone-DET lines ``left,top,width,height,score,category,truncation,occlusion``: category 4 is a car, 1 a
    pedestrian; score 0 and category 0 (ignored region) are left out; a malformed line names file, line and value."""
    import cv2

    cv2.imwrite(str(tmp_path / "0000001_02999_d_0000005.jpg"), np.zeros((100, 200, 3), np.uint8))
    ann = tmp_path / "annotations"
    ann.mkdir()
    (ann / "0000001_02999_d_0000005.txt").write_text(
        "684,8,273,116,0,0,0,0\n"      # ignored region
        "10,20,30,15,1,4,0,1\n"        # car
        "50,60,8,20,1,1,0,0\n"         # pedestrian
        "70,60,8,20,0,2,0,0\n"         # not evaluated (score 0)
        "100,5,40,30,1,9,1,0,\n")      # bus, trailing comma as some files have
    (g,) = load_annotations(ann, tmp_path, format="visdrone")
    assert g.classes == ["car", "pedestrian", "bus"]
    assert g.boxes.tolist() == [[10, 20, 40, 35], [50, 60, 58, 80], [100, 5, 140, 35]]
    (ann / "0000001_02999_d_0000005.txt").write_text("10,20,0,15,1,4,0,1\n")
    with pytest.raises(ValueError, match=r"0000001_02999_d_0000005.txt:1: expected .* got '10,20,0,15,1,4,0,1'"):
        load_annotations(ann, tmp_path, format="visdrone")
