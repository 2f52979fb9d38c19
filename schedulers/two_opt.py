"""TwoOptScheduler: a near-optimal trajectory-scheduler plug-in (nearest neighbour + 2-opt + Or-opt).

It also serves as the worked example of the plug-in contract (the paper's INavigate):

* subclass :class:`~aerodaas.schedulers.base.TrajectoryScheduler`, give it a unique ``name``;
* override ``order(waypoints, start) -> list[Waypoint]``: return the SAME Waypoint objects, each exactly once,
  in the order the drone should fly them from ``start`` (an ``(x, y, z)`` tuple). The objective every built-in
  scheduler is measured by is ``TrajectoryScheduler.tour_length(ordered, start)``: the OPEN path
  start -> w1 -> ... -> wn in 3-D Euclidean metres (no return to start);
* optionally override ``order_segments(segments, start)`` to plan *nodes*: a list of lists in which each
  inner list is flown as given (a fixed ORDERED run of waypoints entered at its first waypoint and left at its
  last one, or a single free waypoint); return the same inner lists, reordered. Without an override the base
  class asks ``order()`` to sequence the runs by their first waypoint;
* ``order`` is only ever called for UNORDERED navigation, and only with the waypoints of one mission (one
  priority): the base class keeps priorities apart, keeps ORDERED runs contiguous, keeps velocity commands
  after the waypoints, and is thread-safe — the plug-in needs no locking. It must be deterministic (seed any
  randomness) and fast: it runs inside the scheduler actor when analytics inject waypoints mid-mission.

Coordinates are used as given (``x``, ``y``, ``z``: ENU metres from home for relative waypoints), exactly as
``tour_length`` and :class:`NearestNeighborScheduler` use them.

Algorithms (all deterministic):

0. Up to ``exact_max`` nodes (default 9): the exact optimum by the **Held–Karp** dynamic programme
   (M. Held & R. M. Karp, "A dynamic programming approach to sequencing problems", J. SIAM 10, 1962) for an
   open path with a fixed first node, O(2^n n²) — about 1 ms at n = 9. Larger inputs use steps 1-4.
1. **Nearest neighbour** construction from ``start`` (ties keep the given order), the same greedy rule as
   :class:`NearestNeighborScheduler`.
2. **2-opt** (G. A. Croes, "A method for solving traveling-salesman problems", Operations Research 6, 1958):
   reverse a sub-path when that shortens the path; adapted to an open path with a fixed first node (reversing
   the tail is a move too).
3. **Or-opt** (I. Or, "Traveling salesman-type combinatorial problems and their relation to the logistics of
   regional blood banking", PhD thesis, Northwestern University, 1976): move a chain of 1-3 consecutive nodes
   elsewhere, possibly reversed.

   Both neighbourhoods are searched with K-nearest-neighbour candidate lists and don't-look bits
   (J. L. Bentley, "Fast algorithms for geometric traveling salesman problems", ORSA J. on Computing 4, 1992),
   so a local optimum costs ~O(n K) per pass instead of O(n²).
4. **Iterated local search**: a fixed number (150) of seeded double-bridge kicks (O. Martin, S. W. Otto &
   E. W. Felten, "Large-step Markov chains for the TSP", Complex Systems 5, 1991), each followed by the local
   search restricted to the nodes whose edges changed; a kick is kept only if the path got shorter. Two of
   three kicks swap two short neighbouring segments (<= 50 nodes); every third swaps two parts that reach the
   end of the path, which changes the direction the drone heads off in — the typical trap of an open path
   that starts inside the area.

Fixed ORDERED runs are nodes with distinct entry and exit points, so the cost between nodes is asymmetric
(exit of one -> entry of the next); every move's gain is computed exactly for that case (reversing a sub-path
never reverses a run), and the run's internal length is a constant.

The result is never longer than the nearest-neighbour path it starts from (only improving moves are applied).
"""
from __future__ import annotations

import random
from collections import deque
from typing import Sequence

import numpy as np

from aerodaas.model.types import Waypoint

from aerodaas.schedulers.base import TrajectoryScheduler

