"""Exact max-gain schedules for one machine with release times and deadlines, non-preemptive.

Problem (1 | r_j | Σ w_j U_j in Graham's notation): jobs ``j`` with release ``r_j``, deadline ``d_j``, processing
time ``p_j`` (all ms) and gain ``w_j > 0``; choose a subset and a non-preemptive one-at-a-time schedule in which every
chosen job starts at or after its release and ends by its deadline, maximising the summed gain. The problem is
strongly NP-hard in general; this solver is exact and fast when every job's window ``d_j - r_j`` is short compared
with the horizon (the analytics workloads: windows <= 1 s over runs of 120 s). A job may come in *variants* (a
group: same release and processing time, different deadlines and gains — e.g. a higher expected gain for an
earlier end), of which at most one is chosen.

Method: a label-setting dynamic program over *left-shifted* schedules (every job starts at its release or when the
previous one ends; any feasible schedule can be shifted so, keeping its order and its job set). A label is the time
``f`` the machine becomes free, the gain so far and the set of jobs used so far that could still be started at
``f`` — jobs used earlier that can no longer start are irrelevant to the rest, which keeps the sets small (a job
with ``p_j > d_j - r_j - p_j`` can never be in one). Labels are taken in order of ``f``; at each time ``t`` (a
label's ``f`` or a release), every label free at or before ``t`` can start the jobs released at ``t``, and a new
label at ``t`` can start every job available at ``t`` (of a job's variants only the best one still startable at
``t``). A label is dropped if some label free no later with a subset of its used (still startable) jobs has at
least its gain (it can do everything the dropped one can: dominance), so the labels kept at time ``t`` form a
Pareto set over (used set, gain).

Used by the LAPLAN scheduler (a rolling plan over the pool and the predicted arrivals of the next seconds,
:mod:`.analytics_laplan`) and by the exact upper bounds of the scheduler benchmark (:mod:`aerodaas.bench.bound`).
"""
from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from aerodaas.schedulers import single_machine_jit

__all__ = ["SolveCounts", "max_gain_schedule", "max_gain_schedule_arrays"]

_EPS = 1e-9


class _Group:
    """One job and its variants: release, processing time, and (latest start, job index) by latest start, with
    the index of the best gain among the variants from each position on (a variant startable at ``t`` is one
    whose latest start is >= t: a suffix of the list)."""

    __slots__ = ("bit", "release", "proc", "latest", "best", "pos")

    def __init__(self, bit: int, release: float, proc: float, variants: list[tuple[float, int]],
                 gains: Sequence[float]) -> None:
        self.bit, self.release, self.proc = bit, release, proc
        variants.sort()
        self.latest = [v[0] for v in variants]
        self.best = [v[1] for v in variants]
        for k in range(len(variants) - 2, -1, -1):  # suffix argmax of the gain
            if gains[self.best[k + 1]] > gains[self.best[k]]:
                self.best[k] = self.best[k + 1]
        self.pos = 0

    def at(self, t: float) -> int | None:
        """The best variant still startable at ``t`` (times only grow between calls), or None."""
        while self.pos < len(self.latest) and self.latest[self.pos] + _EPS < t:
            self.pos += 1
        return self.best[self.pos] if self.pos < len(self.latest) else None


@dataclass
class SolveCounts:
    """Plans solved by the compiled kernel (``compiled``) and by the Python loop (``python``: numba missing,
    ``jit=False`` or more than 64 groups live at once), counted into the object a caller passes as ``counts`` to
    :func:`max_gain_schedule` / :func:`max_gain_schedule_arrays` (LAPLAN reports its plans solved in Python)."""

    compiled: int = 0
    python: int = 0


def _bits(rows: list) -> list[int] | None:
    """A bit per group (rows in release order) such that groups live at the same time get different bits: a bit is
    reused only by a group released more than the longest processing time + 1 ms after the previous owner's last
    latest start. Then no label still holding the old owner's bit is in the heap when the new owner is released
    (it was pushed while the old owner could still start, so it is popped by then), and the stored labels have
    forgotten it (the DP drops a group that can no longer start as soon as time passes it). Subset tests and the
    store's insertion order do not depend on which bit a group has, so the DP's answer is the same. None if more
    than 64 bits would be needed."""
    maxproc = max(row[2] for row in rows)
    free_after: list[float] = []
    out = []
    for row in rows:
        b = next((k for k, f in enumerate(free_after) if f < row[0]), None)
        if b is None:
            if len(free_after) == single_machine_jit.MAX_GROUPS:
                return None
            b = len(free_after)
            free_after.append(0.0)
        free_after[b] = row[3][-1][0] + maxproc + 1.0
        out.append(1 << b)
    return out


