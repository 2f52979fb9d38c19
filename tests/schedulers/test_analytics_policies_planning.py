"""GEMS, GAINPLAN and the invariants every analytics scheduler keeps on random traces (non-anticipation among
them), on the hand-derivable workload of :mod:`tests.schedulers.hand_workload`."""
from __future__ import annotations

import itertools
import random

import pytest
from aerodaas.schedulers.analytics_base import (
    AnalyticsTask,
    TaskState,
    Workload,
    make_analytics_scheduler,
    task_utility,
)
from aerodaas.schedulers.analytics_gainplan import max_gain_edge_plan
from aerodaas.schedulers.analytics_laplan import ArrivalPredictor
from aerodaas.schedulers.single_machine import max_gain_schedule

from tests.conftest import needs_workload
from tests.schedulers.analytics_harness import Harness, Result, make_trace, run_policy
from tests.schedulers.hand_workload import ALL, TASK_IDS, TW, WORKLOAD_JSON, busy, cloud_done, kinds, task


# --------------------------------------------------------------------------------------------- GEMS
def _finish(pol, model: str, now: float, on_time: bool):
    t = task(model, now - 100, now + (1 if on_time else -1))
    t.tier, t.start_ms = "cloud", now - 100
    t.state = TaskState.DONE_ON_TIME if on_time else TaskState.DONE_LATE
    return pol.on_cloud_done(t, now, 100.0)


def test_gems_gatekeeper_sends_a_models_queued_tasks_to_the_cloud_below_90_percent_on_time():
    pol = make_analytics_scheduler("GEMS", TW)
    busy(pol, 0.0, "B")
    a1, c1 = task("A", 0.0, 1000.0), task("C", 0.0, 1000.0)
    pol.submit(a1, 0.0)
    pol.submit(c1, 0.0)
    for i in range(9):
        assert _finish(pol, "A", 10.0 + i, True) == []
    assert _finish(pol, "A", 20.0, False) == []       # 9/10 = 0.9: not below
    assert pol.on_time_fraction("A") == pytest.approx(0.9)
    got = _finish(pol, "A", 30.0, False)              # 9/11 < 0.9: A's queued task goes to the cloud
    assert kinds(got) == [("cloud", a1, None)] and list(pol.queue) == [c1]
    for i in range(5):
        _finish(pol, "C", 40.0 + i, False)            # C is below 0.9 but its cloud utility is negative: stays
    assert list(pol.queue) == [c1]


def test_gems_window_tumbles_every_20_s():
    pol = make_analytics_scheduler("GEMS", TW)
    _finish(pol, "A", 1000.0, False)
    assert pol.on_time_fraction("A") == 0.0
    _finish(pol, "A", 20_999.0, True)                 # still the first window [1000, 21000)
    assert pol.on_time_fraction("A") == 0.5
    _finish(pol, "A", 21_000.0, True)                 # a new window: counts restart
    assert pol.on_time_fraction("A") == 1.0
    busy(pol, 21_001.0, "B")
    a1 = task("A", 21_001.0, 30_000.0)
    pol.submit(a1, 21_001.0)
    assert list(pol.queue) == [a1]                    # 100% on time: nothing migrated


# --------------------------------------------------------------------------------------------- GAINPLAN
def _brute_force(items, start):
    best = 0.0
    for r in range(len(items) + 1):
        for sub in itertools.combinations(range(len(items)), r):
            t, ok = start, True
            for i in sorted(sub, key=lambda i: items[i][0]):
                t += items[i][1]
                ok &= t <= items[i][0]
            if ok:
                best = max(best, sum(items[i][2] for i in sub))
    return best


def test_max_gain_edge_plan_is_exact_and_feasible():
    rng = random.Random(7)
    for _ in range(200):
        n = rng.randint(0, 8)
        items = [(rng.uniform(50, 900), rng.choice([100, 142, 174, 244, 563, 739]), rng.uniform(-5, 200)) for _ in range(n)]
        chosen = max_gain_edge_plan(items, 0.0)
        t = 0.0
        for i in chosen:                              # returned in EDF order, each on time
            t += items[i][1]
            assert t <= items[i][0]
        assert [items[i][0] for i in chosen] == sorted(items[i][0] for i in chosen)
        assert sum(items[i][2] for i in chosen) == pytest.approx(_brute_force(items, 0.0))


