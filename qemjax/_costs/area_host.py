"""The wide-ring solve of ``method="area"`` (`area.solve_host`), compiled (numba).

Rings wider than `area.RING_CAP` are solved on the host in float64. A pair's solve is three bisections of
60 halvings, each halving an evaluation of ΔS or its slope over the pair's whole ring; a vertex of valence
in the hundreds has hundreds of such pairs, all re-priced after every contraction around it. Written as
numpy passes over (pairs, ring, 3) arrays, one set per halving, those evaluations made a small mesh with
such a vertex slower than large meshes without one.

The loops here add in numpy's order, so that the results are the bits those passes gave
(``tests/area_reference.py`` holds them; ``tests/test_area.py`` compares): a face's |v| as
``sqrt((v0·v0 + v1·v1) + v2·v2)`` (`np.linalg.norm` over three entries, left to right) and a ring's sum as
`numpy_sum` (numpy's pairwise summation over a row). They skip only work whose result is known: a
bisection stops once its interval no longer changes (every further halving would repeat the same step),
and a side's root is bisected only where the side has one (elsewhere it weighs +inf in the choice).
"""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit

STEPS = 60  # halvings of each bisection (the float64 interval stops changing before this, most often)


@njit(cache=True)
def _block(v, lo, n):
    """numpy's pairwise sum of v[lo:lo + n] for n ≤ 128: left to right under 8 entries, else eight running
    sums."""
    if n < 8:
        s = 0.0
        for i in range(lo, lo + n):
            s += v[i]
        return s
    r0, r1, r2, r3 = v[lo], v[lo + 1], v[lo + 2], v[lo + 3]
    r4, r5, r6, r7 = v[lo + 4], v[lo + 5], v[lo + 6], v[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += v[lo + i]
        r1 += v[lo + i + 1]
        r2 += v[lo + i + 2]
        r3 += v[lo + i + 3]
        r4 += v[lo + i + 4]
        r5 += v[lo + i + 5]
        r6 += v[lo + i + 6]
        r7 += v[lo + i + 7]
        i += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        s += v[lo + i]
        i += 1
    return s


@njit(cache=True)
def numpy_sum(v, n):
    """``np.sum(v[:n])`` as numpy adds a contiguous row: pairwise summation, a row over 128 entries split in
    two at a multiple of 8, each half summed so, then added. The halves are walked with a stack, not by
    recursion: numba crashes loading a recursive function from its cache."""
    if n <= 128:
        return _block(v, 0, n)
    los = np.empty(64, np.int64)  # the pending rows (start, length); depth ≤ log2(n / 64)
    ns = np.empty(64, np.int64)
    state = np.empty(64, np.int64)  # 0: not split yet, 1: its left half pending, 2: its right half pending
    left = np.empty(64)  # the left half's sum, while the right one is summed
    top = 0
    los[0], ns[0], state[0] = 0, n, 0
    while True:
        m = ns[top]
        if m > 128 and state[top] == 0:
            h = m // 2 - (m // 2) % 8
            state[top] = 1
            los[top + 1], ns[top + 1], state[top + 1] = los[top], h, 0
            top += 1
            continue
        r = _block(v, los[top], m)
        top -= 1
        while top >= 0 and state[top] == 2:  # a right half done: add it to its left half
            r = left[top] + r
            top -= 1
        if top < 0:
            return r
        left[top] = r  # a left half done: sum the right one
        state[top] = 2
        m = ns[top]
        h = m // 2 - (m // 2) % 8
        los[top + 1], ns[top + 1], state[top + 1] = los[top] + h, m - h, 0
        top += 1


@njit(cache=True)
def _cross(p):
    """(p1 − p0) × (p2 − p0) of a face's corners p (3,3), as `np.cross` forms it."""
    a0, a1, a2 = p[1, 0] - p[0, 0], p[1, 1] - p[0, 1], p[1, 2] - p[0, 2]
    b0, b1, b2 = p[2, 0] - p[0, 0], p[2, 1] - p[0, 1], p[2, 2] - p[0, 2]
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _affine_face(p0, p1, u, w, k, j):
    """Row j of pair k's u, w (K,3,R) from the face's corners with the moving ones at pa (p0) and at pb (p1)."""
    u0, u1, u2 = _cross(p0)
    q0, q1, q2 = _cross(p1)
    u[k, 0, j], u[k, 1, j], u[k, 2, j] = u0, u1, u2
    w[k, 0, j], w[k, 1, j], w[k, 2, j] = q0 - u0, q1 - u1, q2 - u2


@njit(cache=True)
def _norm_cross(p):
    """|(p1 − p0) × (p2 − p0)|, twice the face's area, as `np.linalg.norm` adds its entries."""
    e0, e1, e2 = _cross(p)
    return np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)


