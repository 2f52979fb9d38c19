"""The compiled kernel of :mod:`aerodaas.schedulers.single_machine_jit` (imports numba: load it lazily).

Module-level ``njit(cache=True, nogil=True)`` functions: module-level so that numba's on-disk cache is reused across
processes (functions defined in a closure are recompiled in every process); ``nogil`` releases the GIL while a plan is
solved, so the other threads of a dispatcher process (its actor loop, the trace replay) are not held up.

The DP is split into one function per step (forget, settle, candidates, extend; prepare's qualifying jobs, group
order, members, variants). The steps called at every event time return scalars only: the caller grows the arrays
they fill beforehand (:func:`_grow_nodes`, :func:`_grow_store`), because returning arrays from a compiled call
costs reference-count updates on each of them; measured in CPU time against the single-function kernel on the
same random instances (2 cores, load ~6 from a concurrent test run): 10.5 vs 9.2 us median on plans of 3-12
groups, 199 vs 206 us on 40-64 groups; identical outputs on ~1,000 instances.
"""
from __future__ import annotations

import heapq

import numba
import numpy as np

__all__ = ["kernel", "prepare"]


@numba.njit(cache=True, nogil=True)
def _at(g, t, pos, vstart, latest, best, eps):
    p = pos[g]
    end = vstart[g + 1]
    while p < end and latest[p] + eps < t:
        p += 1
    pos[g] = p
    return best[p] if p < end else -1

@numba.njit(cache=True, nogil=True)
def _find(keys, n, mask):
    for i in range(n):
        if keys[i] == mask:
            return i
    return -1

@numba.njit(cache=True, nogil=True)
def _grow_nodes(nj, nt, npar, nn, need):
    """The path-node arrays (job int64, start float64, parent int64) with room for ``need`` nodes (at least twice
    their capacity), the first ``nn`` kept."""
    cap = max(need, 2 * nj.shape[0])
    a1, a2, a3 = np.empty(cap, np.int64), np.empty(cap, np.float64), np.empty(cap, np.int64)
    a1[:nn], a2[:nn], a3[:nn] = nj[:nn], nt[:nn], npar[:nn]
    return a1, a2, a3


@numba.njit(cache=True, nogil=True)
def _forget(t, active, na, vstart, latest, bit, sk, sg, sp, sn, pk, pg, pp, eps):
    """Forget the used jobs that can no longer start at ``t``: keep the active groups whose latest start is still
    reachable, recompute the earliest such expiry and the mask of live bits, and merge the stored labels whose keys
    become equal under that mask (the better gain wins; first-insertion order kept). The merged store is written
    back into ``sk``/``sg``/``sp``. Returns ``(na, expiry, alive, sn, pk, pg, pp)`` (the scratch arrays may have
    grown)."""
    m = 0
    for a in range(na):
        g = active[a]
        if latest[vstart[g + 1] - 1] + eps >= t:
            active[m] = g
            m += 1
    na = m
    expiry = np.inf
    alive = np.uint64(0)
    for a in range(na):
        g = active[a]
        if latest[vstart[g + 1] - 1] < expiry:
            expiry = latest[vstart[g + 1] - 1]
        alive |= bit[g]
    if sn > pk.shape[0]:
        pk, pg, pp = np.empty(2 * sn, np.uint64), np.empty(2 * sn, np.float64), np.empty(2 * sn, np.int64)
    pn = 0
    for i in range(sn):
        k2 = sk[i] & alive
        f = _find(pk, pn, k2)
        if f < 0:
            pk[pn], pg[pn], pp[pn] = k2, sg[i], sp[i]
            pn += 1
        elif pg[f] < sg[i]:
            pg[f], pp[f] = sg[i], sp[i]
    for i in range(pn):
        sk[i], sg[i], sp[i] = pk[i], pg[i], pp[i]
    return na, expiry, alive, pn, pk, pg, pp


