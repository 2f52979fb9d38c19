"""LAPLAN's incremental plan preparation decides exactly as the from-scratch one.

The preparation around the compiled DP keeps, per model, the deadline- and fallback-free parts of each task's
edge-time variants until the edge statistics change (``_variants``), and indexes the current plan once instead of
scanning it per task (``_planned_start``). A subclass with the from-scratch code (the code before the change) must
produce the same decision log, edge starts, cloud sends, utility and counters on seeded random HEAVY workloads:
random seed, drones per edge, trace kind (periodic / realistic with random jitter and drop rate) and edge/cloud
jitter, each run through the deterministic harness.
"""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aerodaas.bench.harness import Harness, fleet_tasks
from aerodaas.bench.workload import make_trace
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers.analytics_base import Workload
from aerodaas.schedulers.analytics_laplan import LaPlan
from aerodaas.schedulers.dispatch.emulation import Jitter

from tests.conftest import DATA_DIR, needs_workload

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"
pytestmark = needs_workload


class FromScratchLaPlan(LaPlan):
    """LAPLAN with each variant computed from the profile and each planned start found by scanning the plan."""

    def _variants(self, model, deadline_ms, fallback):
        p = self.w[model]
        proc = p.edge_ms * self._edge_mean
        return [(deadline_ms - p.edge_ms * tail, proc, chance * p.benefit - p.edge_cost - fallback)
                for tail, chance in self._tails]

    def _planned_start(self, task, now_ms):
        k = self._key(task)
        for q, s in self.schedule(now_ms):
            if q == k:
                return s
        return None


def _run(cls, w, tasks, seed, edge_sigma, cloud_sigma):
    pol = cls(w)
    h = Harness(pol, edge_jitter=Jitter("lognormal", edge_sigma), cloud_jitter=Jitter("lognormal", cloud_sigma),
                seed=seed, edge_id="edge00")
    res = h.run([t.__class__(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in tasks])
    counters = dict(pol.counters)
    return (res.log, [(t.task_id, s) for t, s in res.edge_starts], [(t.task_id, s) for t, s in res.cloud_sends],
            res.utility, counters)


@settings(max_examples=6, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(seed=st.integers(0, 10_000), dpe=st.integers(2, 4), realistic=st.booleans(),
       jitter=st.floats(0.0, 0.3), drop=st.floats(0.0, 0.2), edge_sigma=st.sampled_from([0.0, 0.05, 0.2]),
       cloud_sigma=st.sampled_from([0.0, 0.1, 0.2]))
def test_incremental_preparation_gives_the_same_decisions(seed, dpe, realistic, jitter, drop, edge_sigma,
                                                          cloud_sigma):
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    spec = TraceSpec.parse("realistic", jitter=jitter, drop=drop) if realistic else TraceSpec.parse("periodic")
    rows = make_trace(w, dpe, 12.0, seed, dpe, 1.0, spec)
    tasks = fleet_tasks(rows, w)["edge00"]
    fast = _run(LaPlan, w, tasks, seed, edge_sigma, cloud_sigma)
    ref = _run(FromScratchLaPlan, w, tasks, seed, edge_sigma, cloud_sigma)
    assert fast[4]["plans"] > 10 and len(fast[1]) > 5   # the runs plan and start edge tasks
    assert fast[1] == ref[1], "other edge starts"
    assert fast[2] == ref[2], "other cloud sends"
    assert fast[0] == ref[0], "another decision log"
    assert fast[3:] == ref[3:]


def test_the_arrival_predictor_takes_a_bursts_gap_with_a_gap_window():
    """On/off video (frames 500 ms apart for 3 s, then 3 s of silence): with the last gap as the period a
    drone's first frame after a silence predicts the next one 3.5 s on; the median of the last 5 gaps keeps 500 ms.
    After a stall's flush (frames 2 ms apart) the median keeps the 1 s period too."""
    from aerodaas.schedulers.analytics_base import AnalyticsTask
    from aerodaas.schedulers.analytics_laplan import ArrivalPredictor

    def feed(pred, times):
        for n, t in enumerate(times):
            pred.observe(AnalyticsTask(n, "d0", "DEO", t, t + 950.0))
        return pred.drones["d0"][1]

    onoff = [0, 500, 1000, 1500, 2000, 2500, 6000]
    assert feed(ArrivalPredictor(), onoff) == 3500
    assert feed(ArrivalPredictor(gap_window=5), onoff) == 500
    flush = [0, 1000, 2000, 3000, 5500, 5502, 5504, 6000]
    assert feed(ArrivalPredictor(gap_window=5), flush) == 1000
    with pytest.raises(ValueError, match="gap_window"):
        ArrivalPredictor(gap_window=0)
