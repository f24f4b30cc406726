"""The greedy queue's rules, compiled (numba), for `greedy_jit`: the flip test, the link condition, the
vanishing-part rule and the coincident-face rule that the one-at-a-time loop (`greedy._run`) applies, over
the faces' corner array ``T`` and each vertex's face list (``fs``/``fl`` start and length into ``fpool``;
a face listed once at each of its distinct corners). On a `greedy_compiled.simple` mesh in manifold mode
(the usual case) the link rule's degree test and the coincident-face test take shortcuts that the mesh
allows; elsewhere (non-manifold mode, where a contraction drops the faces it makes coincide, or a mesh with
repeated corners or faces) the general rules run. The same answers as the loop (tests/test_greedy_compiled.py
compares whole runs, and each rule with a Python reference), the flip test with the same float32 operations
and roundings as `flips.flips_host_faces`."""
from __future__ import annotations

import numpy as np
from numba import njit

from .outcome import BUDGET, COINCIDENT, FLIP, LOCKED, PART, TOPOLOGY


@njit(cache=True, inline="always")
def has(pool, start, length, v):
    for i in range(start, start + length):
        if pool[i] == v:
            return True
    return False


@njit(cache=True)
def flips(VQ, N0, F, f, corner, x, cos_max, sliver):
    """`flips.flips_host_faces` for face f (corners F[f], positions VQ (n, ≥3)) with its corner ``corner``
    moved to x: the same float32 operations in the same order (products, then sums x + y, then + z; each
    rounded to float32), on scalars (no small arrays per face: the parallel round tests thousands)."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    g0x, g0y, g0z = VQ[i0, 0], VQ[i0, 1], VQ[i0, 2]
    g1x, g1y, g1z = VQ[i1, 0], VQ[i1, 1], VQ[i1, 2]
    g2x, g2y, g2z = VQ[i2, 0], VQ[i2, 1], VQ[i2, 2]
    q0x, q0y, q0z = g0x, g0y, g0z
    q1x, q1y, q1z = g1x, g1y, g1z
    q2x, q2y, q2z = g2x, g2y, g2z
    if corner == 0:
        q0x, q0y, q0z = x[0], x[1], x[2]
    elif corner == 1:
        q1x, q1y, q1z = x[0], x[1], x[2]
    else:
        q2x, q2y, q2z = x[0], x[1], x[2]
    u0x, u0y, u0z = g1x - g0x, g1y - g0y, g1z - g0z
    v0x, v0y, v0z = g2x - g0x, g2y - g0y, g2z - g0z
    u1x, u1y, u1z = q1x - q0x, q1y - q0y, q1z - q0z
    v1x, v1y, v1z = q2x - q0x, q2y - q0y, q2z - q0z
    n0x, n0y, n0z = u0y * v0z - u0z * v0y, u0z * v0x - u0x * v0z, u0x * v0y - u0y * v0x
    n1x, n1y, n1z = u1y * v1z - u1z * v1y, u1z * v1x - u1x * v1z, u1x * v1y - u1y * v1x
    e1x, e1y, e1z = q2x - q1x, q2y - q1y, q2z - q1z
    e2x, e2y, e2z = q0x - q2x, q0y - q2y, q0z - q2z
    rx, ry, rz = N0[f, 0], N0[f, 1], N0[f, 2]
    d11 = n1x * n1x + n1y * n1y + n1z * n1z
    d01 = n0x * n1x + n0y * n1y + n0z * n1z
    d00 = n0x * n0x + n0y * n0y + n0z * n0z
    de0 = u1x * u1x + u1y * u1y + u1z * u1z
    de1 = e1x * e1x + e1y * e1y + e1z * e1z
    de2 = e2x * e2x + e2y * e2y + e2z * e2z
    dr1 = rx * n1x + ry * n1y + rz * n1z
    drr = rx * rx + ry * ry + rz * rz
    l1 = np.float32(np.sqrt(d11))
    if d01 <= cos_max * np.float32(np.sqrt(d00)) * l1:
        return True
    longest2 = de0 if (de0 >= de1 or de0 != de0) else de1  # np.maximum: a NaN wins
    longest2 = longest2 if (longest2 >= de2 or longest2 != longest2) else de2
    if l1 <= sliver * longest2 and cos_max > -1.0:
        return True
    return dr1 <= cos_max * np.float32(np.sqrt(drr)) * l1


@njit(cache=True)
def link_common(T, fs, fl, fpool, cnt, a, b, nshared, out, simple):
    """The link rule of `greedy._link_ok` for the pair (a, b) with ``nshared`` faces: the common
    neighbours of a and b into ``out`` (their number), or -1 where it fails: a manifold edge whose
    endpoints' common neighbours are exactly the apexes of its faces, not pinching two boundaries together
    through an interior edge, no apex of an interior edge of degree 3. ``cnt`` (n,3): zeros, left zeros.
    ``simple``: the mesh is `greedy_compiled.simple` (then an apex with 4 faces or more has 4 neighbours
    or more, and only apexes with 3 faces or fewer are counted)."""
    if nshared < 1 or nshared > 2:
        return -1
    for side in range(2):  # corners of a's faces counted in column 0, of b's in column 1
        v = a if side == 0 else b
        for i in range(fs[v], fs[v] + fl[v]):
            for c in T[fpool[i]]:
                cnt[c, side] += 1
    k = 0
    bound = np.zeros(2, np.bool_)  # a (b) on a boundary: a neighbour counted once
    for side in range(2):
        v = a if side == 0 else b
        for i in range(fs[v], fs[v] + fl[v]):
            for c in T[fpool[i]]:
                if c != v and cnt[c, side] == 1:
                    bound[side] = True
                if side == 0 and cnt[c, 1] > 0 and c != a and c != b and cnt[c, 2] == 0:
                    cnt[c, 2] = 1
                    if k < 2:
                        out[k] = c
                    k += 1
    for side in range(2):  # back to zeros
        v = a if side == 0 else b
        for i in range(fs[v], fs[v] + fl[v]):
            for c in T[fpool[i]]:
                cnt[c, 0] = cnt[c, 1] = cnt[c, 2] = 0
    if k != nshared:
        return -1
    if nshared == 2:
        if bound[0] and bound[1]:
            return -1
        for j in range(2):
            c = out[j]
            # k distinct faces at c need k <= C(d, 2) of its d neighbours: 4 faces or more, 4 or more
            if (fl[c] <= 3 or not simple) and _distinct_corners(T, fs, fl, fpool, c) - 1 <= 3:
                return -1
    return k


@njit(cache=True)
def _distinct_corners(T, fs, fl, fpool, c):
    seen = np.empty(3 * fl[c], np.int64)
    k = 0
    for i in range(fs[c], fs[c] + fl[c]):
        for v in T[fpool[i]]:
            new = True
            for j in range(k):
                if seen[j] == v:
                    new = False
                    break
            if new:
                seen[k] = v
                k += 1
    return k


@njit(cache=True)
def coincident_drop(a, b, T, A, nka, B, nkb, R):
    """`topo.coincident_removals` of the faces kept around the pair once b is contracted into a (those at
    a, then those at b with b replaced by a; taken in face order): the faces to drop into R (ascending), and
    their number. Of a group of faces with the same three corners, oppositely oriented ones cancel in pairs,
    lower index first, and of what is left (all of one orientation) the first is kept. Every kept face holds
    a afterwards, so two coincide when their other two corners do: none in the usual case, found without
    sorting."""
    k = nka + nkb
    S = np.empty((k, 3), np.int64)
    for i in range(k):
        f = A[i] if i < nka else B[i - nka]
        t0, t1, t2 = T[f, 0], T[f, 1], T[f, 2]
        if i >= nka:
            t0, t1, t2 = (a if t0 == b else t0), (a if t1 == b else t1), (a if t2 == b else t2)
        if t0 > t1:
            t0, t1 = t1, t0
        if t1 > t2:
            t1, t2 = t2, t1
        if t0 > t1:
            t0, t1 = t1, t0
        S[i, 0], S[i, 1], S[i, 2] = t0, t1, t2
    any_pair = False
    for i in range(k):
        for j in range(i + 1, k):
            if S[i, 0] == S[j, 0] and S[i, 1] == S[j, 1] and S[i, 2] == S[j, 2]:
                any_pair = True
                break
        if any_pair:
            break
    if not any_pair:
        return 0
    fid = np.empty(k, np.int64)
    for i in range(k):
        fid[i] = A[i] if i < nka else B[i - nka]
    order = np.argsort(fid)
    G = np.empty((k, 3), np.int64)  # the faces after, in face order, and their sorted corners
    Ss = np.empty((k, 3), np.int64)
    pos = np.empty(k, np.bool_)
    for r in range(k):
        i = order[r]
        f = fid[i]
        for c in range(3):
            t = T[f, c]
            G[r, c] = a if (i >= nka and t == b) else t
            Ss[r, c] = S[i, c]
        inv = (1 if G[r, 0] > G[r, 1] else 0) + (1 if G[r, 0] > G[r, 2] else 0) + (1 if G[r, 1] > G[r, 2] else 0)
        pos[r] = inv % 2 == 0
    m = 0
    for r in range(k):
        npos = nneg = rank = 0
        for q in range(k):
            if Ss[q, 0] == Ss[r, 0] and Ss[q, 1] == Ss[r, 1] and Ss[q, 2] == Ss[r, 2]:
                if pos[q]:
                    npos += 1
                else:
                    nneg += 1
                if q < r and pos[q] == pos[r]:
                    rank += 1
        c = min(npos, nneg)
        mine = npos if pos[r] else nneg
        if rank < c or (mine > c and rank > c):
            R[m] = fid[order[r]]
            m += 1
    return m


@njit(cache=True)
def rules(a, b, x, faces, target, manifold, simple, keep_parts, cos_max, sliver, has_locks, locked, T, fs, fl, fpool,
          VQ, N0, cnt, A, B, D, R, common, info):
    """The checks of the one-at-a-time loop (`greedy._run`), in its order: the code of the first rule that
    contracting b into a at x breaks, or -1. Leaves what the contraction would change: info = (number of
    dead faces, of faces kept at a, at b, of faces dropped as coincident (non-manifold mode), of common
    neighbours), A and B the faces kept at a and at b (room for fl[a] and fl[b]), D the dead faces (room for
    fl[a]), R the dropped ones (room for fl[a] + fl[b]). In two parts (`rules_head`, `rules_tail`): the
    loop's seam rule (kept attributes, `greedy_wedges_jit.seam_ok`) comes between them."""
    code = rules_head(a, b, faces, target, manifold, simple, keep_parts, has_locks, locked, T, fs, fl, fpool, cnt,
                      A, B, D, common, info)
    if code >= 0:
        return code
    return rules_tail(a, b, x, faces, target, manifold, simple, cos_max, sliver, T, VQ, N0, A, B, R, common, info)