@numba.njit(cache=True, nogil=True)
def _settle(heap, t, alive, sk, sg, sp, sn, fresh, nf, best_gain, best_node, eps):
    """Pop every label that becomes free at ``t`` and store it unless a stored label with a subset key has at least
    its gain; the stored labels it dominates are dropped. ``fresh[:nf]`` collects the masks stored at ``t`` in
    first-insertion order. Stops early, before popping, when the store or ``fresh`` is full (the caller grows them
    and calls again). Returns ``(sn, nf, best_gain, best_node, full)``."""
    while len(heap) > 0 and heap[0][0] == t:
        if sn == sk.shape[0] or nf == fresh.shape[0]:
            return sn, nf, best_gain, best_node, True
        item = heapq.heappop(heap)
        mask = item[2] & alive
        g = item[3]
        lim = g - eps
        dom = False
        for i in range(sn):
            if sk[i] & mask == sk[i] and sg[i] >= lim:
                dom = True
                break
        if dom:
            continue
        hi = g + eps
        m = 0
        for i in range(sn):
            if sk[i] & mask == mask and sg[i] <= hi:
                continue
            sk[m], sg[m], sp[m] = sk[i], sg[i], sp[i]
            m += 1
        sn = m
        sk[sn], sg[sn], sp[sn] = mask, g, item[4]
        sn += 1
        if _find(fresh, nf, mask) < 0:
            fresh[nf] = mask
            nf += 1
        if g > best_gain + eps:
            best_gain, best_node = g, item[4]
    return sn, nf, best_gain, best_node, False


@numba.njit(cache=True, nogil=True)
def _grow_store(sk, sg, sp, sn, fresh, nf):
    """The store's arrays (key uint64, gain float64, node int64) and ``fresh`` at twice their capacity, their first
    ``sn`` / ``nf`` entries kept."""
    k2, g2, p2 = np.empty(2 * sk.shape[0], np.uint64), np.empty(2 * sk.shape[0], np.float64), \
        np.empty(2 * sk.shape[0], np.int64)
    k2[:sn], g2[:sn], p2[:sn] = sk[:sn], sg[:sn], sp[:sn]
    f2 = np.empty(2 * fresh.shape[0], np.uint64)
    f2[:nf] = fresh[:nf]
    return k2, g2, p2, f2


@numba.njit(cache=True, nogil=True)
def _candidates(groups, n, t, pos, vstart, latest, best, bit, proc, gains, cb, ce, cg, cj, eps):
    """The jobs that can start at ``t``, one per group of ``groups[:n]`` that still has a variant: its bit, end
    time, gain and job index into ``cb``/``ce``/``cg``/``cj``. Returns how many."""
    nc = 0
    for a in range(n):
        g = groups[a]
        j = _at(g, t, pos, vstart, latest, best, eps)
        if j >= 0:
            cb[nc], ce[nc], cg[nc], cj[nc] = bit[g], t + proc[g], gains[j], j
            nc += 1
    return nc


@numba.njit(cache=True, nogil=True)
def _extend(heap, seq, nj, nt, npar, nn, t, mask, g, parent, cb, ce, cg, cj, nc):
    """Push onto ``heap`` the label ``(mask, gain g)`` extended at ``t`` by each candidate job whose bit is not in
    ``mask``, recording each step as a path node (job, start ``t``, ``parent``); the node arrays must have room for
    ``nc`` more. Returns ``(seq, nn)``."""
    for c in range(nc):
        if mask & cb[c] == np.uint64(0):
            nj[nn], nt[nn], npar[nn] = cj[c], t, parent
            seq += 1
            heapq.heappush(heap, (ce[c], np.int64(seq), mask | cb[c], g + cg[c], np.int64(nn)))
            nn += 1
    return seq, nn