@njit(cache=True)
def affine(pa, pb, pos, moving, mask):
    """`area.affine_areas` and `area._area` in float64 for K pairs: pa, pb (K,3), their rings' corners pos
    (K,R,3,3) with moving (K,R,3), mask (K,R). Returns u, w (K,3,R) (components first) and the rings'
    areas before (K,)."""
    K, R = mask.shape
    u = np.empty((K, 3, R))
    w = np.empty((K, 3, R))
    before = np.empty(K)
    buf = np.empty(max(R, 1))
    p0 = np.empty((3, 3))
    p1 = np.empty((3, 3))
    for k in range(K):
        for j in range(R):
            for c in range(3):
                for x in range(3):
                    p = pos[k, j, c, x]
                    p0[c, x] = pa[k, x] if moving[k, j, c] else p
                    p1[c, x] = pb[k, x] if moving[k, j, c] else p
            _affine_face(p0, p1, u, w, k, j)
            buf[j] = _norm_cross(pos[k, j]) if mask[k, j] else 0.0
        before[k] = 0.5 * numpy_sum(buf, R)
    return u, w, before


@njit(cache=True)
def affine_rings(P, pairs, corners, mask, rows, cols):
    """`affine` of the pairs ``rows`` (k,) of a batch, on the ring columns ``cols`` (c,) only, with the rings
    given as vertex ids: positions P (n,3), pairs (K,2), corners (K,R,3) (an id past P's end reads its last
    row), mask (K,R). The same values as `affine` of pa, pb = P[pairs[rows]], pos = the corners' positions,
    moving = the corners at either endpoint, without forming those (k,c,3,3) arrays. Returns u, w (k,3,c),
    the areas before (k,) and the mask (k,c) of those rows and columns."""
    k_, c_ = len(rows), len(cols)
    last = P.shape[0] - 1
    u = np.empty((k_, 3, c_))
    w = np.empty((k_, 3, c_))
    before = np.empty(k_)
    sub = np.empty((k_, c_), np.bool_)
    buf = np.empty(max(c_, 1))
    p = np.empty((3, 3))
    p0 = np.empty((3, 3))
    p1 = np.empty((3, 3))
    for k in range(k_):
        r = rows[k]
        a, b = pairs[r, 0], pairs[r, 1]
        for j in range(c_):
            col = cols[j]
            for c in range(3):
                v = corners[r, col, c]
                mv = v == a or v == b
                v = min(v, last)
                for x in range(3):
                    p[c, x] = P[v, x]
                    p0[c, x] = P[a, x] if mv else p[c, x]
                    p1[c, x] = P[b, x] if mv else p[c, x]
            _affine_face(p0, p1, u, w, k, j)
            sub[k, j] = mask[r, col]
            buf[j] = _norm_cross(p) if sub[k, j] else 0.0
        before[k] = 0.5 * numpy_sum(buf, c_)
    return u, w, before, sub


@njit(cache=True)
def _delta(u, w, mask, before, k, s, buf):
    """ΔS(s) of pair k: before − ½ Σ_f |u_f + s·w_f| over its live faces."""
    R = mask.shape[1]
    for j in range(R):  # no branches: the loop runs on vector registers
        v0 = u[k, 0, j] + s * w[k, 0, j]
        v1 = u[k, 1, j] + s * w[k, 1, j]
        v2 = u[k, 2, j] + s * w[k, 2, j]
        n = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        buf[j] = n if mask[k, j] else 0.0
    return before[k] - 0.5 * numpy_sum(buf, R)


@njit(cache=True)
def _slope(u, w, mask, k, s, buf):
    """G′(s) of pair k: ½ Σ_f (u_f + s·w_f)·w_f / |u_f + s·w_f| over its live faces of nonzero area."""
    R = mask.shape[1]
    for j in range(R):
        v0 = u[k, 0, j] + s * w[k, 0, j]
        v1 = u[k, 1, j] + s * w[k, 1, j]
        v2 = u[k, 2, j] + s * w[k, 2, j]
        n = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        dot = 0.0 + v0 * w[k, 0, j] + v1 * w[k, 1, j] + v2 * w[k, 2, j]  # numpy's reduce starts at 0
        ok = mask[k, j] and n > 0
        q = dot / (n if ok else 1.0)
        buf[j] = q if ok else 0.0
    return 0.5 * numpy_sum(buf, R)


