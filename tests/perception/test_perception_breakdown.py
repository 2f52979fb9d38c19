"""Scores by object size (COCO area ranges) and by per-frame view angle and altitude, on synthetic
boxes: a detector that misses exactly one kind of box must show it in that bucket and only there."""
from __future__ import annotations

import numpy as np
import pytest

from aerodaas.bench.detect_breakdown import breakdown, breakdown_lines
from aerodaas.model.types import Detection
from aerodaas.perception.breakdown import FrameMeta, frame_meta, hit_uav_meta, score_area
from aerodaas.perception.scoring import GroundTruth, score


def _box(x, y, side):
    return (float(x), float(y), float(x + side), float(y + side))


def _d(box, s=0.9, cls="car"):
    return Detection(class_id=0, class_name=cls, score=s, box=box)


# per image: a small (20 px, 400 px²), a medium (50 px) and a large (150 px) car
SIDES = {"small": 20, "medium": 50, "large": 150}


def _frames(n=3):
    gts = []
    for i in range(n):
        boxes = [_box(10 + 300 * k, 10 + 5 * i, side) for k, side in enumerate(SIDES.values())]
        gts.append(GroundTruth(f"f{i}.jpg", np.array(boxes, float), ["car"] * 3))
    return gts


def _misses_small(gts):
    """Finds every box of 32 px or more exactly, none below."""
    return [([_d(tuple(b)) for b in g.boxes if b[2] - b[0] >= 32], g) for g in gts]


def test_a_detector_missing_only_small_boxes_shows_recall_0_small_and_1_elsewhere():
    per = _misses_small(_frames())
    out = breakdown(per, ["car"], {})["by_size"]["car"]
    assert out["small"]["n_gt"] == out["medium"]["n_gt"] == out["large"]["n_gt"] == 3
    assert out["small"]["recall@0.5"] == 0.0 and out["small"]["n_det"] == 0
    assert out["medium"]["recall@0.5"] == out["large"]["recall@0.5"] == 1.0
    assert out["medium"]["precision@0.5"] == out["large"]["precision@0.5"] == 1.0
    assert out["medium"]["ap50"] == out["large"]["ap50"] == 1.0
    assert score(per, "car", 0.5).recall == pytest.approx(2 / 3)  # the overall figure hides where the misses are


def test_a_false_positive_counts_in_its_own_size_bucket_and_a_hit_on_a_box_of_another_size_counts_in_none():
    g = GroundTruth("a.jpg", np.array([_box(0, 0, 20), _box(100, 100, 50)], float), ["car", "car"])
    dets = [_d(_box(0, 0, 20), 0.9),     # finds the small box: ignored in medium and large
            _d(_box(400, 400, 60), 0.8),  # a medium false positive
            _d(_box(100, 100, 50), 0.7)]  # finds the medium box
    small = score_area([(dets, g)], "car", 0.5, 0.0, 32.0 ** 2)
    medium = score_area([(dets, g)], "car", 0.5, 32.0 ** 2, 96.0 ** 2)
    large = score_area([(dets, g)], "car", 0.5, 96.0 ** 2, float("inf"))
    assert (small.n_gt, small.n_det, small.recall, small.precision) == (1, 1, 1.0, 1.0)
    assert (medium.n_gt, medium.n_det, medium.recall, medium.precision) == (1, 2, 1.0, 0.5)
    assert medium.ap == pytest.approx(0.5)  # the false positive outranks the hit
    assert (large.n_gt, large.n_det) == (0, 0)


def test_a_detection_matches_a_counted_box_before_an_ignored_one():
    """COCOeval's order: a small detection overlapping a small box best (IoU 0.94, ignored in the medium bucket)
    and a medium one (IoU 0.83) counts there as finding the medium one."""
    g = GroundTruth("a.jpg", np.array([_box(0, 0, 30), _box(0, 0, 34)], float), ["car", "car"])
    medium = score_area([([_d(_box(0, 0, 31))], g)], "car", 0.5, 32.0 ** 2, 96.0 ** 2)
    assert (medium.n_gt, medium.n_det, medium.recall) == (1, 1, 1.0)


def test_hit_uav_names_give_altitude_and_view_angle():
    assert hit_uav_meta("0_100_30_0_03280.jpg") == FrameMeta(altitude_m=100.0, view_angle_deg=30.0)
    assert hit_uav_meta("1_60_90_0_00012.jpg") == FrameMeta(altitude_m=60.0, view_angle_deg=90.0)
    assert hit_uav_meta("DJI-00760-00001.jpg") is None
    names = ["0_100_30_0_03280.jpg", "DJI-00760-00001.jpg"]
    assert frame_meta(names, "auto") == {}  # not every name is HIT-UAV's: nothing recorded
    assert frame_meta(names, "none") == {}
    with pytest.raises(ValueError, match=r"--frame-meta hit-uav: file name 'DJI-00760-00001.jpg'"):
        frame_meta(names, "hit-uav")
    with pytest.raises(ValueError, match=r"--frame-meta must be one of .* got 'exif'"):
        frame_meta(names, "exif")


def test_view_angle_and_altitude_buckets_separate_frames_the_detector_fails_on():
    """Frames at 30° are missed entirely, frames at 90° found: recall 0 and 1 in those view-angle buckets, while
    both altitudes hold one frame of each and show 0.5."""
    gts = _frames(4)
    names = ["0_60_30_0_1.jpg", "0_60_90_0_2.jpg", "0_120_30_0_3.jpg", "0_120_90_0_4.jpg"]
    for g, n in zip(gts, names):
        g.file = n
    per = [([] if "_30_" in g.file else [_d(tuple(b)) for b in g.boxes], g) for g in gts]
    out = breakdown(per, ["car"], frame_meta(names))
    assert out["by_view_angle"]["car"]["30"]["recall@0.5"] == 0.0
    assert out["by_view_angle"]["car"]["90"]["recall@0.5"] == 1.0
    assert out["by_view_angle"]["car"]["30"]["n_gt"] == 6
    assert out["by_altitude"]["car"]["60"]["recall@0.5"] == out["by_altitude"]["car"]["120"]["recall@0.5"] == 0.5
    lines = breakdown_lines(out)
    assert "  view angle deg     30 car: R 0.00 P 0.00 AP50 0.00 (n 6, det 0)" in lines
    assert any(ln.startswith("  size  small car: R 0.50") for ln in lines)
    assert "by_view_angle" not in breakdown(per, ["car"], {})  # a set that records no angle gets no such table


def test_bench_detect_frame_meta_hit_uav_on_other_names_exits_2_before_inference(tmp_path, capsys):
    import cv2

    from aerodaas.cli import main

    (tmp_path / "im").mkdir()
    (tmp_path / "lab").mkdir()
    cv2.imwrite(str(tmp_path / "im" / "DJI-1.jpg"), np.zeros((64, 64, 3), np.uint8))
    (tmp_path / "lab" / "DJI-1.txt").write_text("0 0.5 0.5 0.2 0.2\n")
    rc = main(["bench", "detect", "--images", str(tmp_path / "im"), "--annotations", str(tmp_path / "lab"),
               "--names", "car", "--frame-meta", "hit-uav", "--model", "no_such_model"])
    assert rc == 2
    assert "--frame-meta hit-uav: file name 'DJI-1.jpg'" in capsys.readouterr().err