def test_gainplan_gives_the_edge_to_the_higher_gain_task_where_dems_follows_edf():
    # Edge free at 0. A (deadline 150, gain 49 - 40 = 9) and B (deadline 320, gain 195 - 50 = 145) cannot both
    # finish (100 + 300 = 400 > 320). DEMS runs A (EDF head); GAINPLAN runs B.
    a, b = task("A", 0.0, 150.0), task("B", 0.0, 320.0)
    gp = make_analytics_scheduler("GAINPLAN", TW)
    gp.submit(a, 0.0)
    gp.submit(b, 0.0)
    assert gp.next_edge_task(0.0)[0] is b
    dems = make_analytics_scheduler("DEMS", TW)
    dems.submit(AnalyticsTask(1, "d0", "A", 0.0, 150.0), 0.0)
    assert dems.next_edge_task(0.0)[0].model == "A"


def test_gainplan_releases_to_the_cloud_at_the_trigger_unless_about_to_run_and_drops_cost_tasks_that_no_longer_fit():
    gp = make_analytics_scheduler("GAINPLAN", TW)
    running = busy(gp, 0.0, "B")                      # edge busy until 300
    a1 = task("A", 0.0)                               # deadline 400, trigger 400 - 200 - 10 = 190
    c1 = task("C", 0.0, 420.0)                        # no cloud option; fits until 420 - 150 = 270
    assert gp.submit(a1, 0.0) == [] and gp.submit(c1, 0.0) == []
    assert gp.next_poll_ms() == 140.0
    # at 140 the edge frees at 300: C1 would end at 450 > 420 (dropped for cost: it can no longer fit anywhere);
    # the plan from 300 is {A1}, starting as soon as the edge frees: committed to the edge, not released
    assert kinds(gp.poll(140.0)) == [("drop", c1, TaskState.DROPPED_COST)]
    assert a1.notes["mode"] == "committed" and gp.next_poll_ms() is None
    gp.on_edge_done(running, 300.0, 300.0)
    assert gp.next_edge_task(300.0) == (a1, [])


def test_gainplan_releases_a_task_the_plan_does_not_start_soon_at_its_cloud_trigger():
    gp = make_analytics_scheduler("GAINPLAN", TW)
    running = busy(gp, 0.0, "B")                      # edge busy until 300
    for i in range(12):                               # offered edge load > 1: commit only imminent tasks
        gp._recent.append((0.0, 300.0))
    d1 = task("D", 0.0, 560.0)                        # gain 199, runs 300-400
    d2 = task("D", 0.0, 580.0)                        # gain 199, runs 400-500
    a1 = task("A", 0.0, 520.0)                        # gain 9, trigger 310: in the plan at 500-600? 600 > 520: no
    for t in (d1, d2, a1):
        assert gp.submit(t, 0.0) == []
    decisions = gp.poll(a1.deadline_ms - 200 - 10 - 50)
    assert kinds(decisions) == [("cloud", a1, None)]
    assert running.state is TaskState.PENDING


def test_gainplan_latency_estimate_reacts_to_one_late_sample():
    gp = make_analytics_scheduler("GAINPLAN", TW)
    assert gp.cloud_estimate_ms("A") == 200.0
    cloud_done(gp, "A", 1000.0, 320.0)
    assert gp.cloud_estimate_ms("A") == 320.0
    for i in range(5):
        cloud_done(gp, "A", 2000.0 + i, 205.0)
    assert gp.cloud_estimate_ms("A") == 205.0


# --------------------------------------------------------------------------------------------- invariants
def _independent_utility(res: Result, w: Workload) -> float:
    total = 0.0
    for t, start in res.edge_starts:
        p = w[t.model]
        total += (p.benefit if t.end_ms is not None and t.end_ms <= t.deadline_ms else 0.0) - p.edge_cost
    for t, start in res.cloud_sends:
        p = w[t.model]
        total += (p.benefit if t.end_ms is not None and t.end_ms <= t.deadline_ms else 0.0) - p.cloud_cost
    return total


