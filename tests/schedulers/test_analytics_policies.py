"""Behavioural tests of the analytics-scheduler policies (Ocularone baselines, E+C, DEM, DEMS, DEMS-A, GEMS,
GAINPLAN, EVPLAN and LAPLAN) and of the exact single-machine planner, with hand-built scenarios whose right answer is derived in the comments, plus invariants and
utility orderings on seeded traces driven by the policy harness (``aerodaas/bench/harness.py``)."""
from __future__ import annotations

import random

import pytest
from aerodaas.schedulers.analytics_base import (
    AnalyticsTask,
    TaskState,
    Workload,
    analytics_scheduler_names,
    make_analytics_scheduler,
)
from aerodaas.schedulers.analytics_dems import CloudLatencyEstimator

from tests.conftest import needs_workload
from tests.schedulers.analytics_harness import Harness, make_trace, run_policy
from tests.schedulers.hand_workload import ALL, EDGE_ONLY, TW, WORKLOAD_JSON, busy, c1_then_a1, cloud_done, kinds, task


# --------------------------------------------------------------------------------------------- registry
def test_every_scheduler_is_registered_under_its_name():
    assert set(ALL) <= set(analytics_scheduler_names())
    for name in ALL:
        assert make_analytics_scheduler(name, TW).name == name


# --------------------------------------------------------------------------------------------- edge-only baselines
@pytest.mark.parametrize("name,order", [
    ("EDGE_FIFO", "CBDA"),  # arrival order
    ("EDGE_EDF", "ADCB"),   # relative deadline 400 < 450 < 500 < 600
    ("EDGE_SJF", "DACB"),   # edge 100 (D before A: FIFO tie) < 150 < 300
    ("EDGE_HBF", "DBCA"),   # benefit 300 > 200 > 60 > 50
    ("EDGE_HUF", "DBAC"),   # benefit - edge cost 299 > 195 > 49 > 20
])
def test_edge_only_queue_order(name, order):
    pol = make_analytics_scheduler(name, TW)
    busy(pol, 0.0, "A")
    queued = [task(m, 1.0, 10_000) for m in "CBDA"]
    for t in queued:
        assert pol.submit(t, 1.0) == []
    pol.on_edge_done(pol.edge_running, 100.0, 100.0)
    ran = []
    for now in (100, 400, 700, 1000):
        t, decisions = pol.next_edge_task(float(now))
        assert decisions == []
        ran.append(t.model)
        pol.on_edge_done(t, now + TW[t.model].edge_ms, TW[t.model].edge_ms)
    assert "".join(ran) == order


def test_edge_only_expires_tasks_that_can_no_longer_finish_instead_of_running_them_late():
    # Reference TaskExecutorEdge: run only if edge_ms < deadline - now, else EXPIRED_EDGE.
    pol = make_analytics_scheduler("EDGE_FIFO", TW)
    busy(pol, 0.0, "B")                      # edge busy until 300
    late, ok = task("A", 10.0, 350.0), task("A", 20.0, 500.0)
    pol.submit(late, 10.0)
    pol.submit(ok, 20.0)
    got, decisions = pol.next_edge_task(300.0)  # 300 + 100 > 350: expired; 300 + 100 <= 500: runs
    assert got is ok
    assert kinds(decisions) == [("drop", late, TaskState.EXPIRED_EDGE)]


@needs_workload
@pytest.mark.parametrize("name", EDGE_ONLY)
def test_edge_only_never_uses_the_cloud_and_cloud_never_uses_the_edge(name):
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    r = run_policy(name, w, make_trace(w, duration_s=20, seed=3))
    assert not r.cloud_sends and r.edge_starts
    assert r.states[TaskState.EXPIRED_EDGE] > 0 and r.states[TaskState.DONE_LATE] == 0
    c = run_policy("CLOUD", w, make_trace(w, duration_s=20, seed=3))
    assert not c.edge_starts and c.cloud_sends
    # BP has benefit 40 < cloud cost 43: every BP task is dropped for cost, every other one runs on the cloud
    assert {t.model for t in c.tasks if t.state is TaskState.DROPPED_COST} == {"BP"}


