"""Per-face quantities in one compiled pass (numba), in numpy's arithmetic: the same bits as the whole-array
expressions they replace, without their dozen (m,) temporaries (`arrays.face_stats`; tests/test_arrays.py compares them)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def face_rows(V, F, half):
    """(nz (m,) bool, area (m,), e2 (m,)) of faces F over V, in V's dtype (``half``: 0.5 in it, as numpy's
    ``0.5 * array`` keeps a float32 array float32): whether the normal (p1 − p0) × (p2 − p0) is non-zero,
    half its length, and the sum of the squared edge vectors' coordinates, edges p1 − p0, p2 − p1, p0 − p2,
    coordinates x, y, z, summed left to right (numpy's order in `arrays.face_stats`)."""
    m = F.shape[0]
    nz = np.empty(m, np.bool_)
    area = np.empty(m, V.dtype)
    e2 = np.empty(m, V.dtype)
    for f in range(m):
        i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
        u0, u1, u2 = V[i1, 0] - V[i0, 0], V[i1, 1] - V[i0, 1], V[i1, 2] - V[i0, 2]
        s0, s1, s2 = V[i2, 0] - V[i1, 0], V[i2, 1] - V[i1, 1], V[i2, 2] - V[i1, 2]
        t0, t1, t2 = V[i0, 0] - V[i2, 0], V[i0, 1] - V[i2, 1], V[i0, 2] - V[i2, 2]
        w0, w1, w2 = -t0, -t1, -t2
        n0, n1, n2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
        nz[f] = n0 != 0 or n1 != 0 or n2 != 0
        area[f] = half * np.sqrt((n0 * n0 + n1 * n1) + n2 * n2)
        e2[f] = ((((((((u0 * u0 + u1 * u1) + u2 * u2) + s0 * s0) + s1 * s1) + s2 * s2) + t0 * t0) + t1 * t1)
                 + t2 * t2)
    return nz, area, e2


@njit(cache=True, nogil=True, inline="always")
def _repeats(F, f, c):
    """Whether corner c of face f repeats an earlier corner's vertex."""
    return (c >= 1 and F[f, 0] == F[f, c]) or (c == 2 and F[f, 1] == F[f, c])


@njit(cache=True, nogil=True)
def vertex_runs(F, n):
    """Each vertex's faces as one run, in face order, a face once even where it repeats the vertex
    (`incidence.FaceLists`' layout): (cnt (n,) int64, off
    (n,) int64, pool (6m + 64,) int32 with the runs first, and where they end). A counting sort, as
    scipy's COO -> CSR conversion of the incidence matrix made it."""
    m = F.shape[0]
    cnt = np.zeros(n, np.int64)
    for f in range(m):
        for c in range(3):
            v = F[f, c]
            if v < 0 or v >= n:
                raise ValueError("a face's vertex index is out of range")
            if not _repeats(F, f, c):  # a vertex repeated in its face lists it once (scipy summed duplicates)
                cnt[v] += 1
    off = np.empty(n, np.int64)
    end = 0
    for v in range(n):
        off[v] = end
        end += cnt[v]
    pool = np.empty(6 * m + 64, np.int32)
    fill = off.copy()
    for f in range(m):
        for c in range(3):
            if not _repeats(F, f, c):
                v = F[f, c]
                pool[fill[v]] = f
                fill[v] += 1
    return cnt, off, pool, end