@needs_workload
@pytest.mark.parametrize("load", ["LIGHT", "MEDIUM", "HEAVY"])
@pytest.mark.parametrize("name", ALL)
def test_invariants_on_random_traces(name, load):
    w = Workload.from_file(WORKLOAD_JSON, load)
    rng = random.Random(f"{name}/{load}")
    for seed, extra, down in ((11, 0.0, []), (12, lambda t, now: rng.uniform(0, 200), [(8_000.0, 12_000.0)])):
        trace = make_trace(w, drones=2, duration_s=20, seed=seed)
        res = Harness(make_analytics_scheduler(name, w), cloud_extra_ms=extra, cloud_down=down).run(trace)
        assert not res.double_terminal and not res.bad_dispatch
        assert all(t.state is not TaskState.PENDING for t in res.tasks)          # exactly one terminal state each
        assert res.utility == pytest.approx(sum(task_utility(t, w[t.model]) for t in res.tasks))
        assert res.utility == pytest.approx(_independent_utility(res, w))
        assert all(not (t0 <= s < t1) for _, s in res.cloud_sends for t0, t1 in down)  # no cloud while down
        if extra == 0.0:  # exact timing: no policy starts an edge task that will miss its deadline
            assert all(s + w[t.model].edge_ms <= t.deadline_ms for t, s in res.edge_starts)
            assert res.states[TaskState.DONE_LATE] == 0


@needs_workload
@pytest.mark.parametrize("name", ALL)
def test_decisions_before_t_do_not_depend_on_arrivals_after_t(name):
    """Non-anticipation: two traces equal up to T and different after it must get the same decisions before T
    (a policy may predict arrivals from what it saw, as LAPLAN does, but never read the trace ahead)."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    cut = 10_000.0
    a = make_trace(w, drones=3, duration_s=20, seed=21)
    other = [t for t in make_trace(w, drones=2, duration_s=20, seed=99) if t.arrival_ms >= cut]
    prefix = [t for t in a if t.arrival_ms < cut]
    b = prefix + [AnalyticsTask(len(prefix) + i, t.drone, t.model, t.arrival_ms, t.deadline_ms)
                  for i, t in enumerate(other)]
    assert [(t.drone, t.model, t.arrival_ms) for t in a if t.arrival_ms >= cut] != \
        [(t.drone, t.model, t.arrival_ms) for t in other]                    # the futures really differ
    logs = [run_policy(name, w, trace, cloud_extra_ms=40.0).log for trace in (a, b)]
    before = [[e for e in log if e[0] < cut] for log in logs]
    assert before[0] and before[0] == before[1]


# --------------------------------------------------------------------------------------------- orderings
@needs_workload
def test_heavy_load_utility_orderings():
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")

    def total(name, **kw):
        return sum(run_policy(name, w, make_trace(w, drones=2, duration_s=60, seed=s), **kw).utility for s in range(3))

    u = {n: total(n) for n in ("EDGE_FIFO", "EDGE_EDF", "CLOUD", "E+C", "DEMS", "DEMS-A", "GAINPLAN")}
    assert u["DEMS"] > u["E+C"] > u["CLOUD"] > u["EDGE_EDF"] > u["EDGE_FIFO"]
    assert u["DEMS-A"] == pytest.approx(u["DEMS"])     # exact timing: nothing to adapt to
    assert u["GAINPLAN"] >= 1.05 * u["DEMS-A"]

    # the paper's latency-variability setting: +200 ms on every cloud call for 20 s of each minute
    step = dict(cloud_extra_ms=lambda t, now: 200.0 if now % 60_000 >= 40_000 else 0.0)
    v = {n: total(n, **step) for n in ("DEMS", "DEMS-A", "GAINPLAN")}
    assert v["DEMS-A"] > 1.2 * v["DEMS"]
    assert v["GAINPLAN"] >= 1.10 * v["DEMS-A"]


@needs_workload
@pytest.mark.parametrize("name", ALL)
def test_cloud_recheck_is_a_pure_query(name):
    """The dispatcher bisects ``cloud_admit`` into an admit-by time (a dozen calls per cloud task): a policy must
    decide the same whether it is asked once or a dozen times. GEMS used to count every refused probe as a missed
    task, which filled its gatekeeper window with phantom misses and sent its whole edge queue to the cloud."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    trace = make_trace(w, drones=2, duration_s=30, seed=5)
    step = lambda t, now: 150.0 if 10_000 <= now < 20_000 else 0.0  # noqa: E731 — some re-checks must fail
    once = run_policy(name, w, trace, cloud_extra_ms=step, admit_probes=False)
    probed = run_policy(name, w, trace, cloud_extra_ms=step, admit_probes=True)
    assert [(t.task_id, t.state, t.tier) for t in probed.tasks] == [(t.task_id, t.state, t.tier) for t in once.tasks]
    assert probed.utility == pytest.approx(once.utility)