@needs_workload
def test_cloud_only_falls_back_to_the_edge_while_the_cloud_is_lost():
    """A lost cloud node must not stop a mission's analytics: CLOUD runs new tasks on the edge (FIFO, never late)
    while no cloud is reachable, and sends to the cloud again when it returns."""
    w = Workload.from_file(WORKLOAD_JSON, "LIGHT")
    down = (5_000.0, 12_000.0)
    r = run_policy("CLOUD", w, make_trace(w, duration_s=20, seed=3), cloud_down=[down])
    assert r.edge_starts and all(down[0] <= t.arrival_ms < down[1] for t, _ in r.edge_starts)
    assert all(not (down[0] <= s < down[1]) for _, s in r.cloud_sends)
    assert any(s >= down[1] for _, s in r.cloud_sends)              # back on the cloud afterwards
    during = [t for t in r.tasks if down[0] <= t.arrival_ms < down[1] - 1_000]
    assert sum(t.state is TaskState.DONE_ON_TIME for t in during) > 0.9 * len(during)   # LIGHT fits on the edge
    assert r.states[TaskState.DONE_LATE] == 0


# --------------------------------------------------------------------------------------------- E+C and DEM
def test_e_plus_c_inserts_at_the_edf_slot_never_evicts_and_sends_rejects_to_the_cloud_at_once():
    pol, c1, a1, decisions = c1_then_a1("E+C")
    assert decisions == [] and list(pol.queue) == [a1, c1]  # A1 inserted ahead; C1 is NOT evicted
    b2 = task("B", 20.0)                              # behind both: 20 + 280 + 250 + 300 > 620: rejected
    assert kinds(pol.submit(b2, 20.0)) == [("cloud", b2, None)]  # to the cloud at once: 20 + 350 <= 620
    assert pol.next_poll_ms() is None
    pol.on_edge_done(pol.edge_running, 300.0, 300.0)
    assert pol.next_edge_task(300.0) == (a1, [])
    pol.on_edge_done(a1, 400.0, 100.0)
    got, decisions = pol.next_edge_task(400.0)        # C1 would end at 550 > 500: expires at the head
    assert got is None and kinds(decisions) == [("drop", c1, TaskState.EXPIRED_EDGE)]


def test_dem_evicts_only_when_the_victims_score_less_and_migrates_at_once():
    pol, c1, a1, decisions = c1_then_a1("DEM")
    # C1's score 20 (cloud utility < 0: |60 - 40|) >= A1's 9: A1 is rejected and migrated at once (10 + 200 <= 410)
    assert kinds(decisions) == [("cloud", a1, None)]
    assert list(pol.queue) == [c1]
    d1 = task("D", 40.0)
    # D1 (prio 450 < 500) at slot 0: 40 + 260 + 100 = 400 <= 490; C1 then ends at 550 > 500; 20 < D1's 199:
    # C1 is evicted; DEM keeps no candidates, so C1 (cloud utility -10) is dropped for cost
    assert kinds(pol.submit(d1, 40.0)) == [("drop", c1, TaskState.DROPPED_COST)]
    assert list(pol.queue) == [d1]
    assert pol.next_poll_ms() is None and pol.held_tasks() == [d1]


@pytest.mark.parametrize("b1_deadline,evicted", [(520.0, False), (700.0, True)])
def test_eviction_compares_the_summed_score_of_all_victims(b1_deadline, evicted):
    pol = make_analytics_scheduler("DEMS", TW, eviction_scan="full")
    busy(pol, 0.0, "A")                               # running until 100
    d1, b1 = task("D", 0.0, 300.0), task("B", 0.0, b1_deadline)
    pol.submit(d1, 0.0)                               # 100 + 100 = 200 <= 300
    pol.submit(b1, 0.0)                               # 200 + 300 = 500 <= 520
    e1 = task("E", 0.0, 400.0)                        # slot 0 (420 < 450): 100 + 250 = 350 <= 400
    decisions = pol.submit(e1, 0.0)
    # behind E1: D1 ends at 450 > 300 (victim, score 199); B1 at 650: a victim too if its deadline is 520
    # (score 145). 199 + 145 = 344 >= E1's 299: E1 is rejected although each victim alone scores less; with B1's
    # deadline at 700 only D1 is a victim (199 < 299): E1 goes in and D1 is evicted.
    assert decisions == []                            # everything off the edge is held (triggers > now + 50)
    if evicted:
        assert list(pol.queue) == [e1, b1] and d1 in pol.tentative.tasks()
    else:
        assert list(pol.queue) == [d1, b1] and e1 in pol.tentative.tasks()


