"""The hand-derivable workload of the policy tests (times in ms) and small helpers that build its tasks."""
from __future__ import annotations

import itertools

from aerodaas.schedulers.analytics_base import (
    AnalyticsTask,
    TaskState,
    Workload,
    make_analytics_scheduler,
)

from tests.conftest import DATA_DIR

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"

ALL = ["EDGE_FIFO", "EDGE_EDF", "EDGE_SJF", "EDGE_HBF", "EDGE_HUF", "CLOUD", "E+C", "DEM", "DEMS", "DEMS-A", "GEMS",
       "GAINPLAN", "EVPLAN", "LAPLAN"]
EDGE_ONLY = ["EDGE_FIFO", "EDGE_EDF", "EDGE_SJF", "EDGE_HBF", "EDGE_HUF"]

# A small workload where every number below is derivable by hand (times in ms).
#   model  edge cloud benefit e_cost c_cost deadline | edge util cloud util | EDF prio
#   A       100  200    50     1     10     400      |    49        40      |  400
#   B       300  350   200     5    150     600      |   195        50      |  600
#   C       150  250    60    40     70     500      |    20       -10      |  500   (cloud never worth it)
#   D       100  150   300     1    200     450      |   299       100      |  450
#   E       250  150   400     1    300     420      |   399       100      |  420
# Eviction score (cloud feasible): A 9, B 145, D 199, E 299; C (cloud utility < 0): |60 - 40| = 20.
# Steal rank (c_cost - e_cost) * 1000 / edge (+1000 if cloud utility < 0): A 90, B 483, C 1200, D 1990.
TW = Workload.from_dict({
    "models": {
        "A": {"edge_ms": 100, "cloud_ms": 200, "benefit": 50, "edge_cost": 1, "cloud_cost": 10},
        "B": {"edge_ms": 300, "cloud_ms": 350, "benefit": 200, "edge_cost": 5, "cloud_cost": 150},
        "C": {"edge_ms": 150, "cloud_ms": 250, "benefit": 60, "edge_cost": 40, "cloud_cost": 70},
        "D": {"edge_ms": 100, "cloud_ms": 150, "benefit": 300, "edge_cost": 1, "cloud_cost": 200},
        "E": {"edge_ms": 250, "cloud_ms": 150, "benefit": 400, "edge_cost": 1, "cloud_cost": 300},
    },
    "loads": {"T": {"A": 400, "B": 600, "C": 500, "D": 450, "E": 420}},
}, "T")

TASK_IDS = itertools.count(1000)  # task ids unique across every test of the process


def task(model: str, arrival: float, deadline: float | None = None, w: Workload = TW) -> AnalyticsTask:
    """A task of ``model`` arriving at ``arrival`` (absolute deadline defaults to arrival + the model's)."""
    return AnalyticsTask(next(TASK_IDS), "d0", model, arrival, arrival + w[model].deadline_ms if deadline is None else deadline)


def busy(pol, now: float = 0.0, model: str = "B") -> AnalyticsTask:
    """Make the edge busy with one ``model`` task started at ``now`` (submitted to an empty queue, then popped)."""
    t = task(model, now)
    assert pol.submit(t, now) == []
    got, decisions = pol.next_edge_task(now)
    assert got is t and decisions == []
    return t


def kinds(decisions):
    return [(d.kind, d.task, d.state) for d in decisions]


def c1_then_a1(name: str, **options):
    """Edge running B until 300; C1 (deadline 500) queued at 0 (0 + 300 + 150 = 450 <= 500); then A1 (deadline
    410) submitted at 10 at the EDF head slot (400 < 500): 10 + 290 + 100 = 400 <= 410 fits, but it would push C1 to
    550 > 500. Returns (policy, C1, A1, the decisions of A1's submit). Evicting policies scan every task behind
    the insertion point (``eviction_scan="full"``) unless ``options`` say otherwise."""
    if name != "E+C":
        options.setdefault("eviction_scan", "full")
    pol = make_analytics_scheduler(name, TW, **options)
    busy(pol, 0.0, "B")
    c1 = task("C", 0.0)
    assert pol.submit(c1, 0.0) == []
    a1 = task("A", 10.0)
    return pol, c1, a1, pol.submit(a1, 10.0)


def cloud_done(pol, model: str, now: float, latency: float, state: TaskState = TaskState.DONE_ON_TIME):
    """Report a cloud completion of ``model`` at ``now`` (ms) after ``latency`` ms to the policy ``pol``."""
    t = task(model, now - latency, now + 1_000)
    t.tier, t.start_ms, t.state = "cloud", now - latency, state
    return pol.on_cloud_done(t, now, latency)
