"""Upper bounds on the utility any analytics scheduler can earn on one edge's trace (offline oracles).

Every bound knows every arrival and every realised edge execution time in advance (the harness's seeded draws).
Each task earns at most ``max(0, cloud value, edge value)``:

* cloud value: by default (``cloud_chance=None``, the *clairvoyant cloud*) ``benefit - cloud_cost`` if some send time
  ``s`` in ``[arrival, deadline]`` returns by the deadline with the task's drawn round trip at ``s`` (the network's
  extra latency depends on ``s``), else 0. With ``cloud_chance(task, s)`` = the probability that a round trip sent
  at ``s`` is on time, the *expected* cloud value ``max_s chance * benefit - cloud_cost`` instead (see below). The
  cloud has unbounded concurrency, so cloud choices never interact;
* edge value: ``benefit - edge_cost`` if the task is run on the edge within its window; the edge runs one task at a
  time, so the chosen set must be schedulable on one machine with release times and deadlines.

Two ways to choose the edge set (``method``):

* ``"lp"`` — a relaxation: the edge may be *preempted* and the choice ``x_j`` is fractional. Preemptive feasibility
  with release times and deadlines is a transportation problem over the elementary intervals between consecutive
  release/deadline times (Horn, "Some simple scheduling algorithms", Naval Research Logistics Quarterly 21(1), 1974):
  ``z_jk`` = time of task j run in interval k, ``sum_k z_jk = p_j x_j``, ``sum_j z_jk <= |k|``; the LP
  ``maximise sum_j base_j + sum_j gain_j x_j`` (``gain_j = edge value - max(0, cloud value) > 0``) is solved with
  HiGHS (``scipy.optimize.linprog``).
* ``"exact"`` — the offline optimum itself: the non-preemptive max-gain schedule with release times and deadlines,
  solved exactly by :func:`aerodaas.schedulers.single_machine.max_gain_schedule` (a dominance DP; < 1 s for an
  edge's 2,160 tasks). With the clairvoyant cloud this is the best any schedule could earn on that seed's draws;
  it is never above the LP.

The expected-cloud bound. A scheduler that does not see a cloud call's draw before sending it (every online policy:
the draw is seeded per task, independent of everything observed before) earns on a task sent at ``s`` an expected
``chance(s) * benefit - cloud_cost``; on the edge it can do no better than the clairvoyant edge schedule. So its
*expected* utility over the cloud draws is at most the exact bound computed with the expected cloud value. It is a
bound on the mean over seeds, not on every seed (a lucky seed can lie above it by the cloud draws' noise).
"""
from __future__ import annotations

import math
import os
import pickle
import resource
import select
import signal
import time
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any, Callable, Sequence

import numpy as np

from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload
from aerodaas.schedulers.single_machine import max_gain_schedule

__all__ = ["utility_upper_bound", "lognormal_on_time_chance", "lognormal_slack", "EDGE_LEVELS", "Budget",
           "bounded", "NOT_COMPUTED"]

#: what a bound that ran out of its budget reports instead of a number
NOT_COMPUTED = "not computed"


@dataclass(frozen=True)
class Budget:
    """Time (s, wall clock) and memory (MiB of address space above the process's own at the start) one exact
    bound may use. Why: on a stall-and-flush trace one edge's exact bound ran over 5 min and 2 GB (the
    flushed frames put more than 64 task groups in one window, and the DP's label sets grow exponentially)."""

    time_s: float = 120.0
    memory_mb: float = 1024.0

    def __post_init__(self) -> None:
        if not (self.time_s > 0 and self.memory_mb > 0):
            raise ValueError(f"bound budget: time_s and memory_mb must be > 0, got {self.time_s}, {self.memory_mb}")


