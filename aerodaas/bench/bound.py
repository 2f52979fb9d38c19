"""An upper bound on the utility any analytics scheduler can earn on one edge's trace (an offline oracle, LP-relaxed).

The oracle knows every arrival and every realised execution time in advance (the harness's seeded draws). Each
task earns at most ``max(0, cloud value, edge value)``:

* cloud value: ``benefit - cloud_cost`` if some send time ``s`` in ``[arrival, deadline]`` returns by the
  deadline with the task's drawn round trip at ``s`` (the network's extra latency depends on ``s``), else 0 —
  the cloud has unbounded concurrency, so cloud choices never interact;
* edge value: ``benefit - edge_cost`` if the task is run on the edge within its window; the edge runs one task at a
  time, so the chosen set must be schedulable on one machine with release times and deadlines.

Relaxations (each can only raise the optimum, so the result is an upper bound): the edge may be *preempted*, and
the edge choice ``x_j`` is fractional. Preemptive feasibility with release times and deadlines is a transportation
problem over the elementary intervals between consecutive release/deadline times (Horn, "Some simple scheduling
algorithms", Naval Research Logistics Quarterly 21(1), 1974): ``z_jk`` = time of task j run in interval k,
``sum_k z_jk = p_j x_j``, ``sum_j z_jk <= |k|``. The LP

    maximise  sum_j base_j + sum_j gain_j x_j,   gain_j = edge value - max(0, cloud value) > 0

is solved with HiGHS (``scipy.optimize.linprog``). The gap between a policy and this bound is a gap to an oracle
with preemption and fractional choices: the true (non-preemptive, online) optimum lies somewhere in between.
"""
from __future__ import annotations

from typing import Callable, Sequence

from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload

__all__ = ["utility_upper_bound"]


def utility_upper_bound(tasks: Sequence[AnalyticsTask], workload: Workload, edge_ms: Callable[[AnalyticsTask], float],
                        cloud_ms: Callable[[AnalyticsTask, float], float],
                        send_times: Callable[[AnalyticsTask], Sequence[float]] | None = None) -> dict:
    """The LP upper bound for one edge (see the module docstring).

    ``edge_ms(task)``: its realised edge execution time (ms); ``cloud_ms(task, send_ms)``: its realised round trip
    if sent at ``send_ms``; ``send_times(task)``: the send times worth trying (default: its arrival; give the times
    where the network's extra latency changes within the window too). Returns ``{"bound", "cloud_part",
    "edge_gain", "edge_tasks", "lp_status"}`` (utility units; ``edge_tasks``: candidates with a positive gain).
    Raises RuntimeError if the LP solver fails."""
    import numpy as np
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix

    base = 0.0
    cands: list[tuple[float, float, float, float]] = []  # (release, deadline, p, gain)
    for t in tasks:
        prof = workload[t.model]
        times = send_times(t) if send_times is not None else (t.arrival_ms,)
        cloud_ok = prof.cloud_utility > 0 and any(s + cloud_ms(t, s) <= t.deadline_ms for s in times
                                                  if s <= t.deadline_ms)
        fallback = prof.cloud_utility if cloud_ok else 0.0
        base += fallback
        p = edge_ms(t)
        gain = prof.edge_utility - fallback
        if gain > 0 and t.arrival_ms + p <= t.deadline_ms:
            cands.append((t.arrival_ms, t.deadline_ms, p, gain))
    if not cands:
        return {"bound": base, "cloud_part": base, "edge_gain": 0.0, "edge_tasks": 0, "lp_status": "trivial"}
    points = sorted({c[0] for c in cands} | {c[1] for c in cands})
    index = {v: i for i, v in enumerate(points)}
    n, m = len(cands), len(points) - 1
    # variables: x_0..x_{n-1}, then z_jk for each task j and interval k inside its window
    rows_eq, cols_eq, vals_eq = [], [], []
    rows_cap, cols_cap = [], []
    nz = n
    for j, (r, d, p, _) in enumerate(cands):
        rows_eq.append(j), cols_eq.append(j), vals_eq.append(p)
        for k in range(index[r], index[d]):
            rows_eq.append(j), cols_eq.append(nz), vals_eq.append(-1.0)
            rows_cap.append(k), cols_cap.append(nz)
            nz += 1
    a_eq = coo_matrix((vals_eq, (rows_eq, cols_eq)), shape=(n, nz)).tocsr()
    a_ub = coo_matrix((np.ones(len(rows_cap)), (rows_cap, cols_cap)), shape=(m, nz)).tocsr()
    b_ub = np.diff(np.asarray(points, dtype=float))
    c = np.zeros(nz)
    c[:n] = [-g for *_, g in cands]
    bounds = [(0.0, 1.0)] * n + [(0.0, None)] * (nz - n)
    res = linprog(c, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=np.zeros(n), bounds=bounds, method="highs")
    if res.status != 0:
        raise RuntimeError(f"upper-bound LP failed: {res.message}")
    gain = float(-res.fun)
    return {"bound": base + gain, "cloud_part": base, "edge_gain": gain, "edge_tasks": n, "lp_status": "optimal"}
