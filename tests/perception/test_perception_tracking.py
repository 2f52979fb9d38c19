"""ByteTrack: stable ids, the low-score association, re-acquisition after occlusion."""
from __future__ import annotations

import pytest

from aerodaas.model.types import Detection
from aerodaas.perception.tracking import ByteTrackConfig, ByteTracker


def _car(x, y, score=0.8, w=40, h=20):
    return Detection(class_id=2, class_name="car", score=score, box=(x, y, x + w, y + h))


def test_two_moving_cars_keep_their_ids():
    tr = ByteTracker()
    ids = []
    for k in range(40):
        a, b = _car(10 + 5 * k, 100), _car(400 - 5 * k, 160)  # pass each other 60 px apart vertically
        out = tr.update([b, a] if k % 2 else [a, b])
        ids.append({t.track_id: round(t.detection.box[1]) for t in out})
    assert all(i == {1: 100, 2: 160} for i in ids)


def test_low_score_frames_keep_the_track_and_occlusion_reacquires_the_same_id():
    tr = ByteTracker(ByteTrackConfig(track_buffer=10))
    seen = []
    for k in range(30):
        x = 10 + 4 * k
        if 10 <= k < 14:
            dets = [_car(x, 100, score=0.15)]  # partly occluded: only a low score (the BYTE step)
        elif 18 <= k < 24:
            dets = []  # fully hidden for 6 frames: lost, predicted on
        else:
            dets = [_car(x, 100)]
        seen.append([t.track_id for t in tr.update(dets)])
    assert all(s == [1] for s in seen[:18])  # the low-score frames did not break the track
    assert all(s == [] for s in seen[18:24])
    assert all(s == [1] for s in seen[24:])  # re-acquired under its old id
    assert tr.next_id == 2


def test_a_lost_track_past_its_buffer_gets_a_new_id():
    tr = ByteTracker(ByteTrackConfig(track_buffer=3))
    tr.update([_car(10, 10)])
    for _ in range(5):
        tr.update([])
    tr.update([_car(10, 10)])
    out = tr.update([_car(10, 10)])  # a new track is confirmed on its second frame
    assert [t.track_id for t in out] == [2]


def test_tracker_options_checked():
    with pytest.raises(ValueError, match=r"tracker.low_threshold=0.5 is above high_threshold=0.3"):
        ByteTracker(ByteTrackConfig(low_threshold=0.5))
    with pytest.raises(ValueError, match=r"tracker.track_buffer .* got 0"):
        ByteTracker(ByteTrackConfig(track_buffer=0))