@njit(cache=True)
def rules_head(a, b, faces, target, manifold, simple, keep_parts, has_locks, locked, T, fs, fl, fpool, cnt, A, B,
               D, common, info):
    """`rules` up to the lock rule (the face budget, the link rule, the vanishing part, the locks)."""
    nd = nka = nkb = 0
    for i in range(fs[a], fs[a] + fl[a]):
        f = fpool[i]
        if has(fpool, fs[b], fl[b], f):
            D[nd] = f
            nd += 1
        else:
            A[nka] = f
            nka += 1
    for i in range(fs[b], fs[b] + fl[b]):
        f = fpool[i]
        if not has(D, 0, nd, f):
            B[nkb] = f
            nkb += 1
    info[0], info[1], info[2], info[3] = nd, nka, nkb, 0
    if faces - nd < target:
        return BUDGET
    ncommon = 0
    if manifold:
        ncommon = link_common(T, fs, fl, fpool, cnt, a, b, nd, common, simple)
        if ncommon < 0:
            return TOPOLOGY
        if keep_parts and nka == 0 and nkb == 0:  # its faces are all its part has left
            return PART
    info[4] = ncommon
    if has_locks and _strands(a, b, nd, nka + nkb, locked, T, fl, D):
        return LOCKED
    return -1