_EPS = 1e-9  # metres: a move must shorten the path by more than this to be applied
_KICK_SEGMENT = 50  # longest segment a local double-bridge kick moves (nodes)
_DEFAULT_KICKS = 150  # iterated-local-search rounds: ~25 ms of CPU at 200 waypoints

__all__ = ["TwoOptScheduler", "node_cost_matrix", "nearest_neighbour_path", "path_cost", "improve_path",
           "held_karp_open_path"]


def node_cost_matrix(entries: np.ndarray, exits: np.ndarray, start: Sequence[float]) -> np.ndarray:
    """Cost matrix in metres for an open path over nodes with entry/exit points, with node 0 = ``start``.

    ``entries`` and ``exits`` are ``(m, 3)`` arrays (equal rows for a single waypoint). Returns the
    ``(m+1, m+1)`` array ``D`` with ``D[a, b]`` = 3-D Euclidean distance from the exit of node ``a`` to the entry
    of node ``b`` (nodes 1..m are the inputs in order); ``D[0, b]`` is the distance from ``start``. The diagonal
    is 0; column 0 is never used by a path (the start is fixed).
    """
    entries = np.asarray(entries, dtype=float).reshape(-1, 3)
    exits = np.asarray(exits, dtype=float).reshape(-1, 3)
    s = np.asarray(start, dtype=float).reshape(1, 3)
    out_pts = np.vstack([s, exits])
    in_pts = np.vstack([s, entries])
    d = np.zeros((len(out_pts), len(in_pts)))
    for k in range(3):  # one coordinate at a time: peak memory ~2 (m+1)^2 floats
        diff = out_pts[:, k, None] - in_pts[None, :, k]
        d += diff * diff
    np.sqrt(d, out=d)
    np.fill_diagonal(d, 0.0)
    return d


def nearest_neighbour_path(D: np.ndarray) -> list[int]:
    """Greedy nearest-neighbour open path over ``D`` from node 0: ``[0, ...]``. Ties go to the lowest index."""
    n1 = D.shape[0]
    visited = np.zeros(n1, dtype=bool)
    visited[0] = True
    path = [0]
    cur = 0
    for _ in range(n1 - 1):
        row = np.where(visited, np.inf, D[cur])
        cur = int(np.argmin(row))
        visited[cur] = True
        path.append(cur)
    return path


def path_cost(D, path: Sequence[int]) -> float:
    """Sum of ``D[path[k], path[k+1]]`` (metres); ``D`` is an array or a list of lists."""
    return float(sum(D[a][b] for a, b in zip(path, path[1:])))


def held_karp_open_path(D) -> tuple[float, list[int]]:
    """Exact shortest open path over the cost matrix ``D`` (``(m+1, m+1)``, node 0 = the fixed start, free end;
    asymmetric costs allowed) by the Held–Karp (1962) dynamic programme, O(2^m m²) time, O(2^m m) memory
    (vectorised over the sets of each size: ~1 ms at m = 9, ~3 ms at m = 12, ~0.2 s at m = 16).

    Returns ``(cost, path)`` with ``path = [0, ...]``. Raises ValueError above 16 nodes besides the start."""
    D = np.asarray(D, dtype=float)
    m = D.shape[0] - 1
    if m > 16:
        raise ValueError(f"Held-Karp is limited to 16 nodes besides the start here, got {m}")
    if m == 0:
        return 0.0, [0]
    C = D[1:, 1:]
    n_masks = 1 << m
    # dp[S, j]: shortest path from the start through exactly the node set S (bit k = node k+1), ending at j
    dp = np.full((n_masks, m), np.inf)
    parent = np.full((n_masks, m), -1, dtype=np.int64)
    nodes = np.arange(m)
    dp[1 << nodes, nodes] = D[0, 1:]
    masks = np.arange(n_masks)
    size = np.zeros(n_masks, dtype=np.int64)
    for j in range(m):
        size += (masks >> j) & 1
    for k in range(2, m + 1):  # sets in order of size; one vectorised step per (size, last node)
        layer = masks[size == k]
        for j in range(m):
            sets = layer[((layer >> j) & 1) == 1]
            vals = dp[sets ^ (1 << j)] + C[:, j]  # row: come to j from every node of the smaller set
            best = vals.argmin(axis=1)
            dp[sets, j] = vals[np.arange(len(sets)), best]
            parent[sets, j] = best
    full = n_masks - 1
    last = int(dp[full].argmin())
    cost = float(dp[full, last])
    path, mask = [], full
    while last >= 0:
        path.append(last + 1)
        prev = int(parent[mask, last])
        mask ^= 1 << last
        last = prev
    return cost, [0] + path[::-1]


