"""The compiled kernel of :mod:`aerodaas.schedulers.single_machine_jit` (imports numba: load it lazily).

Module-level ``njit(cache=True, nogil=True)`` functions: module-level so that numba's on-disk cache is reused across
processes (functions defined in a closure are recompiled in every process); ``nogil`` releases the GIL while a plan is
solved, so the other threads of a dispatcher process (its actor loop, the trace replay) are not held up.
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
def kernel(rel, proc, bit, vstart, latest, best, gains, eps):
    G = rel.shape[0]
    inf = np.inf
    zero = np.uint64(0)
    one = np.uint64(1)
    pos = vstart[:-1].copy()
    cap = 64
    nj = np.empty(cap, np.int64)    # path nodes: job, start, parent
    nt = np.empty(cap, np.float64)
    npar = np.empty(cap, np.int64)
    nn = 0
    seq = 0
    heap = [(rel[0], np.int64(seq), zero, 0.0, np.int64(-1))]
    scap = 16                          # the store: keys, gains, path nodes in insertion order
    sk = np.empty(scap, np.uint64)
    sg = np.empty(scap, np.float64)
    sp = np.empty(scap, np.int64)
    sn = 0
    active = np.empty(G, np.int64)
    na = 0
    newly = np.empty(G, np.int64)
    cb = np.empty(G, np.uint64)        # candidates: bit, end, gain, job
    ce = np.empty(G, np.float64)
    cg = np.empty(G, np.float64)
    cj = np.empty(G, np.int64)
    best_gain = 0.0
    best_node = -1
    # scratch, reused: the store before a release (its labels expand to the new jobs), the pruned store, the masks
    # inserted at the current time (first-insertion order)
    ok, og, op = np.empty(16, np.uint64), np.empty(16, np.float64), np.empty(16, np.int64)
    pk, pg, pp = np.empty(16, np.uint64), np.empty(16, np.float64), np.empty(16, np.int64)
    fresh = np.empty(16, np.uint64)
    gi = 0
    alive = zero
    expiry = inf
    while len(heap) > 0 or gi < G:
        t = heap[0][0] if len(heap) > 0 else inf
        if gi < G and rel[gi] < t:
            t = rel[gi]
        if t > expiry + eps:  # forget used jobs that can no longer start
            m = 0
            for a in range(na):
                g = active[a]
                if latest[vstart[g + 1] - 1] + eps >= t:
                    active[m] = g
                    m += 1
            na = m
            expiry = inf
            alive = zero
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
            sn = pn
        nw = 0
        while gi < G and rel[gi] == t:
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
        nf = 0
        while len(heap) > 0 and heap[0][0] == t:
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
            if sn == scap:
                scap *= 2
                k2_, g2_, p2_ = np.empty(scap, np.uint64), np.empty(scap, np.float64), np.empty(scap, np.int64)
                k2_[:sn], g2_[:sn], p2_[:sn] = sk[:sn], sg[:sn], sp[:sn]
                sk, sg, sp = k2_, g2_, p2_
            sk[sn], sg[sn], sp[sn] = mask, g, item[4]
            sn += 1
            if _find(fresh, nf, mask) < 0:
                if nf == fresh.shape[0]:
                    f2 = np.empty(max(8, 2 * nf), np.uint64)
                    f2[:nf] = fresh[:nf]
                    fresh = f2
                fresh[nf] = mask
                nf += 1
            if g > best_gain + eps:
                best_gain, best_node = g, item[4]
        if nf > 0:
            nc = 0
            for a in range(na):
                g = active[a]
                j = _at(g, t, pos, vstart, latest, best, eps)
                if j >= 0:
                    cb[nc], ce[nc], cg[nc], cj[nc] = bit[g], t + proc[g], gains[j], j
                    nc += 1
            for q in range(nf):
                mask = fresh[q]
                i = _find(sk, sn, mask)
                if i < 0:
                    continue
                g, parent = sg[i], sp[i]
                for c in range(nc):
                    if mask & cb[c] == zero:
                        if nn == cap:
                            cap *= 2
                            a1, a2, a3 = np.empty(cap, np.int64), np.empty(cap, np.float64), np.empty(cap, np.int64)
                            a1[:nn], a2[:nn], a3[:nn] = nj[:nn], nt[:nn], npar[:nn]
                            nj, nt, npar = a1, a2, a3
                        nj[nn], nt[nn], npar[nn] = cj[c], t, parent
                        seq += 1
                        heapq.heappush(heap, (ce[c], np.int64(seq), mask | cb[c], g + cg[c], np.int64(nn)))
                        nn += 1
        if nw > 0:
            nc = 0
            for a in range(nw):
                g = newly[a]
                j = _at(g, t, pos, vstart, latest, best, eps)
                cb[nc], ce[nc], cg[nc], cj[nc] = bit[g], t + proc[g], gains[j], j
                nc += 1
            for q in range(on):
                mask = ok[q]
                i = _find(sk, sn, mask)
                if i < 0 or sg[i] != og[q] or _find(fresh, nf, mask) >= 0:
                    continue
                g, parent = og[q], op[q]
                for c in range(nc):
                    if mask & cb[c] == zero:
                        if nn == cap:
                            cap *= 2
                            a1, a2, a3 = np.empty(cap, np.int64), np.empty(cap, np.float64), np.empty(cap, np.int64)
                            a1[:nn], a2[:nn], a3[:nn] = nj[:nn], nt[:nn], npar[:nn]
                            nj, nt, npar = a1, a2, a3
                        nj[nn], nt[nn], npar[nn] = cj[c], t, parent
                        seq += 1
                        heapq.heappush(heap, (ce[c], np.int64(seq), mask | cb[c], g + cg[c], np.int64(nn)))
                        nn += 1
    return best_gain, nj[:nn], nt[:nn], npar[:nn], best_node


@numba.njit(cache=True, nogil=True)
def prepare(r, d, p, w, gid, ngroups, free_at, eps, max_groups):
    """The kernel's arrays from flat job arrays, exactly as ``single_machine._solve_compiled`` builds them from its
    job tuples: jobs ``j`` (release ``r``, deadline ``d``, processing ``p``, gain ``w``, group ``gid`` in
    ``[0, ngroups)``) with ``w > 0`` that fit ``max(r, free_at) + p <= d + eps``; groups in the order of their first
    such job, stably sorted by release; a group's variants by (latest start, job index) with the suffix-best job;
    bits reused over time as ``single_machine._bits``. Returns ``(code, rel, proc, bit, vstart, latest, best)``:
    code 0 ok, 1 the jobs of a group differ in release or processing time, 2 more than ``max_groups`` bits."""
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
                return 1, np.empty(0), np.empty(0), np.empty(0, np.uint64), np.zeros(1, np.int64), np.empty(0), \
                    np.empty(0, np.int64)
            count[g] += 1
    present = np.empty(ngroups, np.int64)
    G = 0
    for g in range(ngroups):
        if first[g] < J:
            present[G] = g
            G += 1
    present = present[:G]
    # members order (first qualifying job), then a stable sort by release
    present = present[np.argsort(first[present], kind="mergesort")]
    grel = np.empty(G, np.float64)
    for i in range(G):
        grel[i] = max(r[first[present[i]]], free_at)
    order = present[np.argsort(grel, kind="mergesort")]
    # the jobs of each group, in job order
    off = np.zeros(ngroups + 1, np.int64)
    for g in range(ngroups):
        off[g + 1] = off[g] + count[g]
    fill = off[:-1].copy()
    members = np.empty(off[ngroups], np.int64)
    for j in range(J):
        if ok[j]:
            g = gid[j]
            members[fill[g]] = j
            fill[g] += 1
    rel = np.empty(G, np.float64)
    proc = np.empty(G, np.float64)
    bit = np.empty(G, np.uint64)
    vstart = np.empty(G + 1, np.int64)
    latest = np.empty(off[ngroups], np.float64)
    best = np.empty(off[ngroups], np.int64)
    maxproc = -np.inf
    for i in range(G):
        if p[first[order[i]]] > maxproc:
            maxproc = p[first[order[i]]]
    free_after = np.empty(max_groups, np.float64)
    nbits = 0
    v = 0
    for i in range(G):
        g = order[i]
        j0 = first[g]
        pg = p[j0]
        rel[i] = max(r[j0], free_at)
        proc[i] = pg
        js = members[off[g]:off[g + 1]]
        lat = np.empty(js.shape[0], np.float64)
        for k in range(js.shape[0]):
            lat[k] = d[js[k]] - pg
        srt = np.argsort(lat, kind="mergesort")  # ties: job order (js is ascending)
        vstart[i] = v
        for k in range(js.shape[0]):
            latest[v + k] = lat[srt[k]]
            best[v + k] = js[srt[k]]
        for k in range(js.shape[0] - 2, -1, -1):  # suffix argmax of the gain (a later variant only if strictly better)
            if w[best[v + k + 1]] > w[best[v + k]]:
                best[v + k] = best[v + k + 1]
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