@njit(cache=True)
def rules_tail(a, b, x, faces, target, manifold, simple, cos_max, sliver, T, VQ, N0, A, B, R, common, info):
    """`rules` from the flip test on (the flip test, the coincident faces), after `rules_head`."""
    nd, nka, nkb, ncommon = info[0], info[1], info[2], info[4]
    for i in range(nka + nkb):
        f = A[i] if i < nka else B[i - nka]
        v = a if i < nka else b
        corner = 0 if T[f, 0] == v else (1 if T[f, 1] == v else 2)
        if flips(VQ, N0, T, f, corner, x, cos_max, sliver):
            return FLIP
    if manifold and simple:
        if ncommon == 2 and _coincide(a, b, T, A, nka, B, nkb, common):
            return COINCIDENT
        return -1
    ndrop = coincident_drop(a, b, T, A, nka, B, nkb, R)
    if ndrop and (manifold or faces - nd - ndrop < target):  # forbidden in manifold mode, else dropped
        return COINCIDENT if manifold else BUDGET
    info[3] = ndrop
    return -1


@njit(cache=True)
def _strands(a, b, nd, nkept, locked, T, fl, D):
    """Whether the contraction would leave a locked vertex in no face (`_locks.vanishing`, `_locks.strands`):
    a or b locked and no face kept, or a locked third corner of the dead faces D whose faces all die."""
    if nkept == 0 and (locked[a] or locked[b]):
        return True
    for i in range(nd):
        for c in T[D[i]]:
            if c != a and c != b and locked[c]:
                k = 0  # c's corners among the dead faces
                for j in range(nd):
                    for v in T[D[j]]:
                        if v == c:
                            k += 1
                if k >= fl[c]:
                    return True
    return False


@njit(cache=True, inline="always")
def _coincide(a, b, T, A, nka, B, nkb, common):
    """`coincident_drop` is not empty, on a simple mesh where the link rule holds with two common
    neighbours u and w: only faces (a, u, w) and (b, u, w) can coincide. (Looked up in the kept faces'
    corners, O(fl[a] + fl[b]); not in u's and w's face lists, O(fl[u] fl[w]): two apexes of valence d,
    d².)"""
    u, w = common[0], common[1]
    hit_a = hit_b = False
    for i in range(nka + nkb):
        f = A[i] if i < nka else B[i - nka]
        t0, t1, t2 = T[f, 0], T[f, 1], T[f, 2]
        if (t0 == u or t1 == u or t2 == u) and (t0 == w or t1 == w or t2 == w):
            if i < nka:
                hit_a = True
            else:
                hit_b = True
    return hit_a and hit_b