def _vsize() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def bounded(fn: Callable[[], Any], budget: Budget) -> tuple[str, Any]:
    """Run ``fn()`` in a forked child under ``budget`` (address space limited with ``RLIMIT_AS``, killed at the
    time limit): ``("ok", value)``, ``("time", None)``, ``("memory", None)``; re-raises in the caller an
    exception ``fn`` raised (RuntimeError with its text). Linux (``os.fork``, ``/proc``)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: compute, send, exit without running the parent's atexit handlers
        try:
            os.close(r)
            limit = _vsize() + int(budget.memory_mb * 2 ** 20)
            resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
            try:
                out = ("ok", fn())
            except MemoryError:
                out = ("memory", None)
            except BaseException as e:  # noqa: BLE001 - handed to the parent
                out = ("error", f"{type(e).__name__}: {e}")
            data = pickle.dumps(out)
            with os.fdopen(w, "wb") as f:
                f.write(data)
        finally:
            os._exit(0)
    os.close(w)
    chunks, end = [], time.monotonic() + budget.time_s
    with os.fdopen(r, "rb") as f:
        while True:
            left = end - time.monotonic()
            if left <= 0 or not select.select([f], [], [], left)[0]:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return ("time", None)
            b = os.read(f.fileno(), 1 << 20)
            if not b:
                break
            chunks.append(b)
    _, status = os.waitpid(pid, 0)
    if not chunks:  # killed by the kernel (e.g. out of memory) before it could answer
        return ("memory", None)
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "error":
        raise RuntimeError(f"exact bound failed: {value}")
    return kind, value

#: on-time chances at which the non-anticipative edge reward steps (see :func:`utility_upper_bound`)
EDGE_LEVELS = (0.9999, 0.999, 0.995, 0.99, 0.98, 0.96, 0.94, 0.92, 0.9, 0.87, 0.84, 0.8, 0.75, 0.7, 0.65, 0.6, 0.55,
               0.5, 0.45, 0.4, 0.35, 0.3, 0.25, 0.2, 0.15, 0.1, 0.05, 0.02)


def lognormal_on_time_chance(cloud_ms: float, sigma: float, slack_ms: float, extra_ms: float = 0.0) -> float:
    """P(``cloud_ms * X + extra_ms <= slack_ms``) for the harness's cloud jitter ``X = exp(N(-sigma²/2, sigma))``
    (:class:`aerodaas.schedulers.dispatch.emulation.Jitter`, mean 1): ``Phi((ln((slack - extra) / cloud) + sigma²/2)
    / sigma)``; a step at 1 for ``sigma = 0``."""
    room = slack_ms - extra_ms
    if room <= 0:
        return 0.0
    if sigma <= 0:
        return 1.0 if cloud_ms <= room else 0.0
    z = (math.log(room / cloud_ms) + sigma * sigma / 2) / sigma
    return 0.5 * math.erfc(-z / math.sqrt(2))


def lognormal_slack(profile_ms: float, sigma: float, chance: float) -> float:
    """The time (ms) a run of ``profile_ms * X``, ``X = exp(N(-sigma²/2, sigma))``, fits with probability
    ``chance``: ``profile * exp(-sigma²/2 + sigma * z_chance)`` (``profile_ms`` for sigma 0)."""
    if sigma <= 0:
        return profile_ms
    return profile_ms * math.exp(-sigma * sigma / 2 + sigma * NormalDist().inv_cdf(min(max(chance, 1e-12), 1 - 1e-12)))


def _lp_edge_gain(cands: list[tuple[float, float, float, float]]) -> float:
    from scipy.optimize import linprog  # lazy: heavy dependency (SciPy)
    from scipy.sparse import coo_matrix  # lazy: heavy dependency (SciPy)

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
    return float(-res.fun)


def utility_upper_bound(tasks: Sequence[AnalyticsTask], workload: Workload, edge_ms: Callable[[AnalyticsTask], float],
                        cloud_ms: Callable[[AnalyticsTask, float], float],
                        send_times: Callable[[AnalyticsTask], Sequence[float]] | None = None, *,
                        method: str = "lp",
                        cloud_chance: Callable[[AnalyticsTask, float], float] | None = None,
                        edge_slack: Callable[[AnalyticsTask, float], float] | None = None,
                        levels: Sequence[float] = EDGE_LEVELS) -> dict:
    """An upper bound for one edge (see the module docstring).

    ``edge_ms(task)``: its realised edge execution time (ms); ``cloud_ms(task, send_ms)``: its realised round trip
    if sent at ``send_ms`` (used unless ``cloud_chance`` is given); ``cloud_chance(task, send_ms)``: the probability
    it is on time if sent then (the expected-cloud bound); ``send_times(task)``: the send times worth trying
    (default: its arrival; give the times where the network's extra latency changes within the window too).
    ``method``: ``"lp"`` or ``"exact"``. Returns ``{"bound", "cloud_part", "edge_gain", "edge_tasks", "method",
    "edge_schedule"}`` (utility units; ``edge_tasks``: edge candidates with a positive gain, one per task and
    edge-time level when ``edge_slack`` is given; ``edge_schedule``: the
    exact method's ``[(task_id, start_ms)]``, else None). Raises ValueError for an unknown method, RuntimeError if
    the LP solver fails; ValueError for ``edge_slack`` with ``"lp"`` or ``levels`` not descending in (0, 1]."""
    if method not in ("lp", "exact"):
        raise ValueError(f"method must be 'lp' or 'exact', got {method!r}")
    if method == "lp" and edge_slack is not None:
        raise ValueError("method 'lp' has no one-variant-per-task constraint: use edge_slack with method 'exact'")
    if list(levels) != sorted(levels, reverse=True) or not all(0 < q <= 1 for q in levels):
        raise ValueError(f"levels must be descending probabilities in (0, 1], got {tuple(levels)!r}")
    base = 0.0
    cands: list[tuple[float, float, float, float]] = []  # (release, deadline, p, gain)
    ids: list[int] = []
    for t in tasks:
        prof = workload[t.model]
        times = [s for s in (send_times(t) if send_times is not None else (t.arrival_ms,)) if s <= t.deadline_ms]
        if cloud_chance is not None:
            fallback = max([0.0] + [cloud_chance(t, s) * prof.benefit - prof.cloud_cost for s in times])
        else:
            cloud_ok = prof.cloud_utility > 0 and any(s + cloud_ms(t, s) <= t.deadline_ms for s in times)
            fallback = prof.cloud_utility if cloud_ok else 0.0
        base += fallback
        p = edge_ms(t)
        if edge_slack is None:
            gain = prof.edge_utility - fallback
            if gain > 0 and t.arrival_ms + p <= t.deadline_ms:
                cands.append((t.arrival_ms, t.deadline_ms, p, gain))
                ids.append(t.task_id)
            continue
        # expected edge reward by start time, as step variants that over-estimate it: a start in
        # (d - slack(P_{k-1}), d - slack(P_k)] earns at most P_{k-1} * benefit - edge cost
        prev = 1.0
        for lv in list(levels) + [0.0]:
            latest = t.deadline_ms - (edge_slack(t, lv) if lv > 0 else 0.0)
            gain = prev * prof.benefit - prof.edge_cost - fallback
            if gain > 0 and latest >= t.arrival_ms:
                cands.append((t.arrival_ms, latest + p, p, gain))
                ids.append(t.task_id)
            prev = lv
    out = {"cloud_part": base, "edge_tasks": len(cands), "method": method, "edge_schedule": None}
    if not cands:
        return {**out, "bound": base, "edge_gain": 0.0}
    if method == "lp":
        gain = _lp_edge_gain(cands)
    else:
        gain, schedule = max_gain_schedule(cands, groups=ids)
        out["edge_schedule"] = [(ids[j], s) for j, s in schedule]
    return {**out, "bound": base + gain, "edge_gain": gain}
