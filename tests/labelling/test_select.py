"""The selection (:func:`aerodaas.labelling.select.select_frames`): near-duplicates dropped, held-out flights never
read, the budget and per-flight quotas kept, the same picks for the same seed, the image-list API."""
from __future__ import annotations

from pathlib import Path

import cv2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aerodaas.labelling.scoring import Detectors
from aerodaas.labelling.select import SelectOptions, flight_quotas, select_frames, select_images
from aerodaas.labelling.sources import LabelInputError, VideoSource
from tests.labelling.footage import scene, write_video

FPS = 4


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> dict[str, Path]:
    """Three flights: each scene held for 2 s (8 identical frames at 4 fps), different scenes per flight."""
    d = tmp_path_factory.mktemp("videos")
    return {"A": write_video(d / "A_0001.mp4", [k for k in range(0, 4) for _ in range(8)], FPS),
            "B": write_video(d / "B_0002.mp4", [k for k in range(10, 13) for _ in range(8)], FPS),
            "C": write_video(d / "C.mp4", [k for k in range(20, 26) for _ in range(8)], FPS)}


def _names(sel) -> list[str]:
    return [c.ref.name for c in sel.picked]


def test_near_duplicates_are_dropped(videos, picture_detectors):
    """Every frame is a candidate at 4/s, but 8 repeats of a scene are one candidate: as many as scenes, and a
    budget of one per scene picks one frame of each."""
    sel = select_frames([VideoSource(videos["A"])], SelectOptions(budget=4, rate=FPS, uniform=True), picture_detectors)
    assert sel.read == {"A-0001": 32}
    assert sel.candidates == {"A-0001": 4}
    assert sorted(c.ref.index // 8 for c in sel.picked) == [0, 1, 2, 3]


def test_candidates_are_sampled_at_most_rate_per_second(videos, picture_detectors):
    """At 1/s, 8 of the 32 frames are decoded (one per second, 2 per scene) and the repeats among them dropped."""
    sel = select_frames([VideoSource(videos["A"])], SelectOptions(budget=4, rate=1.0, uniform=True), picture_detectors)
    assert sel.read == {"A-0001": 8} and sel.candidates == {"A-0001": 4}
    times = sorted(c.ref.t_s for c in sel.picked)
    assert all(b - a >= 1.0 for a, b in zip(times, times[1:]))
    with pytest.raises(LabelInputError, match="--rate 0"):
        SelectOptions(budget=1, rate=0).check()
    with pytest.raises(LabelInputError, match="--dedup-bits -1"):
        SelectOptions(budget=1, dedup_bits=-1).check()


def test_a_held_out_flight_is_never_read_nor_drawn(videos, picture_detectors):
    srcs = [VideoSource(p) for p in videos.values()]
    sel = select_frames(srcs, SelectOptions(budget=7, rate=FPS, held_out=["B_0002"]), picture_detectors)
    assert {c.ref.flight for c in sel.picked} == {"A-0001", "C"}
    assert "B-0002" not in sel.read and len(sel.picked) == 7
    # A and C have 4 + 6 candidates: 11 frames cannot come from them, whatever B holds
    with pytest.raises(LabelInputError, match=r"--budget 11: only 10 candidate"):
        select_frames(srcs, SelectOptions(budget=11, rate=FPS, held_out=["B-0002"], uniform=True), picture_detectors)


def test_a_held_out_name_matching_no_flight_is_refused(videos, picture_detectors):
    with pytest.raises(LabelInputError, match=r"--held-out 'D': matches no input flight .*A-0001"):
        select_frames([VideoSource(videos["A"])], SelectOptions(budget=1, held_out=["D"]), picture_detectors)


def test_the_budget_and_the_quota_per_flight_are_kept(videos, picture_detectors):
    srcs = [VideoSource(p) for p in videos.values()]
    sel = select_frames(srcs, SelectOptions(budget=9, rate=FPS, per_flight_quota=4, pool_factor=1), picture_detectors)
    per = {f: sum(c.ref.flight == f for c in sel.picked) for f in sel.candidates}
    assert len(sel.picked) == 9 and len(set(_names(sel))) == 9
    assert max(per.values()) <= 4 and per == sel.quotas
    assert per["B-0002"] == 3 or per["A-0001"] + per["C"] == 6  # spread: no flight left short while another is over
    with pytest.raises(LabelInputError, match=r"--budget 10: only 9 candidate frame\(s\) available, at most 3"):
        select_frames(srcs, SelectOptions(budget=10, rate=FPS, per_flight_quota=3), picture_detectors)


@settings(max_examples=100, deadline=None)
@given(st.dictionaries(st.sampled_from("abcdefg"), st.integers(0, 30), min_size=1), st.integers(1, 60),
       st.one_of(st.none(), st.integers(1, 20)), st.integers(0, 3))
def test_quotas_spread_the_budget_as_evenly_as_the_flights_allow(avail, budget, cap, seed):
    limit = {f: min(n, cap) if cap else n for f, n in avail.items()}
    if sum(limit.values()) < budget:
        with pytest.raises(LabelInputError, match=f"only {sum(limit.values())} candidate"):
            flight_quotas(avail, budget, cap, seed)
        return
    q = flight_quotas(avail, budget, cap, seed)
    assert sum(q.values()) == budget and all(0 <= q[f] <= limit[f] for f in avail)
    short = [f for f in avail if q[f] < limit[f]]  # could take more: none has two fewer than another
    assert all(q[f] >= max(q.values()) - 1 for f in short)


class _Blind:
    """A detector that sees nothing: every frame is equally informative, so only the seed orders them."""

    def detect(self, image):
        return []


@pytest.mark.parametrize("uniform", [False, True])
def test_the_same_seed_picks_the_same_frames_and_the_seed_matters(videos, uniform):
    srcs = [VideoSource(p) for p in videos.values()]
    det = Detectors(_Blind(), _Blind(), 0.3, 0.15, ["car"], ["car"], "blind@0", "stub")

    def picks(seed: int) -> tuple[str, ...]:
        opts = SelectOptions(budget=5, rate=FPS, seed=seed, pool_factor=2, uniform=uniform)
        return tuple(_names(select_frames(srcs, opts, det)))

    assert picks(3) == picks(3)
    assert len({picks(s) for s in range(4)}) > 1


def test_images_with_flight_ids_are_selected_by_the_same_rules(tmp_path, picture_detectors):
    """The few-shot API: image files and their flights; repeats dropped, the picks' sources are the files."""
    paths, flights = [], []
    for f, ks in (("DJI_0025", [1, 1, 2, 3]), ("DJI_0026", [4, 5, 5, 5])):
        for i, k in enumerate(ks):
            p = tmp_path / f"{f}-{i:04d}.png"
            cv2.imwrite(str(p), scene(k))
            paths.append(str(p))
            flights.append(f)
    sel = select_images(paths, flights, SelectOptions(budget=5, seed=1, pool_factor=2), picture_detectors)
    assert sel.candidates == {"DJI-0025": 3, "DJI-0026": 2}
    assert {c.ref.source for c in sel.picked} == {paths[i] for i in (0, 2, 3, 4, 5)}
    with pytest.raises(LabelInputError, match="same length"):
        select_images(paths, flights[:-1], SelectOptions(budget=1), picture_detectors)
