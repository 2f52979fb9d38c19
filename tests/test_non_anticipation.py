"""Non-anticipation of every analytics-scheduler policy, with a test that two deliberately cheating policies cannot
pass.

A policy is non-anticipative when its decisions before any time T depend only on what was revealed before T: the
arrivals before T, and the edge and cloud execution times of the tasks that *completed* before T. The test runs each
policy twice per cut T on runs that agree on everything revealed before T and differ in everything revealed at or
after it: the arrivals at or after T (another seeded trace), and every edge or cloud draw that completes at or after
T (re-drawn from another seed, kept at or after T so it is still unrevealed before T). The decision logs and edge
starts before T must be identical.

Cuts: uniform ones, plus cuts just before arrivals (1 ms and 1 µs before), so that a policy reading arrivals even a
few hundred ms ahead is caught; cloud and edge times are jittered (lognormal σ 0.2 / 0.05), so a policy reading a
draw before the task completes is caught. The two cheats below (fixtures, never production code) must be caught:
``PeekArrivals`` (DEM that sends a task straight to the cloud when another frame arrives within 300 ms) and
``PeekDraws`` (DEM whose cloud re-check reads the true, not yet revealed, cloud round trip).
"""
from __future__ import annotations

import random

import pytest

from aerodaas.bench.harness import Harness, make_trace
from aerodaas.schedulers.analytics_base import (AnalyticsTask, Decision, Workload, make_analytics_scheduler)
from aerodaas.schedulers.analytics_dems import Dem
from aerodaas.schedulers.dispatch.emulation import Jitter, seeded_rng

from .conftest import DATA_DIR

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"
needs_workload = pytest.mark.skipif(not WORKLOAD_JSON.is_file(), reason=f"no workload at {WORKLOAD_JSON}")

REAL = ["EDGE_FIFO", "EDGE_EDF", "EDGE_SJF", "EDGE_HBF", "EDGE_HUF", "CLOUD", "E+C", "DEM", "DEMS", "DEMS-A", "GEMS",
        "GAINPLAN", "EVPLAN", "LAPLAN"]
SEED = 7
DURATION_S = 12.0


# ------------------------------------------------------------------------------------------------ the cheats
class PeekArrivals(Dem):
    """CHEAT (test fixture): DEM that reads the trace ahead — a task whose frame is followed by another drone's
    frame within ``lookahead_ms`` goes straight to the cloud, as if it knew the edge would be contended."""

    name = "CHEAT_PEEK_ARRIVALS"
    lookahead_ms = 300.0

    def peek(self, trace, harness) -> None:
        self._arrivals = sorted((t.arrival_ms, t.drone) for t in trace)

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        if any(now_ms < a <= now_ms + self.lookahead_ms and d != task.drone for a, d in self._arrivals):
            return [self._cloud_or_drop(task, now_ms, "peeked: contention ahead")]
        return super().submit(task, now_ms)


class PeekDraws(Dem):
    """CHEAT (test fixture): DEM whose cloud re-check reads the task's true cloud round trip (the harness's draw)
    instead of the profile — the draw a real dispatcher only learns when the reply comes back."""

    name = "CHEAT_PEEK_DRAWS"

    def peek(self, trace, harness) -> None:
        self._draw = harness.cloud_round_trip_ms

    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        return now_ms + self._draw(task, now_ms) <= task.deadline_ms


# ------------------------------------------------------------------------------------------------ the cut runs
class CutHarness(Harness):
    """The policy harness with every edge and cloud draw that completes at or after ``cut`` re-drawn from
    ``alt_seed`` (and held at or after ``cut``, so it stays unrevealed before it). ``cut`` None: the plain draws."""

    def __init__(self, policy, *, cut: float | None, alt_seed: int, **kw) -> None:
        super().__init__(policy, **kw)
        self.cut, self.alt_seed = cut, alt_seed

    def _alt(self, base: float, start: float, profile_ms: float, jitter: Jitter, kind: str, task) -> float:
        if self.cut is None or start + base < self.cut:
            return base
        alt = profile_ms * jitter.factor(seeded_rng(self.alt_seed, kind, self.edge_id, task.task_id))
        return max(alt, self.cut - start)

    def edge_hold_ms(self, task):
        return self._alt(super().edge_hold_ms(task), self.now, self.w[task.model].edge_ms, self.edge_jitter, "edge",
                         task)

    def cloud_round_trip_ms(self, task, send_ms):
        return self._alt(super().cloud_round_trip_ms(task, send_ms), send_ms, self.w[task.model].cloud_ms,
                         self.cloud_jitter, "cloud", task)