@numba.njit(cache=True, nogil=True)
def kernel(rel, proc, bit, vstart, latest, best, gains, eps):
    """The label-setting DP over the groups sorted by release (see :func:`aerodaas.schedulers.single_machine_jit.
    solve` for the arrays): at each event time it forgets jobs that can no longer start (:func:`_forget`),
    releases the groups of that time, stores the labels that become free (:func:`_settle`) and extends the new
    labels by every startable job, and the earlier labels by the newly released jobs (:func:`_extend`). Returns
    ``(best gain, node job, node start, node parent, best node)``."""
    G = rel.shape[0]
    zero = np.uint64(0)
    pos = vstart[:-1].copy()
    nj, nt, npar = np.empty(64, np.int64), np.empty(64, np.float64), np.empty(64, np.int64)  # path nodes
    nn, seq, sn, na, gi = 0, 0, 0, 0, 0
    heap = [(rel[0], np.int64(seq), zero, 0.0, np.int64(-1))]
    # the store: keys, gains, path nodes in insertion order
    sk, sg, sp = np.empty(16, np.uint64), np.empty(16, np.float64), np.empty(16, np.int64)
    active, newly = np.empty(G, np.int64), np.empty(G, np.int64)
    cb, ce = np.empty(G, np.uint64), np.empty(G, np.float64)   # candidates: bit, end, gain, job
    cg, cj = np.empty(G, np.float64), np.empty(G, np.int64)
    best_gain, best_node = 0.0, -1
    # scratch, reused: the store before a release (its labels expand to the new jobs), the pruned store, the masks
    # inserted at the current time (first-insertion order)
    ok, og, op = np.empty(16, np.uint64), np.empty(16, np.float64), np.empty(16, np.int64)
    pk, pg, pp = np.empty(16, np.uint64), np.empty(16, np.float64), np.empty(16, np.int64)
    fresh = np.empty(16, np.uint64)
    alive = zero
    expiry = np.inf
    while len(heap) > 0 or gi < G:
        t = heap[0][0] if len(heap) > 0 else np.inf
        if gi < G and rel[gi] < t:
            t = rel[gi]
        if t > expiry + eps:
            na, expiry, alive, sn, pk, pg, pp = _forget(t, active, na, vstart, latest, bit, sk, sg, sp, sn, pk, pg,
                                                        pp, eps)
        nw = 0
        while gi < G and rel[gi] == t:    # release the groups of time t
            if _at(gi, t, pos, vstart, latest, best, eps) >= 0:
                newly[nw] = gi
                nw += 1
                alive |= bit[gi]
                if latest[vstart[gi + 1] - 1] < expiry:
                    expiry = latest[vstart[gi + 1] - 1]
            gi += 1
        on = sn if nw > 0 else 0
        if on > ok.shape[0]:
            ok, og, op = np.empty(2 * on, np.uint64), np.empty(2 * on, np.float64), np.empty(2 * on, np.int64)
        for i in range(on):
            ok[i], og[i], op[i] = sk[i], sg[i], sp[i]
        for a in range(nw):
            active[na] = newly[a]
            na += 1
        nf, full = 0, True
        while full:
            sn, nf, best_gain, best_node, full = _settle(heap, t, alive, sk, sg, sp, sn, fresh, nf, best_gain,
                                                         best_node, eps)
            if full:
                sk, sg, sp, fresh = _grow_store(sk, sg, sp, sn, fresh, nf)
        if nf > 0:                        # the labels stored at t, extended by every job that can start at t
            nc = _candidates(active, na, t, pos, vstart, latest, best, bit, proc, gains, cb, ce, cg, cj, eps)
            for q in range(nf):
                i = _find(sk, sn, fresh[q])
                if i >= 0:
                    if nn + nc > nj.shape[0]:
                        nj, nt, npar = _grow_nodes(nj, nt, npar, nn, nn + nc)
                    seq, nn = _extend(heap, seq, nj, nt, npar, nn, t, fresh[q], sg[i], sp[i], cb, ce, cg, cj, nc)
        if nw > 0:                        # the labels stored before t, still unchanged, by the jobs released at t
            nc = _candidates(newly, nw, t, pos, vstart, latest, best, bit, proc, gains, cb, ce, cg, cj, eps)
            for q in range(on):
                mask = ok[q]
                i = _find(sk, sn, mask)
                if i < 0 or sg[i] != og[q] or _find(fresh, nf, mask) >= 0:
                    continue
                if nn + nc > nj.shape[0]:
                    nj, nt, npar = _grow_nodes(nj, nt, npar, nn, nn + nc)
                seq, nn = _extend(heap, seq, nj, nt, npar, nn, t, mask, og[q], op[q], cb, ce, cg, cj, nc)
    return best_gain, nj[:nn], nt[:nn], npar[:nn], best_node


@numba.njit(cache=True, nogil=True)
def _qualifying(r, d, p, w, gid, ngroups, free_at, eps):
    """Which jobs qualify (``w > 0`` and ``max(r, free_at) + p <= d + eps``), each group's first qualifying job
    (``J`` if none) and its number of qualifying jobs. Returns ``(same, ok, first, count)``; ``same`` is False when
    two qualifying jobs of one group differ in release or processing time."""
    J = r.shape[0]
    first = np.full(ngroups, J, np.int64)
    count = np.zeros(ngroups, np.int64)
    ok = np.zeros(J, np.bool_)
    for j in range(J):
        if w[j] > 0 and max(r[j], free_at) + p[j] <= d[j] + eps:
            ok[j] = True
            g = gid[j]
            if first[g] == J:
                first[g] = j
            elif r[j] != r[first[g]] or p[j] != p[first[g]]:
                return False, ok, first, count
            count[g] += 1
    return True, ok, first, count


