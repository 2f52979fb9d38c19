"""LAPLAN's faster planner decides exactly as the old one did.

The max-gain DP behind LAPLAN's plan now runs compiled (numba, :mod:`aerodaas.schedulers.single_machine_jit`) or as a
rewritten pure-Python loop (``jit=False``, and above 64 task groups). Both must return the schedule the old DP
(``tests/schedulers/reference_max_gain_schedule.py``, the code before the change) returned, ties included — LAPLAN's jobs tie
often (tasks of one model have equal gains), and the plan's first task is what the edge runs. Checked on the
decisions themselves: LAPLAN driven by the harness over seeded periodic and realistic HEAVY traces with each solver
must produce the same decision log, the same edge starts and cloud sends, and the same utility.
"""
from __future__ import annotations

import random

import pytest

from aerodaas.bench.harness import Harness, fleet_tasks
from aerodaas.bench.workload import make_trace
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers import analytics_laplan, single_machine_jit
from aerodaas.schedulers.analytics_base import TaskState, Workload, make_analytics_scheduler
from aerodaas.schedulers.dispatch.emulation import Jitter
from aerodaas.schedulers.single_machine import SolveCounts, max_gain_schedule, max_gain_schedule_arrays

from tests.conftest import DATA_DIR, needs_workload
from tests.schedulers.reference_max_gain_schedule import max_gain_schedule as old_max_gain_schedule

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"


def _python(jobs, *, free_at=float("-inf"), groups=None, counts=None):
    return max_gain_schedule(jobs, free_at=free_at, groups=groups, jit=False, counts=counts)


def _arrays(jobs, *, free_at=float("-inf"), groups=None, counts=None):
    """The flat-array entry point LAPLAN uses, its groups numbered in order of first appearance."""
    import numpy as np

    ids: dict = {}
    gid = [ids.setdefault(g if groups is not None else j, len(ids)) for j, g in enumerate(groups or [None] * len(jobs))]
    cols = list(zip(*jobs)) if jobs else [(), (), (), ()]
    return max_gain_schedule_arrays(*(np.array(c, np.float64) for c in cols), np.array(gid, np.int64), len(ids),
                                    free_at=free_at, counts=counts)


SOLVERS = {"compiled": max_gain_schedule, "python": _python, "arrays": _arrays}


def test_the_compiled_kernel_is_available():
    # numba is a dependency (pyproject.toml): without it LAPLAN silently falls back to the slow loop
    assert single_machine_jit.available(), single_machine_jit.import_error()


def _random_instance(rng: random.Random, n_groups: int, span_ms: float = 3000.0):
    jobs, groups = [], []
    for g in range(n_groups):
        rel = rng.choice([0.0, 100.0, 250.0, float(rng.randrange(0, int(span_ms), 50)), rng.uniform(0, span_ms)])
        p = rng.choice([150.0, 244.0, 563.0, 739.0, rng.uniform(50, 800)])
        for _ in range(rng.choice([1, 1, 3, 6])):       # variants: same release and length
            jobs.append((rel, rel + p + rng.choice([0.0, 100.0, 400.0, rng.uniform(-50, 1200)]), p,
                         rng.choice([25.0, 38.0, 148.0, 204.0, -1.0, rng.uniform(1, 200)])))  # many exact ties
            groups.append(("g", g))
    free_at = rng.choice([float("-inf"), 0.0, rng.uniform(0, 500)])
    return jobs, free_at, groups


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_the_solver_returns_the_old_schedule_on_random_instances_with_ties(solver):
    rng = random.Random(29)
    f = SOLVERS[solver]
    sizes = [rng.randint(0, 12) for _ in range(250)] + [rng.randint(40, 64) for _ in range(12)] + [70, 80]
    nonempty = 0
    counts = SolveCounts()
    for n in sizes:                                   # 70 and 80 groups over 3 s: > 64 live, the Python loop runs
        jobs, free_at, groups = _random_instance(rng, n)
        want = old_max_gain_schedule(jobs, free_at=free_at, groups=groups)
        assert f(jobs, free_at=free_at, groups=groups, counts=counts) == want, (n, jobs, free_at)
        nonempty += bool(want[1])
    assert nonempty > 200                             # the instances are not trivially empty
    for _ in range(3):                                # 300 groups over 40 s: the compiled kernel reuses bits
        jobs, free_at, groups = _random_instance(rng, 300, span_ms=40_000.0)
        assert f(jobs, free_at=free_at, groups=groups, counts=counts) == old_max_gain_schedule(jobs, free_at=free_at,
                                                                                              groups=groups)
    if solver in ("compiled", "arrays"):
        assert counts.python >= 1 and counts.compiled > 200, counts
    else:
        assert counts.compiled == 0 and counts.python > 200, counts  # jit=False: every non-empty plan in Python


