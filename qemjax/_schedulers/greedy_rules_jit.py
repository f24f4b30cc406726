"""The greedy queue's rules, compiled (numba), for `greedy_jit`: the flip test, the link condition and the
coincident-face test of `greedy_batches._Batches.check` on a simple mesh in manifold mode, over the
faces' corner array ``T`` and each vertex's face list (``fs``/``fl`` start and length into ``fpool``).
The same answers as the Python rules (tests/test_greedy_compiled.py compares them), the flip test with
the same float32 operations and roundings as `flips.flips_host_faces`."""
from __future__ import annotations

import numpy as np
from numba import njit

from .outcome import BUDGET, COINCIDENT, FLIP, PART, TOPOLOGY

@njit(cache=True, inline="always")
def has(pool, start, length, v):
    for i in range(start, start + length):
        if pool[i] == v:
            return True
    return False


@njit(cache=True)
def flips(VQ, N0, T, f, corner, x, cos_max, sliver):
    """`flips.flips_host_faces` for face f with its corner ``corner`` moved to x: the same float32
    operations in the same order (products, then sums x + y, then + z; each rounded to float32)."""
    g = np.empty((3, 3), np.float32)
    for c in range(3):
        for i in range(3):
            g[c, i] = VQ[T[f, c], i]
    q = g.copy()
    for i in range(3):
        q[corner, i] = x[i]
    u0, v0, u1, v1 = g[1] - g[0], g[2] - g[0], q[1] - q[0], q[2] - q[0]
    n0 = np.empty(3, np.float32)
    n1 = np.empty(3, np.float32)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        n0[i] = u0[j] * v0[k] - u0[k] * v0[j]
        n1[i] = u1[j] * v1[k] - u1[k] * v1[j]
    e1, e2 = q[2] - q[1], q[0] - q[2]
    ref = N0[f]
    d11 = n1[0] * n1[0] + n1[1] * n1[1] + n1[2] * n1[2]
    d01 = n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]
    d00 = n0[0] * n0[0] + n0[1] * n0[1] + n0[2] * n0[2]
    de0 = u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]
    de1 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
    de2 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
    dr1 = ref[0] * n1[0] + ref[1] * n1[1] + ref[2] * n1[2]
    drr = ref[0] * ref[0] + ref[1] * ref[1] + ref[2] * ref[2]
    l1 = np.float32(np.sqrt(d11))
    if d01 <= cos_max * np.float32(np.sqrt(d00)) * l1:
        return True
    longest2 = de0 if (de0 >= de1 or de0 != de0) else de1  # np.maximum: a NaN wins
    longest2 = longest2 if (longest2 >= de2 or longest2 != longest2) else de2
    if l1 <= sliver * longest2 and cos_max > -1.0:
        return True
    return dr1 <= cos_max * np.float32(np.sqrt(drr)) * l1


@njit(cache=True)
def link_common(T, fs, fl, fpool, cnt, a, b, nshared, out):
    """`greedy_batches._Mesh.link_common` on a simple mesh: the common neighbours of a and b into
    ``out`` (their number), or -1 where the link rule fails. ``cnt`` (n,3): zeros, left zeros."""
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
            if fl[c] <= 3 and _distinct_corners(T, fs, fl, fpool, c) - 1 <= 3:
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
def rules(a, b, x, faces, target, keep_parts, cos_max, sliver, T, fs, fl, fpool, VQ, N0, cnt, A, B, common, info):
    """`greedy_batches._Batches.check` on a simple mesh in manifold mode: the code of the first rule that
    contracting b into a at x breaks, or -1. Leaves what the contraction would change: info = (number of
    dead faces, of faces kept at a, at b, first dead face, second or -1), A and B the faces kept at a and
    at b (room for fl[a] and fl[b])."""
    nd = nka = nkb = 0
    d0 = d1 = -1
    for i in range(fs[a], fs[a] + fl[a]):
        f = fpool[i]
        if has(fpool, fs[b], fl[b], f):
            if nd == 0:
                d0 = f
            else:
                d1 = f
            nd += 1
        else:
            A[nka] = f
            nka += 1
    for i in range(fs[b], fs[b] + fl[b]):
        f = fpool[i]
        if f != d0 and f != d1:
            B[nkb] = f
            nkb += 1
    info[0], info[1], info[2], info[3], info[4] = nd, nka, nkb, d0, d1
    if faces - nd < target:
        return BUDGET
    ncommon = link_common(T, fs, fl, fpool, cnt, a, b, nd, common)
    if ncommon < 0:
        return TOPOLOGY
    if keep_parts and nka == 0 and nkb == 0:  # its faces are all its part has left
        return PART
    for i in range(nka + nkb):
        f = A[i] if i < nka else B[i - nka]
        v = a if i < nka else b
        corner = 0 if T[f, 0] == v else (1 if T[f, 1] == v else 2)
        if flips(VQ, N0, T, f, corner, x, cos_max, sliver):
            return FLIP
    if ncommon == 2:  # (a, u, w) and (b, u, w) would coincide: a face kept at a and one kept at b on u and w
        u, w = common[0], common[1]  # (looked up in the kept faces' corners, O(fl[a] + fl[b]); not in u's
        hit_a = hit_b = False        # and w's face lists, O(fl[u] fl[w]): two apexes of valence d, d²)
        for i in range(nka + nkb):
            f = A[i] if i < nka else B[i - nka]
            t0, t1, t2 = T[f, 0], T[f, 1], T[f, 2]
            if (t0 == u or t1 == u or t2 == u) and (t0 == w or t1 == w or t2 == w):
                if i < nka:
                    hit_a = True
                else:
                    hit_b = True
        if hit_a and hit_b:
            return COINCIDENT
    return -1
