"""The re-fit's normal equations, assembled in compiled loops (numba) straight from the samples.

The least-squares problem of `refit` (its step 3) has one row per sample: the sample's barycentric
coordinates b on its output face, times the square root of its weight, in the columns of the face's
corners. Its normal equations are N = AᵀA + λI and R = Aᵀ(targets) + λX. Building A as a scipy matrix and
multiplying it out cost a (q,3) CSR matrix, its transpose and two sparse products per round, a large part
of a big mesh's re-fit (docs/benchmarks.md, "Measured choices inside a run"). Here the same sums are made
directly: every entry of N and R is a sum over the samples in increasing order, as scipy's products made
it, so the system is the same bit for bit (the same re-fits as with scipy's products; tests/test_refit.py
compares the sums with numpy's in sample order), and it depends on no library's kernels.
The loops release the GIL: a batch's re-fits run side by side on threads (`stages.refit_all`).

* `regions`: each sample's barycentric coordinates on its face (Ericson's regions), in numpy's arithmetic
  (`fit_rules.closest_barycentric` made them with einsum and np.select: the same bits, without their (q,3)
  temporaries);
* `layout`: N's sparsity (a row per free output vertex, the columns of the free vertices it shares a face
  with and its own, ascending) and where each face's corner pairs sit in it;
* `accumulate`: one block of samples' contributions to N and R, in sample order;
* `finish`: N's entries that summed to exactly zero dropped (as scipy's product drops them), λ added on the
  diagonal: the CSR arrays.
"""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit

_HUGE = 1.7976931348623157e308  # np.nan_to_num's stand-in for an infinity
SHORT_ROW = 48  # rows of N's layout up to this long are sorted by insertion, longer ones by numpy's sort


@njit(cache=True, nogil=True, inline="always")
def _finite(t):
    """np.nan_to_num of one value: NaN 0, ±inf ±the largest float."""
    if t != t:
        return 0.0
    if t == np.inf:
        return _HUGE
    return -_HUGE if t == -np.inf else t


@njit(cache=True, nogil=True, error_model="numpy")
def regions(P, X, G, f, out):
    """out[s] = the barycentric coordinates of the point of face f[s] of (X, G) closest to P[s] (Ericson,
    Real-Time Collision Detection 5.1.5: the first of the vertex, edge and interior regions that holds).
    Not for slivers (their regions lose all precision: `fit_rules.closest_barycentric` measures them by their
    edges). numpy's arithmetic, operation for operation: einsum's dot products sum (x0·y0 + x2·y2) + x1·y1,
    the edge parameters go through np.nan_to_num, the interior's through den = (va + vb) + vc (1 where 0)."""
    for s in range(len(f)):
        g = f[s]
        i0, i1, i2 = G[g, 0], G[g, 1], G[g, 2]
        ax, ay, az = X[i0, 0], X[i0, 1], X[i0, 2]
        bx, by, bz = X[i1, 0], X[i1, 1], X[i1, 2]
        cx, cy, cz = X[i2, 0], X[i2, 1], X[i2, 2]
        abx, aby, abz = bx - ax, by - ay, bz - az
        acx, acy, acz = cx - ax, cy - ay, cz - az
        px, py, pz = P[s, 0], P[s, 1], P[s, 2]
        pax, pay, paz = px - ax, py - ay, pz - az
        pbx, pby, pbz = px - bx, py - by, pz - bz
        pcx, pcy, pcz = px - cx, py - cy, pz - cz
        d1 = (abx * pax + abz * paz) + aby * pay
        d2 = (acx * pax + acz * paz) + acy * pay
        d3 = (abx * pbx + abz * pbz) + aby * pby
        d4 = (acx * pbx + acz * pbz) + acy * pby
        d5 = (abx * pcx + abz * pcz) + aby * pcy
        d6 = (acx * pcx + acz * pcz) + acy * pcy
        va = d3 * d6 - d5 * d4
        vb = d5 * d2 - d1 * d6
        vc = d1 * d4 - d3 * d2
        if d1 <= 0 and d2 <= 0:
            o0, o1, o2 = 1.0, 0.0, 0.0
        elif d3 >= 0 and d4 <= d3:
            o0, o1, o2 = 0.0, 1.0, 0.0
        elif d6 >= 0 and d5 <= d6:
            o0, o1, o2 = 0.0, 0.0, 1.0
        elif vc <= 0 and d1 >= 0 and d3 <= 0:
            t = _finite(d1 / (d1 - d3))
            o0, o1, o2 = 1 - t, t, 0.0
        elif vb <= 0 and d2 >= 0 and d6 <= 0:
            t = _finite(d2 / (d2 - d6))
            o0, o1, o2 = 1 - t, 0.0, t
        elif va <= 0 and d4 >= d3 and d5 >= d6:
            t = _finite((d4 - d3) / ((d4 - d3) + (d5 - d6)))
            o0, o1, o2 = 0.0, 1 - t, t
        else:
            den = (va + vb) + vc
            if den == 0:
                den = 1.0
            v, w = vb / den, vc / den
            o0, o1, o2 = (1 - v) - w, v, w
        out[s, 0], out[s, 1], out[s, 2] = o0, o1, o2


@njit(cache=True, nogil=True)
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
    for r in range(nfree):  # each row's columns sorted in place, repeats removed
        s0, s1 = start[r], start[r + 1]
        if s1 - s0 > SHORT_ROW:  # a vertex of high valence (a fan's hub): no quadratic sort
            raw[s0:s1].sort()
        for t in range(s0 + 1, s1):  # insertion: a no-op on a sorted row, quick on a short one
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
    if indptr[nfree] >= 2**31:
        raise ValueError("re-fit: the output has too many vertices for the solver's index type")
    indices = np.empty(indptr[-1], np.int64)
    for r in range(nfree):
        for t in range(indptr[r + 1] - indptr[r]):
            indices[indptr[r] + t] = raw[start[r] + t]
    pos = np.full((j, 3, 3), -1, np.int32)  # N's entries, fewer than 2**31 (checked above)
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


@njit(cache=True, nogil=True, inline="always")
def _ascending(a, b, c):
    """The positions 0, 1, 2 of three distinct numbers a, b, c in ascending order of the numbers."""
    if a < b:
        return (0, 1, 2) if b < c else ((0, 2, 1) if a < c else (2, 0, 1))
    return (1, 0, 2) if a < c else ((1, 2, 0) if b < c else (2, 1, 0))


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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
