"""The parallel round's contraction as compiled loops (numba): the accepted pairs' faces (dead ones out, b's
corners to a, new runs in the pool) and pairs (merged, moved, counted, compacted), with the degrees after and
which pairs are stale; and the rejections cleared around a round.

They make exactly the choices of the numpy code they replace (`FaceLists.contract_touched` and the edge update
of `parallel.pairs.EdgeUpdate`, which runs `contract_edges`' steps on two threads); tests/test_round_loops.py
compares them on random meshes.
"""
from __future__ import annotations

import numpy as np

from ..._mesh.compiled import njit


@njit(cache=True)
def contract_faces(a, b, F, alive, cnt, off, pool, end):
    """`FaceLists.contract_touched` for vertex-disjoint pairs (a, b) two edges apart: the faces holding
    both endpoints die, b's other faces take a, and a's run (its surviving faces, then b's) is written at
    the pool's end (which must have room for cnt[a] + cnt[b] more entries). Returns the new end and the
    faces that died, pair by pair."""
    dead = np.empty(2 * len(a), np.int64)
    nd = 0
    for s in range(len(a)):
        u, v = a[s], b[s]
        for i in range(off[v], off[v] + cnt[v]):
            f = pool[i]
            if alive[f] and (F[f, 0] == u or F[f, 1] == u or F[f, 2] == u):
                alive[f] = False
                if nd == len(dead):
                    dead = np.concatenate((dead, np.empty(len(dead), np.int64)))
                dead[nd] = f
                nd += 1
        start = end
        for i in range(off[u], off[u] + cnt[u]):
            f = pool[i]
            if alive[f]:
                pool[end] = f
                end += 1
        for i in range(off[v], off[v] + cnt[v]):
            f = pool[i]
            if alive[f]:
                for c in range(3):
                    if F[f, c] == v:
                        F[f, c] = u
                pool[end] = f
                end += 1
        off[u] = start
        cnt[u] = end - start
        cnt[v] = 0
    return end, dead[:nd].copy()


@njit(cache=True, nogil=True)
def contract_edges(E, ecount, deg, a, b, apex, label):
    """`topology.contract_edges` for vertex-disjoint pairs (a, b) that passed the link test, with their
    apexes (S,2) (-1 where a pair has one face): (b, c) merges into (a, c) for an apex c (which loses the
    vanished face and gains (b, c)'s others), b's other pairs move to a, the contracted pair goes.
    ``label`` (n,) int32 scratch, all -1 (left so). Returns (E', ecount', keep, degree', stale'): the
    pairs that stay in their order, which old rows they continue, the degrees after, and which of them
    are at a kept vertex (their cost is stale).

    In five steps, which `parallel.EdgeUpdate` also runs with the two passes over every pair shared between
    two threads: the endpoints labelled; the rows at an endpoint listed with their labels (`list_rows`);
    what becomes of each listed row (`listed_rows`); every row that stays copied (`copy_rows`) and the
    listed ones rewritten (`rewrite_rows`)."""
    P = len(E)
    label_pairs(a, b, label)
    rows, lab, far, nu, nv, cnt = listing(E, ecount, P)
    nr = list_rows(E, ecount, label, 0, P, rows, lab, far, nu, nv, cnt)
    rows, nu, nv, cnt = rows[:nr], nu[:nr], nv[:nr], cnt[:nr]
    keep, d2, m = listed_rows(E, deg, a, b, apex, label, rows, lab[:nr], far[:nr], nu, nv, cnt)
    E3 = np.empty((m, 2), E.dtype)
    c3 = np.empty(m, ecount.dtype)
    copy_rows(E, ecount, keep, 0, P, E3, c3, 0)
    s3 = rewrite_rows(rows, keep, nu, nv, cnt, E3, c3)
    return E3, c3, keep, d2, s3


@njit(cache=True, nogil=True)
def label_pairs(a, b, label):
    """label[a[s]] = s and label[b[s]] = S + s (``label`` all -1 before; `listed_rows` undoes it)."""
    S = len(a)
    for s in range(S):
        label[a[s]] = s
        label[b[s]] = S + s


@njit(cache=True, nogil=True)
def listing(E, ecount, P):
    """Room for `list_rows` of P rows: (rows int64, lab int32, far, nu, nv in E's dtype, cnt in ecount's)."""
    return (np.empty(P, np.int64), np.empty(P, np.int32), np.empty(P, E.dtype), np.empty(P, E.dtype),
            np.empty(P, E.dtype), np.empty(P, ecount.dtype))


