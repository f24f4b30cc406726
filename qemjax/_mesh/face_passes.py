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


@njit(cache=True, nogil=True)
def normals(V, F):
    """(m,3) unnormalised normals (p1 − p0) × (p2 − p0) of faces F over positions V, in V's dtype, with
    numpy's arithmetic (`arrays.face_normals`' whole-array expressions, np.cross's order)."""
    m = F.shape[0]
    out = np.empty((m, 3), V.dtype)
    for f in range(m):
        i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
        u0, u1, u2 = V[i1, 0] - V[i0, 0], V[i1, 1] - V[i0, 1], V[i1, 2] - V[i0, 2]
        w0, w1, w2 = V[i2, 0] - V[i0, 0], V[i2, 1] - V[i0, 1], V[i2, 2] - V[i0, 2]
        out[f, 0] = u1 * w2 - u2 * w1
        out[f, 1] = u2 * w0 - u0 * w2
        out[f, 2] = u0 * w1 - u1 * w0
    return out


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


@njit(cache=True, nogil=True)
def around(alive, cnt, off, pool, verts):
    """`incidence.FaceLists.around`: (positions into verts (k,) int64, face ids (k,)) of every live face at
    each of ``verts``, grouped by position in order, each run in pool order. The runs are copied, then the
    dead faces dropped without a branch (as in `touched`)."""
    total = 0
    for v in verts:
        total += cnt[v]
    which = np.empty(total, np.int64)
    faces = np.empty(total, pool.dtype)
    k = 0
    for s in range(len(verts)):
        v = verts[s]
        o = off[v]
        for i in range(cnt[v]):
            faces[k + i] = pool[o + i]
            which[k + i] = s
        k += cnt[v]
    m = 0
    for i in range(k):  # (in place: m <= i)
        f = faces[i]
        faces[m] = f
        which[m] = which[i]
        m += alive[f]
    return which[:m], faces[:m]


@njit(cache=True, nogil=True)
def touched(F, alive, cnt, off, pool, ends):
    """`incidence.FaceLists.touched_with_dead` over the live faces around pairs given by their endpoints
    ``ends`` (a0, b0, a1, b1, ...), visited in that order, each run in pool order (`around`): a face holding
    its pair's other endpoint dies (listed once, from b's side, with its owner pair); every other one is
    kept with its position w into the endpoints, its corners before and after (the moving corner, the first
    that holds the endpoint, takes a) and its owner pair. Returns (f, G, corner, owner, after), (w, f,
    corner), (dead faces, their owners), with numpy's dtypes (f and the dead faces: the pool's; G and after:
    F's; the rest int64).

    After the look-up, two passes over arrays in order: the faces' corners gathered (loads that wait on no
    branch, so their cache misses overlap), then the faces sorted into kept and dead without a branch
    (whether a face lives or dies follows no pattern)."""
    wk, fk = around(alive, cnt, off, pool, ends)
    m = len(fk)
    G = np.empty((m, 3), F.dtype)
    for i in range(m):
        f = fk[i]
        G[i, 0], G[i, 1], G[i, 2] = F[f, 0], F[f, 1], F[f, 2]
    after = np.empty((m, 3), F.dtype)
    corner = np.empty(m, np.int64)
    owner = np.empty(m, np.int64)
    dead = np.empty(m, pool.dtype)
    dead_owner = np.empty(m, np.int64)
    k = nd = 0
    for i in range(m):  # kept or dead (in place: k <= i); each is written, then the count moves or not
        w = wk[i]
        s, side = w >> 1, w & 1
        v, other = ends[w], ends[w ^ 1]
        g0, g1, g2 = G[i, 0], G[i, 1], G[i, 2]
        holds = (g0 == other) | (g1 == other) | (g2 == other)
        dead[nd] = fk[i]
        dead_owner[nd] = s
        nd += holds & (side == 1)
        c = 0 if g0 == v else (1 if g1 == v else 2)
        fk[k], wk[k], corner[k], owner[k] = fk[i], w, c, s
        G[k, 0], G[k, 1], G[k, 2] = g0, g1, g2
        after[k, 0], after[k, 1], after[k, 2] = g0, g1, g2
        after[k, c] = ends[2 * s]
        k += not holds
    fk, corner = fk[:k], corner[:k]
    return (fk, G[:k], corner, owner[:k], after[:k]), (wk[:k], fk, corner), (dead[:nd], dead_owner[:nd])


@njit(cache=True, nogil=True)
def first_step(F, step_of, faces, out):
    """out[f] = the smallest ``step_of`` of face f's corners, for each of ``faces`` (the contraction that
    removed a dying face: `parallel._removal_steps`)."""
    for f in faces:
        out[f] = min(min(step_of[F[f, 0]], step_of[F[f, 1]]), step_of[F[f, 2]])