@njit(cache=True)
def _f(kind, u, w, mask, before, k, s, buf):
    """The bisected function: 0 the slope, 1 ΔS, 2 −ΔS (each non-decreasing on its interval)."""
    if kind == 0:
        return _slope(u, w, mask, k, s, buf)
    d = _delta(u, w, mask, before, k, s, buf)
    return d if kind == 1 else -d


@njit(cache=True)
def _bisect(kind, u, w, mask, before, k, lo, hi, buf):
    """The root of non-decreasing f on [lo, hi] by `STEPS` halvings (fewer when the interval stops
    changing: the rest would repeat the last one)."""
    for _ in range(STEPS):
        mid = 0.5 * (lo + hi)
        if _f(kind, u, w, mask, before, k, mid, buf) >= 0:
            if hi == mid:
                break
            hi = mid
        else:
            if lo == mid:
                break
            lo = mid
    return 0.5 * (lo + hi)


@njit(cache=True)
def _clip(x, lo, hi):
    """``np.clip(x, lo, hi)`` (NaN stays NaN)."""
    if np.isnan(x) or np.isnan(lo) or np.isnan(hi):
        return np.nan
    return min(max(x, lo), hi)


@njit(cache=True)
def _root(i, u, w, mask, before, k, a, b, peak, cand_s, cand_d, buf):
    """Candidate i (0: the root of ΔS in [a, peak], 1: the root of −ΔS in [peak, b]) and its ΔS, into
    cand_s[i], cand_d[i]."""
    if i == 0:
        cand_s[0] = _clip(_bisect(1, u, w, mask, before, k, a, peak, buf), a, peak)
    else:
        cand_s[1] = _clip(_bisect(2, u, w, mask, before, k, peak, b, buf), peak, b)
    cand_d[i] = _delta(u, w, mask, before, k, cand_s[i], buf)


@njit(cache=True)
def solve(u, w, mask, before, lo, hi, s_out, cost_out, d_out, branch_out):
    """`area.solve_host` for K pairs from their rings' affine areas u, w (K,3,R) float64 C-contiguous, mask
    (K,R), the areas before (K,) and intervals lo, hi (K,): fills s, |ΔS|, ΔS and the branch (K,)."""
    K, R = mask.shape
    buf = np.empty(max(R, 1))
    cand_s = np.empty(5)  # the candidates: the root left of the peak, the one right of it, peak, lo, hi
    cand_d = np.empty(5)
    ok = np.empty(5, np.bool_)
    for k in range(K):
        a, b = lo[k], hi[k]
        peak = _clip(_bisect(0, u, w, mask, before, k, a, b, buf), a, b)
        d_lo = _delta(u, w, mask, before, k, a, buf)
        d_hi = _delta(u, w, mask, before, k, b, buf)
        d_peak = _delta(u, w, mask, before, k, peak, buf)
        cand_s[2], cand_s[3], cand_s[4] = peak, a, b
        cand_d[2], cand_d[3], cand_d[4] = d_peak, d_lo, d_hi
        ok[0] = (d_lo <= 0) and (d_peak >= 0)
        ok[1] = (d_hi <= 0) and (d_peak >= 0)
        ok[2] = ok[3] = ok[4] = True
        # a side's root is bisected where the side has one; elsewhere it weighs +inf, and its value matters
        # only if it is chosen all the same (below)
        for i in range(2):
            if ok[i]:
                _root(i, u, w, mask, before, k, a, b, peak, cand_s, cand_d, buf)
        # np.argmin over |ΔS| of the allowed candidates (+inf for the others): the first NaN, else the
        # first smallest
        best = -1
        best_v = np.inf
        for i in range(5):
            v = abs(cand_d[i]) if ok[i] else np.inf
            if np.isnan(v):
                best = i
                break
            if best < 0 or v < best_v:
                best, best_v = i, v
        if not ok[best]:  # every allowed one at +inf: the first root, though its side has none
            _root(best, u, w, mask, before, k, a, b, peak, cand_s, cand_d, buf)
        s_out[k] = cand_s[best]
        cost_out[k] = abs(cand_d[best])
        d_out[k] = cand_d[best]
        if a == b:
            branch_out[k] = 3
        elif best == 2:
            branch_out[k] = 1
        elif best >= 3:
            branch_out[k] = 2
        else:
            branch_out[k] = 0