def test_gems_counts_each_cloud_task_once_however_often_it_is_rechecked():
    pol = make_analytics_scheduler("GEMS", TW)
    a = task("A", 0.0)                                  # deadline 400, cloud 200
    for at in (0.0, 150.0, 200.0, 201.0, 300.0, 400.0):  # the dispatcher's probes: admitted up to 200 ms
        pol.cloud_admit(a, at)
    assert pol.on_time_fraction("A") is None            # probing is not an outcome
    a.state = TaskState.DROPPED_TIME                    # refused by the executor's re-check
    pol.on_cloud_done(a, 250.0, 0.0)
    assert (pol.terminal["A"], pol.done_on_time["A"]) == (1, 0)
    b = task("A", 1000.0)
    b.state = TaskState.DONE_ON_TIME
    pol.on_cloud_done(b, 1200.0, 200.0)
    assert pol.on_time_fraction("A") == pytest.approx(0.5)


# --------------------------------------------------------------------------------------------- EVPLAN
def test_evplan_values_the_cloud_by_its_expected_utility_under_the_observed_latencies():
    pol = make_analytics_scheduler("EVPLAN", TW)
    a = task("A", 0.0)                                  # deadline 400, cloud 200: profile only, P = 1
    assert pol.submit(a, 0.0) == [] and a.notes["mode"] == "open"
    assert pol.trigger_ms(a) == 400 - 200 - 10          # exact timing: DEMS's cloud trigger
    for i in range(10):                                 # A's round trips: 200, 220, ..., 380 ms (ratios 1.0..1.9)
        cloud_done(pol, "A", 1000.0 + i, 200.0 + 20 * i)
    assert pol.on_time_chance("A", 300.0) == pytest.approx(0.6)   # 200..300: 6 of 10 fit
    # V = P * 50 - 10 > 0 needs P > 0.2: with 230 ms left P = 0.2 -> V = 0: no cloud option, an edge-only candidate
    b = task("A", 2000.0, 2230.0)
    pol.submit(b, 2000.0)
    assert b.notes["mode"] == "edge_only"
    c = task("A", 3000.0)                               # 400 ms left: P = 1 at arrival; holding costs chance at once
    pol.submit(c, 3000.0)
    # hold while it costs < 2 % of the on-time chance: until the 98th-percentile ratio (1.9, the slowest) fits
    assert pol.trigger_ms(c) == 3400 - 1.9 * 200 - 10
    assert pol.cloud_admit(c, 3000.0)


# --------------------------------------------------------------------------------------------- exact single-machine plans
def _brute_force_release_dates(jobs, free_at, groups):
    """Max gain over every subset (at most one job per group) and every order, each job left-shifted."""
    best = 0.0
    for r in range(1, len(jobs) + 1):
        for sub in itertools.combinations(range(len(jobs)), r):
            if len({groups[j] for j in sub}) < r or any(jobs[j][3] <= 0 for j in sub):
                continue
            for perm in itertools.permutations(sub):
                f, ok = free_at, True
                for j in perm:
                    rel, dl, p, _ = jobs[j]
                    f = max(f, rel) + p
                    ok = ok and f <= dl + 1e-9
                if ok:
                    best = max(best, sum(jobs[j][3] for j in sub))
                    break
    return best


def test_max_gain_schedule_with_release_dates_equals_brute_force_and_is_feasible():
    rng = random.Random(3)
    for _ in range(300):
        jobs, groups = [], []
        for g in range(rng.randint(0, 5)):            # a job and 1-2 variants (same release and length)
            rel = rng.choice([0.0, 10.0, 20.0, 35.0, rng.uniform(0, 60)])
            p = rng.choice([10.0, 15.0, 30.0, rng.uniform(5, 40)])
            for _ in range(rng.choice([1, 1, 2])):
                jobs.append((rel, rel + p + rng.choice([-3.0, 0.0, 10.0, rng.uniform(0, 50)]), p,
                             rng.choice([-1.0, 1.0, 3.0, rng.uniform(0.5, 5)])))
                groups.append(g)
        free_at = rng.choice([float("-inf"), 0.0, 15.0, rng.uniform(0, 40)])
        gain, sched = max_gain_schedule(jobs, free_at=free_at, groups=groups)
        f, total = free_at, 0.0
        for j, start in sched:                        # in start order, none before its release or the previous end
            rel, dl, p, w = jobs[j]
            assert start >= max(f, rel) - 1e-9 and start + p <= dl + 1e-9
            f, total = start + p, total + w
        assert len({groups[j] for j, _ in sched}) == len(sched)
        assert total == pytest.approx(gain)
        assert gain == pytest.approx(_brute_force_release_dates(jobs, free_at, groups))


