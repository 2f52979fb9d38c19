"""LAPLAN's burst/idle-aware arrival predictor on synthetic bursty arrivals.

Frames are fed as tasks (one model per frame unless said) to :class:`BurstArrivalPredictor`; the predictions are
read back from :meth:`predict`. Covers: within a burst it predicts the burst's gap (not the silence before it);
after an idle gap longer than the burst's it predicts idle; a burst that has reached the length of the drone's
earlier bursts is predicted to end; a flush (the same model twice within a few ms) does not move the drone's phase;
heavy-tailed gaps are predicted from the gap given the wait, later the longer the drone is silent; and LAPLAN with
``arrivals="burst"`` passes the cut comparison of ``test_non_anticipation`` (isolated, secret seeds).
"""
from __future__ import annotations

import pytest

from aerodaas.schedulers.analytics_arrivals import ArrivalPredictor, BurstArrivalPredictor
from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload
from aerodaas.schedulers.analytics_laplan import LaPlan

from tests.conftest import DATA_DIR, needs_workload

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"


def feed(pred, times, drone="d0", models=("DEO",)):
    n = len(pred.drones) * 10_000
    for t in times:
        for m in models:
            n += 1
            pred.observe(AnalyticsTask(n, drone, m, t, t + 950.0))
    return pred


def frames(pred, now, horizon=2000.0, drone="d0"):
    """The predicted frame times of ``drone`` (one per frame) and their weights."""
    got = sorted({(frame, w) for _, d, _, _, frame, w in pred.predict(now, horizon) if d == drone})
    return [f for f, _ in got], [w for _, w in got]


def onoff(bursts, frames_per_burst=6, gap=500.0, off=3000.0, start=0.0):
    """Frame times of ``bursts`` on/off bursts: ``frames_per_burst`` frames ``gap`` ms apart, then ``off`` ms idle."""
    cycle = frames_per_burst * gap + off
    return [start + b * cycle + k * gap for b in range(bursts) for k in range(frames_per_burst)]


def test_within_a_burst_it_predicts_the_burst_rate_not_the_silence_before():
    times = onoff(1) + [6000.0]        # one burst, 3.5 s of silence, then the next burst's first frame
    pred = feed(BurstArrivalPredictor(), times)
    got, weights = frames(pred, 6000.0)
    assert got[:4] == [6500.0, 7000.0, 7500.0, 8000.0]   # the burst's 500 ms, not the 3.5 s gap
    assert set(weights) == {1.0}


def test_after_an_idle_gap_longer_than_the_bursts_it_predicts_idle():
    pred = feed(BurstArrivalPredictor(), onoff(1))    # the burst's last frame at 2500 ms
    assert frames(pred, 2900.0)[0][0] == 3000.0          # still within the burst's rhythm: next frame expected
    assert frames(pred, 3100.0)[0] == []                 # 600 ms since the last frame (> 500 + 10 %): idle


def test_a_burst_as_long_as_the_earlier_ones_is_predicted_to_end():
    times = onoff(4)   # bursts 2 and 3 are complete (6 frames each, after an idle gap); burst 4 is under way
    pred = feed(BurstArrivalPredictor(), times[:-3])    # 3 frames of the 4th burst seen
    s = pred.bursts["d0"]
    assert list(s.runs) == [6, 6] and s.run == 3
    assert frames(pred, times[-4])[0] == times[-3:]      # exactly the 3 frames left in the burst
    feed(pred, times[-3:])
    assert frames(pred, times[-1])[0] == []              # the burst is over: idle, although 500 ms have not passed
    feed(pred, [times[-1] + 3500.0])                     # the next burst begins: its rhythm again
    assert frames(pred, times[-1] + 3500.0)[0][:2] == [times[-1] + 4000.0, times[-1] + 4500.0]


def test_bursts_of_varying_length_are_not_cut_short():
    times = []
    t = 0.0
    for n in (3, 8, 5, 9):
        times += [t + k * 500.0 for k in range(n)]
        t = times[-1] + 4000.0
    pred = feed(BurstArrivalPredictor(), times)
    assert pred.frames_left("d0") == float("inf")
    assert frames(pred, times[-1])[0][:1] == [times[-1] + 500.0]


def test_a_flush_does_not_move_the_drones_phase():
    """A link stalls from 3,300 to 5,500 ms: the frames made at 4,000 and 5,000 ms arrive at 5,500 and 5,502; the
    next one is made (and arrives) at 6,000 ms, on the old grid, not 1 s after the flush."""
    pred = BurstArrivalPredictor()
    feed(pred, [0.0, 1000.0, 2000.0, 3000.0])
    feed(pred, [5500.0, 5502.0])        # within same_frame_ms: one frame that repeats its model, a flush
    assert pred.bursts["d0"].anchor == 3000.0
    assert frames(pred, 5510.0)[0][:2] == [6000.0, 7000.0]
    feed(pred, [6000.0])                # on the grid again: it becomes the anchor
    assert pred.bursts["d0"].anchor == 6000.0


def test_a_late_frame_without_a_flush_resets_the_phase():
    pred = feed(BurstArrivalPredictor(), [0.0, 1000.0, 2000.0, 3000.0, 4300.0])
    assert frames(pred, 4300.0)[0][:1] == [5300.0]