@numba.njit(cache=True, nogil=True)
def _group_order(r, first, ngroups, free_at):
    """The groups that have a qualifying job, in the order of their first one, then stably sorted by release."""
    J = r.shape[0]
    present = np.empty(ngroups, np.int64)
    G = 0
    for g in range(ngroups):
        if first[g] < J:
            present[G] = g
            G += 1
    present = present[:G]
    present = present[np.argsort(first[present], kind="mergesort")]
    grel = np.empty(G, np.float64)
    for i in range(G):
        grel[i] = max(r[first[present[i]]], free_at)
    return present[np.argsort(grel, kind="mergesort")]


@numba.njit(cache=True, nogil=True)
def _members(gid, ok, count, ngroups):
    """The qualifying jobs of each group, in job order: ``members[off[g]:off[g + 1]]``. Returns ``(off, members)``."""
    off = np.zeros(ngroups + 1, np.int64)
    for g in range(ngroups):
        off[g + 1] = off[g] + count[g]
    fill = off[:-1].copy()
    members = np.empty(off[ngroups], np.int64)
    for j in range(gid.shape[0]):
        if ok[j]:
            g = gid[j]
            members[fill[g]] = j
            fill[g] += 1
    return off, members


@numba.njit(cache=True, nogil=True)
def _variants(js, d, w, pg, latest, best, v):
    """Write one group's variants at ``latest[v:]``/``best[v:]``: the jobs ``js`` (ascending) by latest start
    ``d - pg`` (ties: job order), each with the suffix-best job by gain (a later variant only if strictly better)."""
    lat = np.empty(js.shape[0], np.float64)
    for k in range(js.shape[0]):
        lat[k] = d[js[k]] - pg
    srt = np.argsort(lat, kind="mergesort")
    for k in range(js.shape[0]):
        latest[v + k] = lat[srt[k]]
        best[v + k] = js[srt[k]]
    for k in range(js.shape[0] - 2, -1, -1):
        if w[best[v + k + 1]] > w[best[v + k]]:
            best[v + k] = best[v + k + 1]


@numba.njit(cache=True, nogil=True)
def prepare(r, d, p, w, gid, ngroups, free_at, eps, max_groups):
    """The kernel's arrays from flat job arrays, exactly as ``single_machine._solve_compiled`` builds them from its
    job tuples: jobs ``j`` (release ``r``, deadline ``d``, processing ``p``, gain ``w``, group ``gid`` in
    ``[0, ngroups)``) with ``w > 0`` that fit ``max(r, free_at) + p <= d + eps``; groups in the order of their first
    such job, stably sorted by release; a group's variants by (latest start, job index) with the suffix-best job;
    bits reused over time as ``single_machine._bits``. Returns ``(code, rel, proc, bit, vstart, latest, best)``:
    code 0 ok, 1 the jobs of a group differ in release or processing time, 2 more than ``max_groups`` bits."""
    same, ok, first, count = _qualifying(r, d, p, w, gid, ngroups, free_at, eps)
    if not same:
        return 1, np.empty(0), np.empty(0), np.empty(0, np.uint64), np.zeros(1, np.int64), np.empty(0), \
            np.empty(0, np.int64)
    order = _group_order(r, first, ngroups, free_at)
    G = order.shape[0]
    off, members = _members(gid, ok, count, ngroups)
    rel = np.empty(G, np.float64)
    proc = np.empty(G, np.float64)
    bit = np.empty(G, np.uint64)
    vstart = np.empty(G + 1, np.int64)
    latest = np.empty(off[ngroups], np.float64)
    best = np.empty(off[ngroups], np.int64)
    maxproc = -np.inf
    for i in range(G):
        maxproc = max(maxproc, p[first[order[i]]])
    free_after = np.empty(max_groups, np.float64)   # a bit is reused once its group can no longer be used
    nbits = 0
    v = 0
    for i in range(G):
        g = order[i]
        rel[i] = max(r[first[g]], free_at)
        proc[i] = p[first[g]]
        js = members[off[g]:off[g + 1]]
        vstart[i] = v
        _variants(js, d, w, proc[i], latest, best, v)
        b = -1
        for k in range(nbits):
            if free_after[k] < rel[i]:
                b = k
                break
        if b < 0:
            if nbits == max_groups:
                return 2, rel, proc, bit, vstart, latest, best
            b = nbits
            nbits += 1
        free_after[b] = latest[v + js.shape[0] - 1] + maxproc + 1.0
        bit[i] = np.uint64(1) << np.uint64(b)
        v += js.shape[0]
    vstart[G] = v
    return 0, rel, proc, bit, vstart, latest, best