def test_max_gain_schedule_waits_for_a_later_release_when_it_pays():
    # Y (gain 1) is available now and would block X (gain 10, released at 50, latest start 60) if started at 0
    gain, sched = max_gain_schedule([(0.0, 1000.0, 100.0, 1.0), (50.0, 160.0, 100.0, 10.0)])
    assert gain == 11.0 and sched == [(1, 50.0), (0, 150.0)]
    with pytest.raises(ValueError, match="share"):
        max_gain_schedule([(0.0, 100.0, 10.0, 1.0), (5.0, 100.0, 10.0, 1.0)], groups=[0, 0])


# --------------------------------------------------------------------------------------------- LAPLAN
#   model  edge  cloud  benefit e_cost c_cost deadline: X long, valuable and tight (latest start + 20 ms after it
#   arrives); Y a short filler with a loose deadline. Neither has a cloud option in time.
LW = Workload.from_dict({"models": {
    "X": {"edge_ms": 300, "cloud_ms": 5000, "benefit": 200, "edge_cost": 0, "cloud_cost": 0},
    "Y": {"edge_ms": 150, "cloud_ms": 5000, "benefit": 30, "edge_cost": 0, "cloud_cost": 0}},
    "loads": {"T": {"X": 320, "Y": 1000}}}, "T")


def _frame(pol, drone, t, models):
    out = []
    for m in models:
        tk = AnalyticsTask(next(TASK_IDS), drone, m, t, t + LW[m].deadline_ms)
        assert pol.submit(tk, t) == []
        out.append(tk)
    return out


def _run_edge(pol, t, now, exec_ms):
    got, drops = pol.next_edge_task(now)
    assert got is t and drops == []
    pol.on_edge_done(t, now + exec_ms, exec_ms)


def test_arrival_predictor_learns_each_drones_period_and_stops_waiting_for_a_missing_frame():
    ap = ArrivalPredictor()
    for t in (0.0, 1000.0):
        for m in ("X", "Y"):
            ap.observe(AnalyticsTask(next(TASK_IDS), "d0", m, t, t + 500))
    assert ap.predict(1500.0, 1000.0) == [(2000.0, "d0", m, 2000.0, 2000.0, 1.0) for m in ("X", "Y")] + \
        [(3000.0, "d0", m, 3000.0, 3000.0, 1.0) for m in ("X", "Y")]    # the last field: the gain's weight
    # overdue within a tenth of the period: expected now, re-plan at the end of the grace
    assert ap.predict(2050.0, 0.0) == [(2050.0, "d0", m, 2100.0, 2000.0, 1.0) for m in ("X", "Y")]
    assert ap.predict(2100.0, 5000.0) == []            # missing: not waited for
    # the first task of a frame has come: the rest of it is expected now
    ap.observe(AnalyticsTask(next(TASK_IDS), "d0", "Y", 2100.0, 3100.0))
    assert ap.predict(2100.0, 0.0)[0] == (2100.0, "d0", "X", 2120.0, 2100.0, 1.0)


def test_laplan_keeps_the_edge_free_for_a_predicted_high_gain_task():
    # drone d0 sends X every 1000 ms. At 1950 a filler Y arrives from d1 with the edge idle: EVPLAN starts it (it
    # ends at 2100, and X of 2000 can no longer start by 2020: lost); LAPLAN waits for X, runs it 2000-2300, then Y.
    for name, first in (("EVPLAN", "Y"), ("LAPLAN", "X")):
        pol = make_analytics_scheduler(name, LW)
        for t0 in (0.0, 1000.0):
            x, = _frame(pol, "d0", t0, ["X"])
            _run_edge(pol, x, t0, 300.0)
        y, = _frame(pol, "d1", 1950.0, ["Y"])
        got, _ = pol.next_edge_task(1950.0)
        if first == "Y":
            assert got is y
            continue
        assert got is None and pol.next_poll_ms() == 2000.0
        assert pol.poll(2000.0) == []
        x, = _frame(pol, "d0", 2000.0, ["X"])
        _run_edge(pol, x, 2000.0, 300.0)
        _run_edge(pol, y, 2300.0, 150.0)
        assert pol.held_tasks() == [] and pol.counters["edge_waits_for_prediction"] == 1


