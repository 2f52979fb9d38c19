"""The max-gain schedule DP exactly as it was before it was compiled (commit 976279e, ``schedulers/single_machine.py``):
the reference that the compiled and the rewritten pure-Python DP must agree with, ties included
(``tests/schedulers/test_laplan_planner_equivalence.py``). Test code only: production uses
:func:`aerodaas.schedulers.single_machine.max_gain_schedule`."""
from __future__ import annotations

import heapq
import itertools
from typing import Sequence

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


def max_gain_schedule(jobs: Sequence[tuple[float, float, float, float]], *, free_at: float = float("-inf"),
                      groups: Sequence[object] | None = None) -> tuple[float, list[tuple[int, float]]]:
    """The exact optimum of 1 | r_j | Σ w_j U_j (see the module docstring).

    ``jobs``: ``(release_ms, deadline_ms, processing_ms, gain)`` each; jobs with gain <= 0 or that cannot fit
    their own window are ignored. ``free_at``: the machine is busy until then (ms). ``groups``: a key per job; at
    most one job of a group is chosen (its variants). Returns ``(gain, schedule)``, ``schedule`` = ``[(job index,
    start_ms), ...]`` in start order, every job starting at its release or when the previous one ends, none before
    ``free_at``. Ties prefer the schedule found first. Raises ValueError if the jobs of one group differ in
    release or processing time."""
    gains = [w for *_, w in jobs]
    members: dict[object, list[int]] = {}
    for j, (r, d, p, w) in enumerate(jobs):
        if w > 0 and max(r, free_at) + p <= d + _EPS:
            members.setdefault(groups[j] if groups is not None else j, []).append(j)
    if not members:
        return 0.0, []
    gs: list[_Group] = []
    for k, js in enumerate(members.values()):
        r, p = jobs[js[0]][0], jobs[js[0]][2]
        if any(jobs[j][0] != r or jobs[j][2] != p for j in js):
            raise ValueError("the jobs of one group must share their release and processing time")
        gs.append(_Group(1 << k, max(r, free_at), p, [(jobs[j][1] - p, j) for j in js], gains))
    gs.sort(key=lambda g: g.release)
    releases = sorted({g.release for g in gs})

    seq = itertools.count()
    heap: list = [(releases[0], next(seq), 0, 0.0, None)]  # (free at, tie, used mask, gain, path)
    store: dict[int, tuple[float, object]] = {}         # used mask (still startable at now) -> (gain, path)
    active: list[_Group] = []                           # released, a variant still startable
    best_gain, best_path = 0.0, None
    gi = 0
    alive_mask = 0

    def dominated(mask: int, g: float) -> bool:
        sub = mask
        while True:
            v = store.get(sub)
            if v is not None and v[0] >= g - _EPS:
                return True
            if sub == 0:
                return False
            sub = (sub - 1) & mask

    def insert(mask: int, g: float, path) -> None:
        for k in [k for k, v in store.items() if k & mask == mask and v[0] <= g + _EPS]:
            del store[k]
        store[mask] = (g, path)

    def expand(mask: int, g: float, path, t: float, cands: list[tuple[_Group, int]]) -> None:
        for grp, j in cands:
            if not mask & grp.bit:
                heapq.heappush(heap, (t + grp.proc, next(seq), mask | grp.bit, g + gains[j], (j, t, path)))

    expiry = float("inf")  # the earliest time an active group's last variant stops being startable
    while heap or gi < len(gs):
        t = min(heap[0][0] if heap else float("inf"), gs[gi].release if gi < len(gs) else float("inf"))
        if t > expiry + _EPS:  # time advanced past an expiry: forget used jobs that can no longer start
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
            store = pruned
        newly: list[_Group] = []
        while gi < len(gs) and gs[gi].release == t:
            if gs[gi].at(t) is not None:
                newly.append(gs[gi])
                alive_mask |= gs[gi].bit
                expiry = min(expiry, gs[gi].latest[-1])
            gi += 1
        old = list(store.items()) if newly else ()
        active += newly
        fresh = []
        while heap and heap[0][0] == t:
            _, _, mask, g, path = heapq.heappop(heap)
            mask &= alive_mask
            if dominated(mask, g):
                continue
            insert(mask, g, path)
            fresh.append(mask)
            if g > best_gain + _EPS:
                best_gain, best_path = g, path
        if fresh:
            cands = [(grp, j) for grp in active if (j := grp.at(t)) is not None]
            for mask in fresh:
                if mask in store:
                    g, path = store[mask]
                    expand(mask, g, path, t, cands)
        if newly:
            fresh_set = set(fresh)
            cands = [(grp, grp.at(t)) for grp in newly]
            for mask, (g, path) in old:
                if mask in store and store[mask][0] == g and mask not in fresh_set:
                    expand(mask, g, path, t, cands)
    out = []
    while best_path is not None:
        j, s, best_path = best_path
        out.append((j, s))
    return best_gain, out[::-1]
