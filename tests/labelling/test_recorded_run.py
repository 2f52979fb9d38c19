"""Frames out of a recording a real run made (``apps/farm_survey.py`` on Ray, recorded): its camera channel is
found, every frame decodes, each comes with the odometry the run recorded nearest in time. Slow (a Ray run); the
development tier reads recordings written with the recorder's own calls (tests/labelling/test_sources.py)."""
from __future__ import annotations

import pytest

from aerodaas.labelling.select import SelectOptions, select_frames
from aerodaas.labelling.sources import McapSource
from aerodaas.recording.reader import read_messages
from aerodaas.runtime.driver import run_file
from tests.conftest import REPO

pytestmark = [pytest.mark.e2e, pytest.mark.slow]


def test_a_recorded_run_gives_frames_with_their_pose(ray_session, run_options, tmp_path, picture_detectors):
    rec = tmp_path / "farm_survey.mcap"
    run_options.record, run_options.speedup = str(rec), 20.0
    assert run_file(str(REPO / "apps" / "farm_survey.py"), run_options)[-1].outcome == "success"
    src = McapSource(rec)
    src.check()
    assert src.topics and all("/camera/" in t for t in src.topics)
    odom = {t: m["position"] for topic, _s, t, m in read_messages(rec) if topic.endswith("/odometry")}
    got = list(src.frames(lambda ref: ref.index % 10 == 0))
    assert len(got) >= 3 and len({tuple(r.pose["position"]) for r, _ in got}) > 1  # the drone moved
    for ref, img in got:
        assert img.ndim == 3 and ref.name.startswith("farm-survey_quadrotor-base-")
        assert ref.pose is not None and abs(ref.pose["dt_s"]) < 1.0
        t_ns = min(odom, key=lambda t: abs(t - src.start_ns - round(ref.pose["t_s"] * 1e9)))
        assert ref.pose["position"] == pytest.approx(odom[t_ns])
    # the simulator's farm camera shows one picture all flight: every frame after the first is a near-duplicate
    sel = select_frames([src], SelectOptions(budget=1, seed=0), picture_detectors)
    assert sel.read["farm-survey"] >= 10 and sel.candidates["farm-survey"] == 1 and len(sel.picked) == 1