def test_laplan_expects_the_rest_of_a_frame_while_its_tasks_are_submitted_one_by_one():
    pol = make_analytics_scheduler("LAPLAN", LW)
    for t0 in (0.0, 1000.0):
        x, y = _frame(pol, "d0", t0, ["X", "Y"])
        _run_edge(pol, x, t0, 300.0)
        _run_edge(pol, y, t0 + 300.0, 150.0)
    y, = _frame(pol, "d0", 2000.0, ["Y"])             # Y of the frame first: X of the same frame is on its way
    assert pol.next_edge_task(2000.0)[0] is None
    x, = _frame(pol, "d0", 2000.0, ["X"])
    assert pol.next_edge_task(2000.0)[0] is x


def test_laplan_does_not_replan_for_the_runtimes_wall_clock_spread_of_one_event():
    # The Ray runtime's calls for one event reach the policy a fraction of a ms apart (the edge loop's poll timer
    # fires 0.7 ms late, the predicted X is submitted at 2000.9 with its arrival time 2000): within
    # replan_tolerance_ms the plan made at 1950 (wait for X, start it at 2000) still holds, so it is not recomputed;
    # with no tolerance each call finds the plan's first start just passed and plans again. The decision is the same.
    plans = {}
    for tol in (0.0, 2.0):
        pol = make_analytics_scheduler("LAPLAN", LW, replan_tolerance_ms=tol)
        for t0 in (0.0, 1000.0):
            x, = _frame(pol, "d0", t0, ["X"])
            _run_edge(pol, x, t0, 300.0)
        y, = _frame(pol, "d1", 1950.0, ["Y"])
        assert pol.next_edge_task(1950.0)[0] is None and pol.next_poll_ms() == 2000.0
        before = pol.counters["plans"]
        assert pol.poll(2000.7) == [] and pol.next_edge_task(2000.7)[0] is None
        x = AnalyticsTask(next(TASK_IDS), "d0", "X", 2000.0, 2000.0 + LW["X"].deadline_ms)
        assert pol.submit(x, 2000.9) == []
        assert pol.next_edge_task(2001.0)[0] is x
        plans[tol] = (pol.counters["plans"] - before, pol.counters["plans_start_passed"])
    assert plans[2.0] == (0, 0)
    assert plans[0.0][0] >= 1 and plans[0.0][1] >= 1


#: X as in LW; Z short, with a fast cloud (its trigger falls after the edge's planned start of it)
SW_SPEC = {"models": {
    "X": {"edge_ms": 300, "cloud_ms": 5000, "benefit": 200, "edge_cost": 0, "cloud_cost": 0},
    "Z": {"edge_ms": 100, "cloud_ms": 40, "benefit": 100, "edge_cost": 0, "cloud_cost": 10}},
    "loads": {"late_start": {"X": 320, "Z": 406}, "overrun": {"X": 320, "Z": 351}}}
SW = Workload.from_dict(SW_SPEC, "late_start")


def _one(pol, drone, model, arrival, now, w=SW):
    tk = AnalyticsTask(next(TASK_IDS), drone, model, arrival, arrival + w[model].deadline_ms)
    return tk, pol.submit(tk, now)


def test_laplan_keeps_its_plan_while_the_running_task_overruns_by_less_than_the_tolerance_and_the_slack():
    # X runs from 0, due to end at 300; Y (deadline 1050, 150 ms) is planned after it with 600 ms of slack. Calls at
    # 300.5 and 301 (X overrunning) keep the plan with 2 ms of tolerance and recompute it with none.
    counts = {}
    for tol in (0.0, 2.0):
        pol = make_analytics_scheduler("LAPLAN", LW, replan_tolerance_ms=tol)
        x, = _frame(pol, "d0", 0.0, ["X"])
        assert pol.next_edge_task(0.0)[0] is x
        y, = _frame(pol, "d1", 50.0, ["Y"])
        assert [k for k, _ in pol.schedule(250.0)] == [pol._key(y)]
        before = pol.counters["plans"]
        assert pol.poll(300.5) == [] and [k for k, _ in pol.schedule(301.0)] == [pol._key(y)]
        counts[tol] = (pol.counters["plans"] - before, pol.counters["plans_edge_overran"])
    assert counts[2.0] == (0, 0)
    assert counts[0.0][0] >= 1 and counts[0.0][1] >= 1


