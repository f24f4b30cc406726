"""The re-fit's normal equations, assembled in compiled loops (numba) straight from the samples.

The least-squares problem of `refit` (its step 3) has one row per sample: the sample's barycentric
coordinates b on its output face, times the square root of its weight, in the columns of the face's
corners. Its normal equations are N = AᵀA + λI and R = Aᵀ(targets) + λX. Building A as a scipy matrix and
multiplying it out cost a (q,3) CSR matrix, its transpose and two sparse products per round (0.6 s of a
1.4 M-face run, and the largest arrays of the re-fit). Here the same sums are made directly: every entry
of N and R is a sum over the samples in increasing order, as scipy's products make it, so the system is
the same bit for bit (tests/test_refit.py compares them), and it does not depend on a library's kernels.

* `layout`: N's sparsity (a row per free output vertex, the columns of the free vertices it shares a face
  with and its own, ascending) and where each face's corner pairs sit in it;
* `accumulate`: one block of samples' contributions to N and R, in sample order;
* `finish`: N's entries that summed to exactly zero dropped (as scipy's product drops them), λ added on the
  diagonal: the CSR arrays.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def layout(G, col, nfree):
    """(indptr (nfree+1,), indices, pos (j,3,3)): N's rows (free vertices: ``col`` maps an output vertex to
    its row, -1 for a fixed one) with the sorted columns of itself and of the free vertices it shares a face
    with; pos[g, x, y]: the entry of corners x, y of face g (-1 where either is fixed)."""
    j = len(G)
    deg = np.zeros(nfree + 1, np.int64)  # at most: each face lists its free corners in each free corner's row
    for g in range(j):
        k = 0
        for x in range(3):
            if col[G[g, x]] >= 0:
                k += 1
        for x in range(3):
            r = col[G[g, x]]
            if r >= 0:
                deg[r + 1] += k
    deg[1:] += 1  # each row's own column, whether or not the vertex is on a face
    start = np.cumsum(deg)
    raw = np.empty(start[-1], np.int64)
    fill = start[:-1].copy()
    for r in range(nfree):
        raw[fill[r]] = r
        fill[r] += 1
    for g in range(j):
        for x in range(3):
            r = col[G[g, x]]
            if r < 0:
                continue
            for y in range(3):
                c = col[G[g, y]]
                if c >= 0:
                    raw[fill[r]] = c
                    fill[r] += 1
    indptr = np.zeros(nfree + 1, np.int64)
    for r in range(nfree):  # each row's columns sorted (a few dozen: insertion), repeats removed, in place
        s0, s1 = start[r], start[r + 1]
        for t in range(s0 + 1, s1):
            c, u = raw[t], t
            while u > s0 and raw[u - 1] > c:
                raw[u] = raw[u - 1]
                u -= 1
            raw[u] = c
        k = 0
        for t in range(s0, s1):
            if t == s0 or raw[t] != raw[t - 1]:
                raw[s0 + k] = raw[t]
                k += 1
        indptr[r + 1] = indptr[r] + k
    indices = np.empty(indptr[-1], np.int64)
    for r in range(nfree):
        for t in range(indptr[r + 1] - indptr[r]):
            indices[indptr[r] + t] = raw[start[r] + t]
    pos = np.full((j, 3, 3), -1, np.int64)
    for g in range(j):
        for x in range(3):
            r = col[G[g, x]]
            if r < 0:
                continue
            for y in range(3):
                c = col[G[g, y]]
                if c < 0:
                    continue
                lo, hi = indptr[r], indptr[r + 1]  # a row holds a few columns: a binary search
                while lo < hi:
                    mid = (lo + hi) // 2
                    if indices[mid] < c:
                        lo = mid + 1
                    else:
                        hi = mid
                pos[g, x, y] = lo
    return indptr, indices, pos


@njit(cache=True, inline="always")
def _ascending(a, b, c):
    """The positions 0, 1, 2 of three distinct numbers a, b, c in ascending order of the numbers."""
    if a < b:
        return (0, 1, 2) if b < c else ((0, 2, 1) if a < c else (2, 0, 1))
    return (1, 0, 2) if a < c else ((1, 2, 0) if b < c else (2, 1, 0))


@njit(cache=True)
def accumulate(Bw, f, P, sw, G, col, X, pos, data, rhs):
    """Add the rows of one block of samples, in their order: Bw (q,3) each sample's barycentric coordinates
    on its face f (q,) times its weight's square root sw (q,), P (q,3) its point. N's entries (``data``, at
    ``pos``) gain b_x·b_y; R (``rhs``, a row per free vertex) gains b_x·t, t the sample's target: its point
    times sw, less (where a corner is fixed) the fixed corners' b·X summed in the order of their vertex
    numbers (the columns' order in scipy's rows)."""
    t = np.empty(3)
    for s in range(len(f)):
        g = f[s]
        for d in range(3):
            t[d] = P[s, d] * sw[s]
        c0, c1, c2 = G[g, 0], G[g, 1], G[g, 2]
        if col[c0] < 0 or col[c1] < 0 or col[c2] < 0:  # the fixed corners' share, in ascending vertex order
            sh = np.zeros(3)
            order = _ascending(c0, c1, c2)
            for i in range(3):
                x = order[i]
                v = G[g, x]
                if col[v] < 0:
                    for d in range(3):
                        sh[d] += Bw[s, x] * X[v, d]
            for d in range(3):
                t[d] = t[d] - sh[d]
        for x in range(3):
            r = col[G[g, x]]
            if r < 0:
                continue
            for y in range(3):
                k = pos[g, x, y]
                if k >= 0:
                    data[k] += Bw[s, x] * Bw[s, y]
            for d in range(3):
                rhs[r, d] += Bw[s, x] * t[d]


@njit(cache=True)
def finish(indptr, indices, data, lam):
    """N's CSR arrays: the off-diagonal entries that summed to exactly zero dropped, λ added to the
    diagonal (every row keeps its diagonal)."""
    n = len(indptr) - 1
    ip = np.zeros(n + 1, np.int64)
    ix = np.empty(len(indices), np.int64)
    dx = np.empty(len(indices))
    k = 0
    for r in range(n):
        for t in range(indptr[r], indptr[r + 1]):
            c = indices[t]
            if c == r:
                ix[k], dx[k] = c, data[t] + lam
                k += 1
            elif data[t] != 0.0:
                ix[k], dx[k] = c, data[t]
                k += 1
        ip[r + 1] = k
    return ip, ix[:k].copy(), dx[:k].copy()
