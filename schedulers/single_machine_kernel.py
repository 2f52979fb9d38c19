"""The compiled kernel of :mod:`aerodaas.schedulers.single_machine_jit` (imports numba: load it lazily).

Module-level ``njit(cache=True, nogil=True)`` functions: module-level so that numba's on-disk cache is reused across
processes (functions defined in a closure are recompiled in every process); ``nogil`` releases the GIL while a plan is
solved, so the other threads of a dispatcher process (its actor loop, the trace replay) are not held up.
"""
from __future__ import annotations

import heapq

import numba
import numpy as np

__all__ = ["kernel"]


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
