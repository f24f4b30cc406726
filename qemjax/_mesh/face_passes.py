"""Per-face quantities in one compiled pass (numba), in numpy's arithmetic: the same bits as the whole-array
expressions they replace, without their dozen (m,) temporaries (`arrays.face_stats`; tests/test_arrays.py compares them)."""
from __future__ import annotations

import numpy as np

from .compiled import njit


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


@njit(cache=True, inline="always")
def _holds(g0, g1, g2, w):
    """Whether the face with corners g0, g1, g2 holds vertex w (without a branch)."""
    return (g0 == w) | (g1 == w) | (g2 == w)


@njit(cache=True, inline="always")
def _corner(g0, g1, g2, v):
    """The corner (0, 1 or 2) of the face g0, g1, g2 that holds v: the first, where it holds v twice."""
    return 0 if g0 == v else (1 if g1 == v else 2)


@njit(cache=True, inline="always")
def _rotated(rows, k, F, f, v):
    """rows[k] = face f's corners rotated to start at its corner v (`_corner`), the orientation kept."""
    c = _corner(F[f, 0], F[f, 1], F[f, 2], v)
    rows[k, 0], rows[k, 1], rows[k, 2] = F[f, c], F[f, (c + 1) % 3], F[f, (c + 2) % 3]


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
        holds = _holds(g0, g1, g2, other)
        dead[nd] = fk[i]
        dead_owner[nd] = s
        nd += holds & (side == 1)
        c = _corner(g0, g1, g2, v)
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


@njit(cache=True, nogil=True)
def ring_rows(F, alive, cnt, off, pool, ends, with_dead):
    """`ring.ring_faces` in one pass: for pairs given by their endpoints ``ends`` (a0, b0, a1, b1, ...),
    (owner pair (k,) int64, non-decreasing; rows (k,3) int32) of each pair's live faces at a, then at b
    (pool order), that do not hold both, each rotated to start at its corner a or b; with ``with_dead``,
    after them the pair's faces that hold both (found from b's side), rotated to start at b. Every face
    visited gives at most one row, so the rows fit in the faces around the endpoints."""
    total = 0
    for v in ends:
        total += cnt[v]
    owner = np.empty(total, np.int64)
    rows = np.empty((total, 3), np.int32)
    dead = np.empty(total, pool.dtype)  # the current pair's dying faces, written after its kept ones
    k = 0
    for s in range(len(ends) // 2):
        nd = 0
        for side in range(2):
            v, other = ends[2 * s + side], ends[2 * s + 1 - side]
            for i in range(off[v], off[v] + cnt[v]):
                f = pool[i]
                if not alive[f]:
                    continue
                if _holds(F[f, 0], F[f, 1], F[f, 2], other):
                    if side == 1:
                        dead[nd] = f
                        nd += 1
                    continue
                _rotated(rows, k, F, f, v)
                owner[k] = s
                k += 1
        if with_dead:
            b = ends[2 * s + 1]
            for j in range(nd):
                _rotated(rows, k, F, dead[j], b)
                owner[k] = s
                k += 1
    return owner[:k], rows[:k]


@njit(cache=True, nogil=True)
def pad_rings(rows, start, counts, idx, R, pad):
    """The padded rings (`ring.Rings`) of items ``idx``: item i's ``counts[i]`` rows from ``rows[start[i]]``
    on, then rows of ``pad`` up to R: corners (len(idx), R, 3) int32, mask (len(idx), R) bool."""
    n = len(idx)
    corners = np.full((n, R, 3), pad, np.int32)
    mask = np.zeros((n, R), np.bool_)
    for j in range(n):
        i = idx[j]
        s = start[i]
        for t in range(counts[i]):
            corners[j, t, 0], corners[j, t, 1], corners[j, t, 2] = rows[s + t, 0], rows[s + t, 1], rows[s + t, 2]
            mask[j, t] = True
    return corners, mask


@njit(cache=True, nogil=True)
def repeated(h):
    """The rows of h (n,) uint64 whose value another row holds too, ascending: ``np.flatnonzero(np.isin(h,
    values held twice))`` from one pass through an open-addressing table, where numpy sorted the values
    (the faces a round touches: a sort every round)."""
    n = len(h)
    size = 16
    while size < 2 * n:
        size <<= 1
    mask = np.uint64(size - 1)
    value = np.empty(size, np.uint64)
    held = np.zeros(size, np.int8)  # 0: empty, 1: one row's value, 2: more
    slot = np.empty(n, np.int64)
    twice = 0
    for i in range(n):
        k = h[i]
        j = np.int64((k ^ (k >> np.uint64(29))) & mask)
        while held[j] and value[j] != k:
            j = (j + 1) & (size - 1)
        if held[j] == 0:
            value[j] = k
            held[j] = 1
        elif held[j] == 1:
            held[j] = 2
            twice += 1
        slot[i] = j
    if twice == 0:
        return np.zeros(0, np.int64)
    count = 0
    for i in range(n):
        count += held[slot[i]] == 2
    out = np.empty(count, np.int64)
    count = 0
    for i in range(n):
        if held[slot[i]] == 2:
            out[count] = i
            count += 1
    return out