def _solve_compiled(members: dict, jobs, gains: list[float], free_at: float
                    ) -> tuple[float, list[tuple[int, float]]] | None:
    """The same DP, run by the compiled kernel (:mod:`.single_machine_jit`): the groups built as :class:`_Group`
    builds them (variants by (latest start, index), suffix-best gain; stable sort by release), as arrays, with
    bits reused over time (:func:`_bits`). None if more than 64 groups are live at once."""
    rows = []
    for js in members.values():
        r, _, p, _ = jobs[js[0]]
        if any(jobs[j][0] != r or jobs[j][2] != p for j in js):
            raise ValueError("the jobs of one group must share their release and processing time")
        var = sorted([(jobs[j][1] - p, j) for j in js])
        bst = [j for _, j in var]
        for q in range(len(bst) - 2, -1, -1):
            if gains[bst[q + 1]] > gains[bst[q]]:
                bst[q] = bst[q + 1]
        rows.append((max(r, free_at), None, p, var, bst))
    rows.sort(key=lambda row: row[0])
    bits = _bits(rows)
    if bits is None:
        return None
    vstart = [0]
    latest, best = [], []
    for row in rows:
        latest += [v for v, _ in row[3]]
        best += row[4]
        vstart.append(len(latest))
    return _run_kernel(np.array([row[0] for row in rows], np.float64), np.array([row[2] for row in rows], np.float64),
                       np.array(bits, np.uint64), np.array(vstart, np.int64), np.array(latest, np.float64),
                       np.array(best, np.int64), np.array(gains, np.float64))


def _run_kernel(rel, proc, bit, vstart, latest, best, gains) -> tuple[float, list[tuple[int, float]]]:
    """Solve with the compiled kernel (arrays as :func:`.single_machine_jit.solve`); the best path as
    ``(gain, [(job index, start ms), ...])`` in start order."""
    gain, nj, nt, npar, node = single_machine_jit.solve(rel, proc, bit, vstart, latest, best, gains, _EPS)
    out = []
    while node >= 0:
        out.append((int(nj[node]), float(nt[node])))
        node = npar[node]
    return float(gain), out[::-1]


def max_gain_schedule_arrays(release, deadline, proc, gain, group, ngroups: int, *, free_at: float = float("-inf"),
                             jit: bool = True, python_fallback: bool = True, counts: SolveCounts | None = None
                             ) -> tuple[float, list[tuple[int, float]]] | None:
    """:func:`max_gain_schedule` on flat arrays, with the same answer (ties included): ``release``, ``deadline``,
    ``proc`` (J,) float64 ms, ``gain`` (J,) float64, ``group`` (J,) int64 in ``[0, ngroups)`` (at most one job of
    a group is chosen). With the compiled kernel the whole preparation runs compiled too (LAPLAN's decision time:
    the Python preparation of the job tuples cost about twice the DP itself); without it, or above 64 groups live
    at once, the job tuples are built and :func:`max_gain_schedule` runs — unless ``python_fallback`` is False:
    then None is returned when the compiled kernel is there but more than 64 groups are live (the pure-Python DP is
    exponential in the live groups: 67 ms for one LAPLAN plan on a stall-and-flush trace). ``counts``:
    which DP solved it is counted there (:class:`SolveCounts`; None: not counted). Raises ValueError if the jobs of
    one group differ in release or processing time."""
    if jit and single_machine_jit.available():
        gains = np.ascontiguousarray(gain, np.float64)
        code, rel, p, bit, vstart, latest, best = single_machine_jit.prepare(
            np.ascontiguousarray(release, np.float64), np.ascontiguousarray(deadline, np.float64),
            np.ascontiguousarray(proc, np.float64), gains, np.ascontiguousarray(group, np.int64), int(ngroups),
            float(free_at), _EPS)
        if code == 1:
            raise ValueError("the jobs of one group must share their release and processing time")
        if code == 0:
            if rel.shape[0] == 0:
                return 0.0, []
            if counts is not None:
                counts.compiled += 1
            return _run_kernel(rel, p, bit, vstart, latest, best, gains)
        if not python_fallback:
            return None
    jobs = list(zip(np.asarray(release, float).tolist(), np.asarray(deadline, float).tolist(),
                    np.asarray(proc, float).tolist(), np.asarray(gain, float).tolist()))
    return max_gain_schedule(jobs, free_at=free_at, groups=np.asarray(group).tolist(), jit=False, counts=counts)