def test_reference_eviction_scan_neither_checks_nor_counts_the_first_task_behind_the_insertion_point():
    """PriorityQueue.add: the outer iterator has consumed the first task behind the insertion point when the victim
    scan starts, so that task is never checked and its edge time is not in the running finish time."""
    pol, c1, a1, decisions = c1_then_a1("DEM", eviction_scan="reference")
    assert decisions == [] and list(pol.queue) == [a1, c1]  # C1 (would end at 550 > 500) is not checked
    pol = make_analytics_scheduler("DEMS", TW)              # the default scan is the reference's
    assert pol.eviction_scan == "reference"
    busy(pol, 0.0, "A")                                     # running until 100
    b1, b2 = task("B", 0.0, 700.0), task("B", 0.0, 720.0)
    pol.submit(b1, 0.0)                                     # 100 + 300 = 400 <= 700
    pol.submit(b2, 0.0)                                     # 700 <= 720
    d1 = task("D", 0.0, 250.0)                              # slot 0: 100 + 100 = 200 <= 250
    # reference: B1 skipped (not counted either), B2 checked from D1's end: 200 + 300 = 500 <= 720, kept.
    # full scan: B1 ends at 500 <= 700, B2 at 800 > 720: a victim (145 < D1's 199) -- see the next assertion
    assert pol.submit(d1, 0.0) == [] and list(pol.queue) == [d1, b1, b2]
    full = make_analytics_scheduler("DEMS", TW, eviction_scan="full")
    busy(full, 0.0, "A")
    for t in (task("B", 0.0, 700.0), task("B", 0.0, 720.0)):
        full.submit(t, 0.0)
    full.submit(task("D", 0.0, 250.0), 0.0)
    assert len(full.queue) == 2 and len(full.tentative) == 1 and full.counters["evicted"] == 1
    with pytest.raises(ValueError, match="eviction_scan"):
        make_analytics_scheduler("DEM", TW, eviction_scan="partial")


# --------------------------------------------------------------------------------------------- DEMS
def test_dems_rejected_task_is_held_until_its_trigger_and_released_in_the_jit_window():
    pol, c1, a1, decisions = c1_then_a1("DEMS")       # rejected as in the DEM test, but held: no decision now
    assert decisions == []
    assert a1.notes["trigger_ms"] == 410 - 200 - 10   # cloud trigger = deadline - cloud - 10 = 200
    assert pol.next_poll_ms() == 150.0                # acted on 50 ms early
    assert pol.poll(149.0) == []
    assert kinds(pol.poll(150.0)) == [("cloud", a1, None)]
    assert pol.cloud_admit(a1, 150.0)                 # 150 + 200 <= 410


@pytest.mark.parametrize("poll_at,expected", [(210.0, "cloud"), (211.0, "drop")])
def test_dems_drops_a_held_task_polled_more_than_10_ms_past_its_trigger(poll_at, expected):
    pol, c1, a1, _ = c1_then_a1("DEMS")               # A1 held, trigger 200
    # trigger - now = -10: still released; -11: dropped for time
    want = ("cloud", a1, None) if expected == "cloud" else ("drop", a1, TaskState.DROPPED_TIME)
    assert kinds(pol.poll(poll_at)) == [want]


def test_dems_eviction_holds_cost_victims_for_stealing_and_drops_them_for_cost_when_unstolen():
    pol = make_analytics_scheduler("DEMS", TW, eviction_scan="full")
    busy(pol, 0.0, "B")
    c1 = task("C", 0.0)
    pol.submit(c1, 0.0)
    d1 = task("D", 40.0)
    assert pol.submit(d1, 40.0) == []                 # C1 evicted (20 < 199) but only held, not terminal
    assert list(pol.queue) == [d1] and c1 in pol.held_tasks() and c1.state is TaskState.PENDING
    assert c1.notes["trigger_ms"] == 500 - 150 - 10   # keyed by its edge trigger
    assert pol.next_poll_ms() == 340 - 50
    assert pol.poll(289.0) == []
    assert kinds(pol.poll(290.0)) == [("drop", c1, TaskState.DROPPED_COST)]
    assert c1 not in pol.held_tasks()