def _run_laplan(w: Workload, tasks, seed: int):
    pol = make_analytics_scheduler("LAPLAN", w)
    h = Harness(pol, edge_jitter=Jitter("lognormal", 0.05), cloud_jitter=Jitter("lognormal", 0.1), seed=seed,
                edge_id="edge00")
    res = h.run([t.__class__(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in tasks])
    counters = dict(pol.counters)
    in_python = counters.pop("plans_in_python", 0)  # which DP ran, not a decision
    return (res.log, [(t.task_id, s) for t, s in res.edge_starts], [(t.task_id, s) for t, s in res.cloud_sends],
            res.utility, counters, in_python)


@needs_workload
@pytest.mark.parametrize("trace", ["periodic", "realistic"])
def test_laplan_decides_exactly_as_with_the_old_planner(trace, monkeypatch):
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    calls = []
    for seed in (0, 1):
        rows = make_trace(w, 3, 30.0, seed, 3, 1.0, TraceSpec.parse(trace))
        tasks = fleet_tasks(rows, w)["edge00"]
        runs = {}
        for name, f in [("old", old_max_gain_schedule), *SOLVERS.items()]:
            def counted(release, deadline, proc, gain, group, ngroups, *, free_at, _f=f, _n=name, **kw):
                calls.append(_n)
                if _n == "arrays":  # what LAPLAN calls
                    return max_gain_schedule_arrays(release, deadline, proc, gain, group, ngroups, free_at=free_at,
                                                    **kw)
                jobs = list(zip(release.tolist(), deadline.tolist(), proc.tolist(), gain.tolist()))
                return _f(jobs, free_at=free_at, groups=group.tolist())
            monkeypatch.setattr(analytics_laplan, "max_gain_schedule_arrays", counted)
            runs[name] = _run_laplan(w, tasks, seed)
        log, starts, sends, utility, counters, _ = runs["old"]
        assert runs["compiled"][5] == 0 and counters["plans"] > 50   # every plan of this run ran compiled
        assert len(starts) > 20 and len(sends) > 20 and utility > 0
        for name in SOLVERS:
            assert runs[name][1] == starts, f"{trace} seed {seed}: {name} solver: other edge starts"
            assert runs[name][2] == sends, f"{trace} seed {seed}: {name} solver: other cloud sends"
            assert runs[name][0] == log, f"{trace} seed {seed}: {name} solver: another decision log"
            assert runs[name][3:5] == (utility, counters)
    assert calls.count("compiled") == calls.count("arrays") == calls.count("old") > 100   # every plan went through the solver under test


@needs_workload
def test_a_flushed_burst_is_planned_compiled_on_a_reduced_instance_not_in_python():
    """On a stall-and-flush trace more than 64 task groups were live in one plan and LAPLAN's DP fell
    back to pure Python (7 times in a run, one decision of 67 ms). Now the plan's instance is reduced until the
    compiled kernel takes it (the latest predicted tasks first), counted, and no plan runs in Python."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    spec = TraceSpec.parse("flush", stall_s=4.0, stall_every_s=4.0)
    tasks = fleet_tasks(make_trace(w, 6, 40.0, 300, 6, 1.0, spec), w)["edge00"]
    pol = make_analytics_scheduler("LAPLAN", w)
    res = Harness(pol, edge_jitter=Jitter("lognormal", 0.05), cloud_jitter=Jitter("lognormal", 0.1), seed=300,
                  edge_id="edge00").run(tasks)
    assert pol.counters["plans_reduced"] >= 1 and pol.counters["plans_in_python"] == 0
    assert pol.counters["plans"] > 50 and res.utility > 0
    assert all(t.state is not TaskState.PENDING for t in res.tasks) and not res.double_terminal and not res.bad_dispatch