def max_gain_schedule(jobs: Sequence[tuple[float, float, float, float]], *, free_at: float = float("-inf"),
                      groups: Sequence[object] | None = None, jit: bool = True, counts: SolveCounts | None = None
                      ) -> tuple[float, list[tuple[int, float]]]:
    """The exact optimum of 1 | r_j | Σ w_j U_j (see the module docstring).

    ``jobs``: ``(release_ms, deadline_ms, processing_ms, gain)`` each; jobs with gain <= 0 or that cannot fit
    their own window are ignored. ``free_at``: the machine is busy until then (ms). ``groups``: a key per job; at
    most one job of a group is chosen (its variants). Returns ``(gain, schedule)``, ``schedule`` = ``[(job index,
    start_ms), ...]`` in start order, every job starting at its release or when the previous one ends, none before
    ``free_at``. Ties prefer the schedule found first. ``jit``: run the DP compiled (:mod:`.single_machine_jit`,
    numba) when it is installed and at most 64 groups are live at once (:func:`_bits`) — the same algorithm and
    the same answer, ties included, ~5-10x faster; False (or ``AERODAAS_NO_JIT=1``) runs the pure-Python loop.
    ``counts``: which DP solved it is counted there (:class:`SolveCounts`; None: not counted). Raises ValueError if
    the jobs of one group differ in release or processing time."""
    gains = [w for *_, w in jobs]
    members: dict[object, list[int]] = {}
    for j, (r, d, p, w) in enumerate(jobs):
        if w > 0 and max(r, free_at) + p <= d + _EPS:
            members.setdefault(groups[j] if groups is not None else j, []).append(j)
    if not members:
        return 0.0, []
    if jit and single_machine_jit.available():
        res = _solve_compiled(members, jobs, gains, free_at)
        if res is not None:
            if counts is not None:
                counts.compiled += 1
            return res
    if counts is not None:
        counts.python += 1
    return _label_setting(_groups(members, jobs, gains, free_at), gains)


def _groups(members: dict, jobs: Sequence[tuple[float, float, float, float]], gains: list[float], free_at: float
            ) -> list[_Group]:
    """The DP's groups (a bit each), sorted by release. Raises ValueError if a group's jobs differ in release or
    processing time."""
    gs: list[_Group] = []
    for k, js in enumerate(members.values()):
        r, p = jobs[js[0]][0], jobs[js[0]][2]
        if any(jobs[j][0] != r or jobs[j][2] != p for j in js):
            raise ValueError("the jobs of one group must share their release and processing time")
        gs.append(_Group(1 << k, max(r, free_at), p, [(jobs[j][1] - p, j) for j in js], gains))
    gs.sort(key=lambda g: g.release)
    return gs


def _label_setting(gs: list[_Group], gains: list[float]) -> tuple[float, list[tuple[int, float]]]:
    """The label-setting DP of the module docstring over the groups ``gs`` (sorted by release): ``(best gain,
    [(job index, start ms)])``. One pass per time ``t`` (a label's free time or a release): forget the jobs that can
    no longer start (:func:`_forget`), release the groups of ``t``, keep the labels free at ``t`` that no stored one
    dominates (:func:`_settle`), and extend them and the older ones by the jobs startable at ``t``
    (:func:`_extend`). The per-label work is written out inline in those steps (no helper call per label: this is
    LAPLAN's decision time when numba is missing). Tie order is the heap's (free time, push counter) order."""
    releases = sorted({g.release for g in gs})
    seq = itertools.count()
    heap: list = [(releases[0], next(seq), 0, 0.0, None)]  # (free at, tie, used mask, gain, path)
    store: dict[int, tuple[float, object]] = {}           # used mask (still startable at now) -> (gain, path)
    active: list[_Group] = []                             # released, a variant still startable
    best: list = [0.0, None]                              # best gain and its path
    gi, ngs = 0, len(gs)
    alive_mask = 0
    inf = float("inf")
    expiry = inf  # the earliest time an active group's last variant stops being startable
    while heap or gi < ngs:
        t = heap[0][0] if heap else inf
        if gi < ngs and gs[gi].release < t:
            t = gs[gi].release
        if t > expiry + _EPS:  # time advanced past an expiry: forget used jobs that can no longer start
            active, store, alive_mask, expiry = _forget(active, store, t)
        newly: list[_Group] = []
        while gi < ngs and gs[gi].release == t:
            grp = gs[gi]
            if grp.at(t) is not None:
                newly.append(grp)
                alive_mask |= grp.bit
                if grp.latest[-1] < expiry:
                    expiry = grp.latest[-1]
            gi += 1
        old = list(store.items()) if newly else ()
        if newly:
            active += newly
        fresh = _settle(t, heap, store, alive_mask, best)
        _extend(t, heap, seq, store, gains, active, fresh, newly, old)
    out = []
    best_path = best[1]
    while best_path is not None:
        j, s, best_path = best_path
        out.append((j, s))
    return best[0], out[::-1]