@njit(cache=True, nogil=True)
def list_rows(E, ecount, label, lo, hi, rows, lab, far, nu, nv, cnt):
    """The rows of E in [lo, hi) with a labelled endpoint, ascending, written from rows[0], with what
    `listed_rows` reads of each: the endpoint's label (lab; -1 for the contracted pair itself, both of
    whose endpoints are labelled), the row's other vertex (far) and the row (nu, nv, cnt). Every row is
    written, then the count moves past it or not (no branch: the rows at an endpoint follow no pattern), so
    each array must have room for hi - lo entries. Returns how many."""
    nr = 0
    for i in range(lo, hi):
        u, v = E[i, 0], E[i, 1]
        l0, l1 = label[u], label[v]
        rows[nr], nu[nr], nv[nr], cnt[nr] = i, u, v, ecount[i]
        at0 = l0 >= 0
        lab[nr] = -1 if (at0 and l1 >= 0) else (l0 if at0 else l1)
        far[nr] = v if at0 else u
        nr += at0 | (l1 >= 0)
    return nr


@njit(cache=True, nogil=True)
def listed_rows(E, deg, a, b, apex, label, rows, lab, far, nu, nv, cnt):
    """What becomes of the listed rows (`list_rows`' arrays, cut to the listed ones): their new (u, v, face
    count) written over nu, nv, cnt, which rows stay (keep (P,) bool: all but dropped listed ones), the
    degrees after, and how many rows stay. Unlabels the endpoints."""
    S = len(a)
    P = len(E)
    nr = len(rows)
    keep = np.ones(P, np.bool_)
    delta = np.zeros((S, 2), np.int64)
    m = P  # the rows that stay
    for t in range(nr):  # pairs at a b: merge into (a, apex) or move to a
        if lab[t] < 0:  # the contracted pair itself
            keep[rows[t]] = False
            m -= 1
            continue
        if lab[t] < S:
            continue
        s, c = lab[t] - S, far[t]
        if c == apex[s, 0] or c == apex[s, 1]:
            delta[s, 0 if c == apex[s, 0] else 1] = cnt[t] - 2
            keep[rows[t]] = False
            m -= 1
        else:
            u = a[s]
            nu[t], nv[t] = min(u, c), max(u, c)
    for t in range(nr):  # pairs (a, apex): their new face counts
        s, c = lab[t], far[t]
        if s < 0 or s >= S:
            continue
        if c == apex[s, 0] or c == apex[s, 1]:
            cnt[t] += delta[s, 0 if c == apex[s, 0] else 1]
            if cnt[t] <= 0:
                keep[rows[t]] = False
                m -= 1
    d2 = deg.copy()
    for s in range(S):
        k = 0
        for j in range(2):
            if apex[s, j] >= 0:
                k += 1
                d2[apex[s, j]] -= 1
        d2[a[s]] += deg[b[s]] - 2 - k
        d2[b[s]] = 0
        label[a[s]] = -1
        label[b[s]] = -1
    return keep, d2, m


@njit(cache=True, nogil=True)
def copy_rows(E, ecount, keep, lo, hi, E3, c3, k):
    """The kept rows of E and ecount in [lo, hi) copied in order into E3 and c3 from row k (the kept rows
    before lo)."""
    for i in range(lo, hi):
        if keep[i]:  # (a dropped row is rare: a predictable branch)
            E3[k, 0], E3[k, 1], c3[k] = E[i, 0], E[i, 1], ecount[i]
            k += 1


@njit(cache=True, nogil=True)
def rewrite_rows(rows, keep, nu, nv, cnt, E3, c3):
    """The listed rows that stay take their new values, at their row less the rows dropped before; returns
    which rows of E3 are at a kept vertex (stale)."""
    s3 = np.zeros(len(E3), np.bool_)
    gone = 0
    for t in range(len(rows)):
        i = rows[t]
        if keep[i]:
            k = i - gone
            E3[k, 0], E3[k, 1], c3[k], s3[k] = nu[t], nv[t], cnt[t], True
        else:
            gone += 1
    return s3


@njit(cache=True)
def clear_bad(E, bad, touched):
    """Pairs known invalid get another chance where an endpoint is in ``touched`` (the round's rings)."""
    for i in range(len(E)):
        if bad[i] != 0 and (touched[E[i, 0]] or touched[E[i, 1]]):
            bad[i] = 0