def _neighbour_lists(D: np.ndarray, k: int) -> tuple[list[list[int]], list[list[float]]]:
    """For each node the ``k`` nearest other nodes by the symmetric distance min(D[a,b], D[b,a]), nearest first
    (node 0, the start, is a candidate neighbour; its own list is unused)."""
    n1 = D.shape[0]
    S = np.minimum(D, D.T)
    np.fill_diagonal(S, np.inf)
    k = max(1, min(k, n1 - 1))
    idx = np.argsort(S, axis=1, kind="stable")[:, :k]  # nearest first, ties by index (deterministic)
    dsel = np.take_along_axis(S, idx, axis=1)
    return idx.tolist(), dsel.tolist()


def improve_path(D, path: list[int], *, neighbours: int = 10, or_opt_max: int = 3, kicks: int = 0,
                 seed: int = 0) -> list[int]:
    """Improve the open path ``path`` (``path[0] == 0``, the fixed start) over the cost matrix ``D`` with 2-opt
    and Or-opt local search (neighbour lists + don't-look bits), then ``kicks`` iterated-local-search rounds of
    seeded double-bridge kicks (see the module doc). ``D`` may be asymmetric (fixed runs). Returns a new path never longer than
    ``path``. Deterministic for a given ``seed``."""
    Dn = np.asarray(D, dtype=float)
    n1 = Dn.shape[0]
    if len(path) != n1 or path[0] != 0 or sorted(path) != list(range(n1)):
        raise ValueError("path must be a permutation of 0..m starting at node 0 (the start)")
    t = list(path)
    if n1 <= 2:
        return t
    asym = not np.allclose(Dn[1:, 1:], Dn[1:, 1:].T, rtol=0.0, atol=1e-12)
    neigh, neigh_d = _neighbour_lists(Dn, neighbours)
    Dl = Dn.tolist()
    pos = [0] * n1
    _local_search(Dl, neigh, neigh_d, t, pos, t[1:], asym, or_opt_max)
    best, best_cost = t[:], path_cost(Dl, t)
    m = n1 - 1
    if kicks > 0 and m >= 3:
        rng = random.Random(seed)
        max_seg = max(1, min(_KICK_SEGMENT, m // 3))
        cost = best_cost
        for it in range(kicks):
            # double bridge on the open path: A B C D -> A C B D (A holds the start, D may be empty)
            if it % 3 == 2:
                # swap two parts of the path that reach its end: changes which way the drone heads first
                p1 = rng.randint(1, m - 1)
                p2 = rng.randint(p1 + 1, m)
                p3 = m + 1
            else:
                p1 = rng.randint(1, m - 1)
                p2 = min(p1 + rng.randint(1, max_seg), m)
                p3 = min(p2 + rng.randint(1, max_seg), m + 1)
            if not 1 <= p1 < p2 < p3 <= m + 1:
                continue
            a0, b0, b1, c0, c1 = best[p1 - 1], best[p1], best[p2 - 1], best[p2], best[p3 - 1]
            kick = Dl[a0][c0] + Dl[c1][b0] - Dl[a0][b0] - Dl[b1][c0]
            touched = [a0, b0, b1, c0, c1]
            if p3 <= m:
                d0 = best[p3]
                kick += Dl[b1][d0] - Dl[c1][d0]
                touched.append(d0)
            t = best[:p1] + best[p2:p3] + best[p1:p2] + best[p3:]
            cost = best_cost + kick + _local_search(Dl, neigh, neigh_d, t, pos, touched, asym, or_opt_max)
            if cost < best_cost - _EPS:
                best, best_cost = t, cost
        best_cost = path_cost(Dl, best)
    if best_cost > path_cost(Dl, path):  # cannot happen (only improving moves are applied); belt and braces
        return list(path)
    return best


def _local_search(D: list[list[float]], neigh: list[list[int]], neigh_d: list[list[float]], t: list[int],
                  pos: list[int], seeds, asym: bool, or_opt_max: int) -> float:
    """2-opt + Or-opt on the open path ``t`` (in place; ``pos`` is scratch space for node positions) until no
    candidate move improves it. ``seeds`` are the nodes whose don't-look bits start cleared. Returns the total
    change of the path length (<= 0, metres)."""
    return _LocalSearch(D, neigh, neigh_d, t, pos, asym, or_opt_max).run(seeds)


class _LocalSearch:
    """The state of one :func:`_local_search`: the path ``t`` and node positions ``pos`` (both updated in place),
    the don't-look queue, and for an asymmetric ``D`` the prefix sums of the reversal penalty."""

    def __init__(self, D, neigh, neigh_d, t: list[int], pos: list[int], asym: bool, or_opt_max: int) -> None:
        self.D, self.neigh, self.neigh_d, self.t, self.pos = D, neigh, neigh_d, t, pos
        self.asym, self.or_opt_max = asym, or_opt_max
        self.m = len(t) - 1
        for k, v in enumerate(t):
            pos[v] = k
        self.inq = [False] * (self.m + 1)
        self.queue: deque[int] = deque()
        #: P[k] = sum over q < k of (D[t[q+1]][t[q]] - D[t[q]][t[q+1]]): reversal penalty of an asymmetric sub-path
        self.P: list[float] = []
        if asym:
            self.prefix()

    def run(self, seeds) -> float:
        """Improve until no queued node has an improving move; the total change of the path length."""
        self.push(*seeds)
        total = 0.0
        queue, inq = self.queue, self.inq
        while queue:
            a = queue.popleft()
            inq[a] = False
            d = self.try_two_opt(a) or self.try_or_opt(a)
            if d:
                total += d
                self.push(a)
        return total

    def prefix(self) -> None:
        D, t, P = self.D, self.t, self.P
        P.clear()
        acc = 0.0
        P.append(0.0)
        for q in range(self.m):
            x, y = t[q], t[q + 1]
            acc += D[y][x] - D[x][y]
            P.append(acc)

    def push(self, *nodes: int) -> None:
        for v in nodes:
            if v and not self.inq[v]:
                self.inq[v] = True
                self.queue.append(v)

    def _moved(self, lo: int, hi: int, ends) -> None:
        """Positions ``lo..hi`` of the path changed: update ``pos``, the penalty sums, and queue ``ends``."""
        t, pos = self.t, self.pos
        for k in range(lo, hi + 1):
            pos[t[k]] = k
        if self.asym:
            self.prefix()
        self.push(*ends)

    def try_two_opt(self, a: int) -> float:
        """The best improving 2-opt move that adds an edge from ``a`` to one of its neighbours, applied; its
        change of the path length (0.0: none)."""
        D, t, pos, m, P, asym = self.D, self.t, self.pos, self.m, self.P, self.asym
        pa = pos[a]
        best_d, best_ij = -_EPS, None
        # Each candidate adds the edge a-b. "out" moves remove a's outgoing edge (a is the last node: none),
        # "in" moves remove a's incoming edge. Neighbour lists are sorted, so once the new edge is no shorter
        # than the removed one (the positive-gain criterion) no later neighbour can qualify.
        last = pa == m
        out_a = 0.0 if last else D[a][t[pa + 1]]
        in_a = D[t[pa - 1]][a]
        na, nd = self.neigh[a], self.neigh_d[a]
        for k in range(len(na)):
            db = nd[k]
            use_out = last or db < out_a
            use_in = db < in_a
            if not (use_out or use_in):
                break
            pb = pos[na[k]]
            cands = []
            if use_out:
                if pb > pa + 1:
                    cands.append((pa, pb))          # t[i]=a, t[j]=b
                elif pb < pa - 1:
                    cands.append((pb, pa))          # t[i]=b, t[j]=a
            if use_in:
                if pb > pa + 1:
                    cands.append((pa - 1, pb - 1))  # t[i+1]=a, t[j+1]=b
                elif 1 <= pb < pa - 1:
                    cands.append((pb - 1, pa - 1))  # t[i+1]=b, t[j+1]=a
            for i, j in cands:
                # reverse t[i+1..j]: edges (t[i], t[i+1]), (t[j], t[j+1]) -> (t[i], t[j]), (t[i+1], t[j+1])
                x, y = t[i], t[j]
                Dx = D[x]
                d = Dx[y] - Dx[t[i + 1]]
                if j < m:
                    z = t[j + 1]
                    d += D[t[i + 1]][z] - D[y][z]
                if asym:
                    d += P[j] - P[i + 1]
                if d < best_d:
                    best_d, best_ij = d, (i, j)
        if best_ij is None:
            return 0.0
        i, j = best_ij
        ends = (t[i], t[i + 1], t[j], t[j + 1] if j < m else 0)
        t[i + 1:j + 1] = t[i + 1:j + 1][::-1]
        self._moved(i + 1, j, ends)
        return best_d

    def try_or_opt(self, a: int) -> float:
        """The best improving Or-opt move of a chain of up to ``or_opt_max`` nodes starting or ending at ``a``,
        applied; its change of the path length (0.0: none)."""
        pa, m = self.pos[a], self.m
        best_d, best_mv = -_EPS, None
        for L in range(1, self.or_opt_max + 1):
            chains = [pa] if pa + L - 1 <= m else []
            if L > 1 and pa - L + 1 >= 1:
                chains.append(pa - L + 1)
            for p in chains:
                best_d, best_mv = self._best_insertion(p, L, best_d, best_mv)
        if best_mv is None:
            return 0.0
        self._apply_or_opt(*best_mv)
        return best_d

    def _best_insertion(self, p: int, L: int, best_d: float, best_mv):
        """The chain ``t[p..p+L-1]`` moved between ``t[q]`` and ``t[q+1]`` (forward or reversed) for the candidate
        ``q`` near its ends: the better of ``(best_d, best_mv)`` and the best such move."""
        D, t, pos, m = self.D, self.t, self.pos, self.m
        e = p + L - 1
        f, l = t[p], t[e]
        prev = t[p - 1]
        if e < m:
            nxt = t[e + 1]
            gain = D[prev][f] + D[l][nxt] - D[prev][nxt]
        else:
            gain = D[prev][f]
        if gain <= _EPS:
            return best_d, best_mv
        rev_pen = 0.0
        if self.asym and L > 1:
            rev_pen = sum(D[t[q + 1]][t[q]] - D[t[q]][t[q + 1]] for q in range(p, e))
        # candidate insertion points q (insert between t[q] and t[q+1]): u=t[q] near an end, or v=t[q+1] near one
        qs = []
        for end in ((f, l) if L > 1 else (f,)):
            ne, nde = self.neigh[end], self.neigh_d[end]
            for k in range(len(ne)):
                if nde[k] >= gain:
                    break
                pb = pos[ne[k]]
                qs.append(pb)
                if pb >= 1:
                    qs.append(pb - 1)
        if e < m:
            qs.append(m)  # append at the end of the path
        for q in qs:
            if p - 1 <= q <= e:
                continue
            u = t[q]
            if q < m:
                v = t[q + 1]
                base = -D[u][v]
                fwd = base + D[u][f] + D[l][v]
                bwd = base + D[u][l] + D[f][v] + rev_pen if L > 1 else fwd
            else:
                fwd = D[u][f]
                bwd = D[u][l] + rev_pen if L > 1 else fwd
            if fwd - gain < best_d:
                best_d, best_mv = fwd - gain, (p, L, q, False)
            if bwd - gain < best_d:
                best_d, best_mv = bwd - gain, (p, L, q, True)
        return best_d, best_mv

    def _apply_or_opt(self, p: int, L: int, q: int, rev: bool) -> None:
        t, m = self.t, self.m
        e = p + L - 1
        chain = t[p:e + 1]
        if rev:
            chain.reverse()
        ends = [t[p - 1], chain[0], chain[-1], t[q]]
        if e < m:
            ends.append(t[e + 1])
        if q < m:
            ends.append(t[q + 1])
        if q < p:
            lo, hi = q + 1, e
            t[lo:hi + 1] = chain + t[q + 1:p]
        else:
            lo, hi = p, q
            t[lo:hi + 1] = t[e + 1:q + 1] + chain
        self._moved(lo, hi, ends)


class TwoOptScheduler(TrajectoryScheduler):
    """Near-optimal trajectory scheduler: nearest neighbour improved by 2-opt and Or-opt (see the module doc).

    Orders an UNORDERED list as an OPEN path from ``start`` (the drone's position; no return), minimising
    ``tour_length`` in 3-D Euclidean metres, and keeps fixed ORDERED runs contiguous and in their order
    (:meth:`order_segments`). Deterministic. ``aerodaas bench tours`` on a 2-core machine: optimal on the
    10-waypoint instances, within ~1-2 % of a proven lower bound at 200 waypoints in ~30 ms (nearest neighbour:
    ~20 % above it).

    Parameters: ``exact_max`` — up to this many nodes solve exactly (Held–Karp; 0 disables, at most 12);
    ``neighbours`` — candidate-list size K; ``or_opt_max`` — longest chain Or-opt moves (1-3); ``kicks`` —
    iterated-local-search rounds (``None``: 150, 0 disables); ``seed`` — seed of those kicks (the same input
    always gives the same order). Memory is O(n²) (the distance matrix): meant for up to a few thousand
    waypoints.
    """

    name = "two_opt"

    def __init__(self, env=None, start: Sequence[float] = (0.0, 0.0, 0.0), *, exact_max: int = 9,
                 neighbours: int = 10, or_opt_max: int = 3, kicks: int | None = None, seed: int = 0) -> None:
        super().__init__(env, start)
        if not 0 <= exact_max <= 12:
            raise ValueError(f"exact_max must be within [0, 12], got {exact_max}")
        if kicks is not None and kicks < 0:
            raise ValueError(f"kicks must be >= 0 or None, got {kicks}")
        if not 1 <= or_opt_max <= 3:
            raise ValueError(f"or_opt_max must be 1, 2 or 3, got {or_opt_max}")
        if neighbours < 1:
            raise ValueError(f"neighbours must be >= 1, got {neighbours}")
        self.exact_max = int(exact_max)
        self.neighbours = int(neighbours)
        self.or_opt_max = int(or_opt_max)
        self.kicks = kicks
        self.seed = int(seed)

    def order(self, waypoints: list[Waypoint], start: Sequence[float]) -> list[Waypoint]:
        """Visiting order (the same Waypoint objects) for an open path from ``start``."""
        return [seg[0] for seg in self.order_segments([[w] for w in waypoints], start)]

    def order_segments(self, segments: list[list[Waypoint]], start: Sequence[float]) -> list[list[Waypoint]]:
        """Order nodes, each flown as given: entered at its first waypoint, left at its last (metres)."""
        segs = list(segments)
        m = len(segs)
        if m <= 1:
            return segs
        entries = np.array([(s[0].x, s[0].y, s[0].z) for s in segs], dtype=float)
        exits = np.array([(s[-1].x, s[-1].y, s[-1].z) for s in segs], dtype=float)
        D = node_cost_matrix(entries, exits, start)
        if m <= self.exact_max:
            return [segs[k - 1] for k in held_karp_open_path(D)[1][1:]]
        kicks = _DEFAULT_KICKS if self.kicks is None else int(self.kicks)
        path = improve_path(D, nearest_neighbour_path(D), neighbours=self.neighbours, or_opt_max=self.or_opt_max,
                            kicks=kicks, seed=self.seed)
        return [segs[k - 1] for k in path[1:]]