def _forget(active: list[_Group], store: dict, t: float) -> tuple[list[_Group], dict, int, float]:
    """At ``t``: the groups still startable, the store with the used jobs that can no longer start masked out (the
    best gain per masked key), their bits and the next expiry."""
    active = [grp for grp in active if grp.latest[-1] + _EPS >= t]
    expiry = min((grp.latest[-1] for grp in active), default=float("inf"))
    alive_mask = 0
    for grp in active:
        alive_mask |= grp.bit
    pruned: dict[int, tuple[float, object]] = {}
    for k, v in store.items():
        k2 = k & alive_mask
        if k2 not in pruned or pruned[k2][0] < v[0]:
            pruned[k2] = v
    return active, pruned, alive_mask, expiry


def _settle(t: float, heap: list, store: dict, alive_mask: int, best: list) -> dict[int, None]:
    """Pop the labels free at ``t``; store each one no stored label dominates (a subset of its used jobs with at
    least its gain), removing those it dominates; update ``best``. Returns the masks stored at ``t`` in
    first-insertion order (a re-insertion extends once)."""
    pop, sget = heapq.heappop, store.get
    fresh: dict[int, None] = {}
    while heap and heap[0][0] == t:
        _, _, mask, g, path = pop(heap)
        mask &= alive_mask
        lim = g - _EPS
        sub = mask
        while True:  # the submasks of mask, down to 0: a stored one with at least the gain dominates
            v = sget(sub)
            if v is not None and v[0] >= lim:
                break
            if sub == 0:
                sub = -1
                break
            sub = (sub - 1) & mask
        if sub != -1:
            continue
        hi = g + _EPS
        dead = [k for k, v in store.items() if k & mask == mask and v[0] <= hi]
        for k in dead:
            del store[k]
        store[mask] = (g, path)
        fresh[mask] = None
        if g > best[0] + _EPS:
            best[0], best[1] = g, path
    return fresh


def _extend(t: float, heap: list, seq, store: dict, gains: list[float], active: list[_Group], fresh: dict,
            newly: list[_Group], old) -> None:
    """Push the labels of starting, at ``t``, a job not used yet: every job startable at ``t`` after a label stored at
    ``t`` (``fresh``), and the jobs released at ``t`` (``newly``) after a label stored earlier and still kept
    (``old``, as it was before ``t``)."""
    push, sget = heapq.heappush, store.get
    if fresh:
        cands = []
        for grp in active:
            j = grp.at(t)
            if j is not None:
                cands.append((grp.bit, t + grp.proc, gains[j], j))
        for mask in fresh:
            v = sget(mask)
            if v is not None:
                g, path = v
                for bit, end, gj, j in cands:
                    if not mask & bit:
                        push(heap, (end, next(seq), mask | bit, g + gj, (j, t, path)))
    if newly:
        cands = [(grp.bit, t + grp.proc, gains[j], j) for grp in newly for j in (grp.at(t),)]
        for mask, (g, path) in old:
            v = sget(mask)
            if v is not None and v[0] == g and mask not in fresh:
                for bit, end, gj, j in cands:
                    if not mask & bit:
                        push(heap, (end, next(seq), mask | bit, g + gj, (j, t, path)))