def test_heavy_tailed_gaps_are_predicted_from_the_gap_given_the_wait():
    xm, alpha = 1000.0 / 3, 1.5              # Pareto gaps of mean 1 s (the bursty sweep's pareto trace)
    t, times = 0.0, []
    for i in range(60):                      # the distribution's quantiles, in a scrambled (fixed) order
        times.append(round(t, 3))
        t += xm * (1.0 - ((7 * i) % 60 + 0.5) / 60) ** (-1.0 / alpha)
    pred = feed(BurstArrivalPredictor(quantile=0.5), times)
    assert not pred.regular("d0")
    last = times[-1]
    early, w_early = frames(pred, last + 1.0, horizon=10_000.0)
    late, _ = frames(pred, last + 1500.0, horizon=10_000.0)
    assert len(early) == 1 and w_early == [0.5]          # one frame, its gain weighted by its chance
    assert late[0] > early[0] and late[0] > last + 1500.0  # decreasing hazard: the longer the wait, the later
    gaps = sorted(b - a for a, b in zip(times, times[1:]))
    assert frames(pred, last + gaps[-1] + 1.0, horizon=1e9)[0] == []  # longer than any gap seen: no prediction


def test_periodic_frames_are_predicted_as_by_the_last_gap():
    from aerodaas.schedulers.analytics_arrivals import ArrivalPredictor
    times = [100.0 + 1000.0 * k for k in range(8)]
    a, b = feed(ArrivalPredictor(), times), feed(BurstArrivalPredictor(), times)
    assert [p[:5] for p in a.predict(7150.0, 2000.0)] == [p[:5] for p in b.predict(7150.0, 2000.0)]


def test_options_out_of_range_are_refused():
    for kw in ({"quantile": 1.0}, {"idle_factor": 1.0}, {"window": 2}, {"regular_share": 0.0}):
        with pytest.raises(ValueError, match=next(iter(kw))):
            BurstArrivalPredictor(**kw)


@needs_workload
def test_laplan_option_arrivals():
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    assert isinstance(LaPlan(w, arrivals="burst").arrivals, BurstArrivalPredictor)
    # the default, chosen on held-out seeds (500-507): the last-gap predictor stays as an option
    assert isinstance(LaPlan(w).arrivals, BurstArrivalPredictor)
    assert type(LaPlan(w, arrivals="last").arrivals) is ArrivalPredictor
    assert LaPlan(w, arrivals="last", gap_window=5).arrivals.gap_window == 5
    with pytest.raises(ValueError, match="arrivals"):
        LaPlan(w, arrivals="future")
    with pytest.raises(ValueError, match="gap_window"):
        LaPlan(w, arrivals="burst", gap_window=5)
    with pytest.raises(ValueError, match="gap_window"):
        LaPlan(w, gap_window=5)  # the default is the burst predictor: gap_window needs arrivals="last"


#: the bursty cut comparisons' instance: one edge of 2 drones for 10 s at 1 fps (the default case: 3 drones, 12 s);
#: smaller to keep the development tier fast, still long enough for an on/off cycle (3 s on, 3 s off)
BURSTY_DRONES, BURSTY_DURATION_S = 2, 10.0


def _cut_cases():
    from tests.schedulers import anticipation_cheats as cheats
    # the default trace: test_non_anticipation's LAPLAN case (its default predictor is this one)
    cases = [pytest.param(kind, "LAPLAN", False, id=kind) for kind in ("onoff", "pareto", "flush")]
    # the comparison must be able to fail on the same bursty instances: a policy handed the future is flagged.
    # PeekDraws: in 200 checks per kind (n_arrivals 16, about 41 cuts), flagged at < 2 cuts in 0 of 200 on onoff
    # (at 16 or more in every check) and on flush (at 6 or more); PeekArrivals was flagged at < 2 cuts in 6 of 200
    # onoff checks (2-drone traces leave few other-drone frames within its 400 ms look ahead), too often for a test
    cases += [pytest.param(kind, cheats.PeekDraws, True, id=f"{kind}-cheat-PeekDraws") for kind in ("onoff", "flush")]
    return cases


@needs_workload
@pytest.mark.parametrize("kind,policy,cheat", _cut_cases())
def test_laplan_with_the_burst_predictor_is_non_anticipative(kind, policy, cheat):
    """The cut comparison of ``test_non_anticipation`` (isolated, secret seeds) on each bursty kind, with cuts
    inside the bursts and the silences of the trace; and a cheat handed the future is flagged on the same bursty
    instance (at >= 2 cuts, as there)."""
    from tests.schedulers.test_non_anticipation import _heavy, check
    kw = {"kind": kind, "drones": BURSTY_DRONES, "duration_s": BURSTY_DURATION_S}
    if cheat:
        res = check(policy, _heavy(), n_arrivals=16, **kw)
        assert len(res.flagged) >= 2, f"{policy.__name__} flagged at {res.flagged} of {res.cuts}"
        return
    res = check(policy, _heavy(), options={"arrivals": "burst"}, **kw)  # LAPLAN with the burst predictor
    assert res.shape["burst"] and res.shape["silence"]
    assert res.flagged == [], f"anticipates at cuts {res.flagged} (seeds, recorded after the run: {res.seeds})"