def _copy(tasks):
    return [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in tasks]


def _run(make, w, trace, cut, alt_seed: int = SEED + 1000):
    pol = make(w)
    h = CutHarness(pol, cut=cut, alt_seed=alt_seed, edge_jitter=Jitter("lognormal", 0.05),
                   cloud_jitter=Jitter("lognormal", 0.2), seed=SEED)
    trace = _copy(trace)
    if hasattr(pol, "peek"):
        pol.peek(trace, h)
    res = h.run(trace)
    return res


def _before(res, cut):
    return ([e for e in res.log if e[0] < cut], [(t.task_id, s) for t, s in res.edge_starts if s < cut])


def cuts(trace, n_uniform: int = 6, n_arrivals: int = 8, seed: int = 3) -> list[float]:
    """Cut points: ``n_uniform`` uniform in the trace's span, and 1 ms and 1 µs before ``n_arrivals`` arrivals
    picked at random (not the first second, where little has happened yet)."""
    rng = random.Random(seed)
    span = trace[-1].arrival_ms
    arr = sorted({t.arrival_ms for t in trace if t.arrival_ms > 1000.0})
    picks = rng.sample(arr, min(n_arrivals, len(arr)))
    return sorted([rng.uniform(1000.0, span) for _ in range(n_uniform)] + [a - 1.0 for a in picks]
                  + [a - 0.001 for a in picks])


def violations(make, w) -> list[float]:
    """The cuts at which ``make(w)``'s decisions before the cut differ between the two runs (see module doc)."""
    a = make_trace(w, drones=3, duration_s=DURATION_S, seed=21, jitter_ms=250.0)
    other = make_trace(w, drones=3, duration_s=DURATION_S, seed=99, jitter_ms=250.0)
    out = []
    for cut in cuts(a):
        prefix = [t for t in a if t.arrival_ms < cut]
        b = prefix + [AnalyticsTask(len(prefix) + i, t.drone, t.model, t.arrival_ms, t.deadline_ms)
                      for i, t in enumerate(t for t in other if t.arrival_ms >= cut)]
        assert [(t.drone, t.model, t.arrival_ms) for t in a[len(prefix):]] != \
            [(t.drone, t.model, t.arrival_ms) for t in b[len(prefix):]]      # the futures really differ
        ra, rb = _run(make, w, a, None), _run(make, w, b, cut)
        before_a, before_b = _before(ra, cut), _before(rb, cut)
        assert before_a[0], f"nothing decided before the cut {cut}"
        if before_a != before_b:
            out.append(cut)
    return out


@needs_workload
@pytest.mark.parametrize("name", REAL)
def test_policy_is_non_anticipative(name):
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    assert violations(lambda w: make_analytics_scheduler(name, w), w) == []


@needs_workload
@pytest.mark.parametrize("cheat", [PeekArrivals, PeekDraws])
def test_cheating_policies_are_caught(cheat):
    """Each cheat must be caught at several cuts (one would already fail the test of a real policy)."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    assert len(violations(cheat, w)) >= 2


@needs_workload
def test_cheats_are_caught_only_by_what_changes_after_the_cut():
    """Sanity of the method: with the same future (the same trace, the draws after the cut "re-drawn" from the same
    seed), no cheat is flagged at any cut — a cheat is caught for what it read from the future, not for noise of
    the cut machinery."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    a = make_trace(w, drones=3, duration_s=DURATION_S, seed=21, jitter_ms=250.0)
    for cheat in (PeekArrivals, PeekDraws):
        for cut in cuts(a):
            assert _before(_run(cheat, w, a, None), cut) == _before(_run(cheat, w, a, cut, alt_seed=SEED), cut)
