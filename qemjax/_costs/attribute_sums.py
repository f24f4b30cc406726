"""`attributes.attribute_state`'s per-corner sums, compiled: the same arithmetic as its numpy code, operation
for operation (einsum's sums start at +0.0 and add the channels in order; numpy's sum of squares adds them
in order; bincount adds the corners k-major, face by face), so the states are the same bits
(tests/test_attributes.py compares them). The numpy code built a (3f, 11 + 4m) matrix of columns and
scattered each with a bincount, a sizeable part of a small textured mesh's run (docs/benchmarks.md,
"Measured choices inside a run").

Up to `MAX_CHANNELS` channels: with three or more, numpy's einsum adds them in an order of its own (its
vector code pairs them: the bits differed in the test), so colours and normals keep the numpy code."""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit

MAX_CHANNELS = 2  # UVs (and one channel): with more, einsum's order is its own (module docstring)


@njit(cache=True, nogil=True)
def corner_sums(F, g, S, w, n):
    """(n, 11 + 4m) float64: per vertex, Σ over its face corners (k-major, face by face) of
    [w·packed(Σ_j g_j g_jᵀ) (6), w·Σ_j s_j g_j (3), w·Σ_j s_j² (1), w (1), then per channel j: w·g_j (3),
    w·s_j (1)], where g (f, m, 3) are the faces' field gradients, S (f, 3, m) the corner values, w (f,)
    the face weights."""
    nf, m = g.shape[0], g.shape[1]
    out = np.zeros((n, 11 + 4 * m))
    pi = (0, 0, 0, 1, 1, 2)
    pk = (0, 1, 2, 1, 2, 2)
    for k in range(3):
        for f in range(nf):
            v = F[f, k]
            wf = w[f]
            for c in range(6):  # the packed upper triangle of Σ_j g_j g_jᵀ (einsum: from +0, j in order)
                t = 0.0
                for j in range(m):
                    t += g[f, j, pi[c]] * g[f, j, pk[c]]
                out[v, c] += wf * t
            for i in range(3):  # Σ_j s_j g_j
                t = 0.0
                for j in range(m):
                    t += S[f, k, j] * g[f, j, i]
                out[v, 6 + i] += wf * t
            t = S[f, k, 0] * S[f, k, 0]  # Σ_j s_j² (numpy's sum of a few: in order)
            for j in range(1, m):
                t = t + S[f, k, j] * S[f, k, j]
            out[v, 9] += wf * t
            out[v, 10] += wf
            for j in range(m):
                for i in range(3):
                    out[v, 11 + 4 * j + i] += wf * g[f, j, i]
                out[v, 14 + 4 * j] += wf * S[f, k, j]
    return out


@njit(cache=True, nogil=True)
def face_systems(P, S):
    """`attributes.face_fields`' systems, in numpy's arithmetic: per face of corners P (f,3,3) and corner
    values S (f,3,m), M (f,4,4) = [corners | 1; unit normal | 0], rhs (f,4,m) = [S; 0], and the normal's
    length nn (f,) (np.cross's products and differences, np.linalg.norm's squares added left to right)."""
    nf, m = P.shape[0], S.shape[2]
    M = np.zeros((nf, 4, 4))
    rhs = np.zeros((nf, 4, m))
    nn = np.empty(nf)
    for f in range(nf):
        u0, u1, u2 = P[f, 1, 0] - P[f, 0, 0], P[f, 1, 1] - P[f, 0, 1], P[f, 1, 2] - P[f, 0, 2]
        v0, v1, v2 = P[f, 2, 0] - P[f, 0, 0], P[f, 2, 1] - P[f, 0, 1], P[f, 2, 2] - P[f, 0, 2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        length = np.sqrt((n0 * n0 + n1 * n1) + n2 * n2)
        nn[f] = length
        d = length if length > 0 else 1.0
        for i in range(3):
            for j in range(3):
                M[f, i, j] = P[f, i, j]
            M[f, i, 3] = 1.0
            for c in range(m):
                rhs[f, i, c] = S[f, i, c]
        M[f, 3, 0], M[f, 3, 1], M[f, 3, 2] = n0 / d, n1 / d, n2 / d
    return M, rhs, nn