def test_dems_insertion_position_and_eviction_of_every_task_behind_that_would_miss():
    pol = make_analytics_scheduler("DEMS", TW, eviction_scan="full")
    busy(pol, 0.0, "A")                               # running until 100
    b1, b2 = task("B", 0.0, 700.0), task("B", 0.0, 1000.0)
    pol.submit(b1, 0.0)                               # 0 + 100 + 300 = 400 <= 700
    pol.submit(b2, 0.0)                               # 700 <= 1000
    a1 = task("A", 0.0, 10_000.0)                     # prio 400: ahead of both B (600)
    assert pol.submit(a1, 0.0) == [] and list(pol.queue) == [a1, b1, b2]
    d1 = task("D", 5.0, 560.0)                        # prio 450: after A1, before B1: 5 + 95 + 100 + 100 = 300
    # B1 would end at 600 <= 700 (kept); B2 at 900 <= 1000 (kept): no victim
    assert pol.submit(d1, 5.0) == [] and list(pol.queue) == [a1, d1, b1, b2]
    d2 = task("D", 6.0, 500.0)                        # after D1 (FIFO tie): 6 + 94 + 200 + 100 = 400 <= 500
    # B1 would end at 700 (<= 700, kept), B2 at 1000 (kept)
    assert pol.submit(d2, 6.0) == [] and list(pol.queue) == [a1, d1, d2, b1, b2]
    d3 = task("D", 7.0, 520.0)                        # after D2: 7 + 93 + 300 + 100 = 500 <= 520
    # behind it B1 would end at 800 > 700: a victim (score 145 < D3's 199), evicted; B2 then ends at
    # 500 + 300 = 800 <= 1000 (the evicted B1 no longer occupies the edge): kept
    assert pol.submit(d3, 7.0) == []
    assert list(pol.queue) == [a1, d1, d2, d3, b2]
    assert b1 in pol.tentative.tasks() and b1.notes["trigger_ms"] == 700 - 350 - 10  # held for the cloud


def test_dems_work_stealing_when_idle_takes_the_best_ranked_task_that_fits():
    pol = make_analytics_scheduler("DEMS", TW)
    d_late, c, b = task("D", 0.0, 90.0), task("C", 0.0, 500.0), task("B", 0.0, 600.0)
    pol.tentative.add(d_late, 1000.0, "cloud")        # rank 1990 but 0 + 100 > 90: cannot fit
    pol.tentative.add(b, 240.0, "cloud")              # rank 483
    pol.tentative.add(c, 340.0, "cost")               # rank 1200
    assert pol.next_edge_task(0.0) == (c, [])
    pol.on_edge_done(c, 150.0, 150.0)
    assert pol.next_edge_task(150.0) == (b, [])       # D still cannot fit; B: 150 + 300 <= 600
    pol.on_edge_done(b, 450.0, 300.0)
    assert pol.next_edge_task(450.0) == (None, []) and pol.held_tasks() == [d_late]


def test_dems_work_stealing_in_slack_without_making_queued_tasks_miss():
    pol = make_analytics_scheduler("DEMS", TW)
    q1 = task("A", 0.0, 240.0)                        # head slack = 240 - 100 - 10 - 0 = 130 > min edge 100
    pol.queue.insert(q1)
    b, c, a = task("B", 0.0, 600.0), task("C", 0.0, 500.0), task("A", 0.0, 400.0)
    for t, key, kind in ((b, 240.0, "cloud"), (c, 340.0, "cost"), (a, 190.0, "cloud")):
        pol.tentative.add(t, key, kind)
    # C (rank 1200) and B (483) need 150 / 300 >= 130; A (100 < 130): A then Q1 ends at 200 <= 240: stolen
    assert pol.next_edge_task(0.0) == (a, [])
    pol.on_edge_done(a, 100.0, 100.0)

    pol2 = make_analytics_scheduler("DEMS", TW)
    q1, q2 = task("A", 0.0, 240.0), task("A", 0.0, 290.0)
    pol2.queue.insert(q1)
    pol2.queue.insert(q2)
    a2 = task("A", 0.0, 400.0)
    pol2.tentative.add(a2, 190.0, "cloud")
    # stealing A2 would end Q2 at 300 > 290: no steal, the head runs
    assert pol2.next_edge_task(0.0) == (q1, [])


def test_dems_cloud_rechecks_the_deadline_before_executing():
    pol = make_analytics_scheduler("DEMS", TW)
    a = task("A", 0.0)                                # deadline 400, cloud 200
    assert pol.cloud_admit(a, 200.0) and not pol.cloud_admit(a, 201.0)