@pytest.mark.parametrize("tol", [0.0, 2.0, 50.0])
def test_laplan_recomputes_a_plan_started_later_than_its_slack_allows(tol):
    # Planned at 1995: X (predicted at 2000) 2000-2300, then Z 2300-2400 against Z's deadline 2401: 1 ms of slack.
    # X is submitted 1.5 ms late (the runtime's replay): the plan no longer holds for Z, whatever the tolerance,
    # so it is recomputed (X alone), and Z goes to the cloud at its trigger instead of being committed to the edge
    # and expiring there (which a plan kept for the full tolerance did).
    pol = make_analytics_scheduler("LAPLAN", SW, replan_tolerance_ms=tol)
    for t0 in (0.0, 1000.0):
        x, _ = _one(pol, "d0", "X", t0, t0)
        _run_edge(pol, x, t0, 300.0)
    z, out = _one(pol, "d1", "Z", 1995.0, 1995.0)
    assert out == [] and z.notes["mode"] == "open"
    assert pol.next_edge_task(1995.0)[0] is None and [k for k, _ in pol.schedule(1995.0)][:2] == [
        ("d0", "X", 2000.0), pol._key(z)]  # then d0's next frames
    plans = pol.counters["plans"]
    x, _ = _one(pol, "d0", "X", 2000.0, 2001.5)
    assert pol.next_edge_task(2001.5)[0] is x
    assert pol.counters["plans"] == plans + 1  # recomputed: 1.5 ms late is more than Z's 1 ms of slack
    due = pol.next_poll_ms()
    assert 2001.5 < due <= 2301.0
    decisions = pol.poll(due)
    assert [(d.kind, d.task) for d in decisions] == [("cloud", z)]
    assert pol.on_edge_done(x, 2301.5, 300.0) == [] and pol.held_tasks() == []


@pytest.mark.parametrize("tol", [0.0, 2.0])
def test_laplan_recomputes_a_plan_when_the_running_task_overruns_more_than_its_slack(tol):
    # X runs 0-300 (planned); Z, arriving at 50 with deadline 401, is planned 300-400 (1 ms of slack). Its trigger
    # poll comes at 301.5 while X overruns: the edge frees later than the plan's slack allows, so Z is not committed
    # to the edge on the old plan; it goes to the cloud.
    w = Workload.from_dict(SW_SPEC, "overrun")
    pol = make_analytics_scheduler("LAPLAN", w, replan_tolerance_ms=tol)
    x, _ = _one(pol, "d0", "X", 0.0, 0.0, w)
    assert pol.next_edge_task(0.0)[0] is x
    z, out = _one(pol, "d1", "Z", 50.0, 50.0, w)
    assert out == [] and [k for k, _ in pol.schedule(50.0)] == [pol._key(z)]
    assert pol.next_poll_ms() == pytest.approx(301.0)
    assert [(d.kind, d.task) for d in pol.poll(301.5)] == [("cloud", z)]


def test_laplan_refuses_bad_options():
    with pytest.raises(ValueError, match="horizon_ms"):
        make_analytics_scheduler("LAPLAN", LW, horizon_ms=-1)
    with pytest.raises(ValueError, match="edge_levels"):
        make_analytics_scheduler("LAPLAN", LW, edge_levels=(0.5, 1.5))
    with pytest.raises(ValueError, match="release_early_ms"):
        make_analytics_scheduler("LAPLAN", LW, release_early_ms=-5)
    with pytest.raises(ValueError, match="commit_horizon_ms"):
        make_analytics_scheduler("LAPLAN", LW, commit_horizon_ms=100.0)
    for bad in (-1.0, 101.0, float("nan")):
        with pytest.raises(ValueError, match="replan_tolerance_ms"):
            make_analytics_scheduler("LAPLAN", LW, replan_tolerance_ms=bad)