# --------------------------------------------------------------------------------------------- DEMS-A
def test_latency_window_replaces_the_estimate_only_on_a_drift_over_10_ms():
    est = CloudLatencyEstimator(TW)
    for _ in range(9):
        est.observe("A", 215.0)
    assert est.estimate["A"] == 200.0                 # window not full yet
    est.observe("A", 215.0)
    assert est.estimate["A"] == 215.0                 # mean 215 drifts 15 > 10 from 200
    for _ in range(5):                                # sliding: the mean moves 2.5 ms per 240 ms sample
        est.observe("A", 240.0)
    assert est.estimate["A"] == 227.5                 # 215 + 12.5: replaced as soon as it drifts > 10
    for _ in range(5):
        est.observe("A", 240.0)
    assert est.estimate["A"] == 240.0
    for _ in range(10):
        est.observe("A", 248.0)                       # drift 8: kept
    assert est.estimate["A"] == 240.0


@pytest.mark.parametrize("name", ["DEMS-A", "GAINPLAN"])
def test_adaptive_latency_estimates_learn_from_completions_only(name):
    """A task refused by the cloud re-check or FAILED never ran: its reply time (here 30 ms) is no cloud round trip
    and must not pull the estimate down; completions, late ones included, do move it."""
    pol = make_analytics_scheduler(name, TW)
    for i in range(10):
        cloud_done(pol, "A", 100.0 + i, 30.0, TaskState.DROPPED_TIME)
        cloud_done(pol, "A", 200.0 + i, 30.0, TaskState.FAILED)
    assert pol.cloud_estimate_ms("A") == 200.0        # still the profile
    for i in range(10):
        cloud_done(pol, "A", 300.0 + i, 420.0, TaskState.DONE_LATE)
    assert pol.cloud_estimate_ms("A") == 420.0


def test_dems_a_cools_down_for_10_s_then_probes_with_the_profile_and_snaps_to_the_probe_latency():
    pol = make_analytics_scheduler("DEMS-A", TW)
    for i in range(10):
        cloud_done(pol, "A", 100.0 + i, 500.0)
    assert pol.cloud_estimate_ms("A") == 500.0
    a1 = task("A", 1000.0)                            # 400 ms left < 500: fails the check, cool-down starts
    assert kinds(pol._off_edge(a1, 1000.0, "test")) == [("drop", a1, TaskState.DROPPED_TIME)]
    assert pol.cooling_since["A"] == 1000.0
    a2 = task("A", 6000.0)
    assert kinds(pol._off_edge(a2, 6000.0, "test")) == [("drop", a2, TaskState.DROPPED_TIME)]
    a3 = task("A", 11_001.0)                          # > 10 s later: probe with the profile's 200 ms
    assert pol._off_edge(a3, 11_001.0, "test") == []
    assert a3.notes["probe"] and a3.notes["cloud_ms"] == 200.0 and pol.cooling_since["A"] is None
    assert a3.notes["trigger_ms"] == 11_401 - 200 - 10
    assert kinds(pol.poll(11_141.0)) == [("cloud", a3, None)]
    assert pol.cloud_admit(a3, 11_141.0)              # re-checked with the probe's own 200 ms, not 500
    a3.state = TaskState.DONE_ON_TIME
    pol.on_cloud_done(a3, 11_371.0, 230.0)
    assert pol.cloud_estimate_ms("A") == 230.0        # window refilled with the probe's latency


def test_dems_a_on_time_cloud_completion_ends_a_cool_down():
    pol = make_analytics_scheduler("DEMS-A", TW)
    for i in range(10):
        cloud_done(pol, "A", 100.0 + i, 500.0)
    pol._off_edge(task("A", 1000.0), 1000.0, "test")
    assert pol.cooling_since["A"] == 1000.0
    cloud_done(pol, "A", 1500.0, 480.0)
    assert pol.cooling_since["A"] is None


def test_dems_a_adapts_and_beats_dems_when_cloud_latency_rises():
    # +300 ms on every cloud call: DEMS keeps releasing just in time with the profile and everything it sends
    # is late (cost, no benefit); DEMS-A learns the latency after 10 samples.
    rng = random.Random(1)
    trace = []
    for k in range(300):                              # 500 ms of edge work every 250 ms: half must go to the cloud
        t = k * 250.0 + rng.uniform(0, 20)
        trace += [task(m, t) for m in "ADB"]
    res = {n: Harness(make_analytics_scheduler(n, TW), cloud_extra_ms=300.0).run(
        [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in trace]) for n in ("DEMS", "DEMS-A")}
    assert res["DEMS-A"].utility > res["DEMS"].utility
    assert res["DEMS-A"].states[TaskState.DONE_LATE] < res["DEMS"].states[TaskState.DONE_LATE]
