"""`memoryless.current_quadrics`'s sums, compiled: a memoryless run rebuilds the quadric of every vertex
whose neighbourhood changed after each round (parallel) or contraction (greedy), and the numpy version
gathered, sorted (the boundary edges' count) and scattered one array per column for that, with the area
weights' powers taken one Python call at a time (`fixed_order.power`): most of such a run's time.

The arithmetic is numpy's, operation for operation, so that the rows are the same bits
(tests/test_memoryless.py compares them on random meshes): the cross product as ``np.cross`` forms it
(a1·b2 − a2·b1, …), lengths as √((x² + y²) + z²), each weight r^p through the C library's ``pow`` (what
Python's ``math.pow`` calls; the same on every x86-64), and per vertex three sums each from +0.0 in the
order of the vertex's faces (bincount's): the face planes, then the planes of the boundary edges that come
second in the rotated face, then of those that come third, added to each other in that order."""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit

TINY = np.finfo(np.float64).tiny


@njit(cache=True, nogil=True, inline="always")
def _power(r, p):
    """r^p for r ≥ 0, exactly r at p = 1 and 1 at p = 0 (the numpy twin's `_power`)."""
    if p == 1.0:
        return r
    if p == 0.0:
        return 1.0
    return max(r, TINY) ** p


@njit(cache=True, nogil=True, inline="always")
def _add_plane(S, s, w, x, y, z):
    """S[s] += the packed upper triangle of w·n nᵀ, n = (x, y, z) (the numpy twin's `_planes`)."""
    S[s, 0] += w * (x * x)
    S[s, 1] += w * (x * y)
    S[s, 2] += w * (x * z)
    S[s, 3] += w * (y * y)
    S[s, 4] += w * (y * z)
    S[s, 5] += w * (z * z)


@njit(cache=True, nogil=True)
def rebuild(P, F, alive, cnt, off, pool, verts, powers, boundary_weights, mean_areas, mean_e2s):
    """(k, 13) float64: `memoryless.current_quadrics` of ``verts`` (k,) from the live faces around each (the
    `incidence.FaceLists` arrays F, alive, cnt, off, pool), positions P (n, 3) float64; each vertex with its
    own weights (k,) float64 (a batch's copies each have their model's)."""
    k = len(verts)
    out = np.zeros((k, 13))
    acc = np.empty((3, 6))  # one vertex's sums: its face planes, its boundary edges (v, c1), (v, c2)
    ends = np.empty((64, 2), np.int64)  # the other corners (c1, c2) of each live face [v, c1, c2] at one vertex,
    for s in range(k):  # grown when a vertex has more faces
        v = verts[s]
        area_power, boundary_weight = powers[s], boundary_weights[s]
        ma = max(mean_areas[s], TINY)
        me2 = max(mean_e2s[s], TINY)
        r = 0
        for i in range(cnt[v]):
            f = pool[off[v] + i]
            if alive[f]:
                if r == len(ends):
                    grown = np.empty((2 * len(ends), 2), np.int64)
                    grown[:r] = ends[:r]
                    ends = grown
                c = 0 if F[f, 0] == v else (1 if F[f, 1] == v else 2)
                ends[r, 0], ends[r, 1] = F[f, (c + 1) % 3], F[f, (c + 2) % 3]
                r += 1
        acc[:] = 0.0
        px, py, pz = P[v, 0], P[v, 1], P[v, 2]
        for t in range(r):
            a, b = ends[t, 0], ends[t, 1]
            ux, uy, uz = P[a, 0] - px, P[a, 1] - py, P[a, 2] - pz
            wx, wy, wz = P[b, 0] - px, P[b, 1] - py, P[b, 2] - pz
            cx, cy, cz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
            nrm = np.sqrt((cx * cx + cy * cy) + cz * cz)
            d = nrm if nrm > 0 else 1.0
            nx, ny, nz = cx / d, cy / d, cz / d
            _add_plane(acc, 0, _power(0.5 * nrm / ma, area_power), nx, ny, nz)
            out[s, 10] += 0.5 * cx
            out[s, 11] += 0.5 * cy
            out[s, 12] += 0.5 * cz
            if boundary_weight > 0:
                for j in range(2):
                    e_end = ends[t, j]
                    seen = 0  # the edge (v, e_end) among the other ends of every live face at v
                    for u in range(r):
                        seen += (ends[u, 0] == e_end) + (ends[u, 1] == e_end)
                    if seen != 1:
                        continue
                    ex, ey, ez = (ux, uy, uz) if j == 0 else (wx, wy, wz)
                    mx, my, mz = ey * nz - ez * ny, ez * nx - ex * nz, ex * ny - ey * nx
                    mn = np.sqrt((mx * mx + my * my) + mz * mz)
                    dm = mn if mn > 0 else 1.0
                    wb = boundary_weight * _power(((ex * ex + ey * ey) + ez * ez) / me2, area_power) \
                        * (1.0 if mn > 0 else 0.0)
                    _add_plane(acc, 1 + j, wb, mx / dm, my / dm, mz / dm)
        for i in range(6):
            out[s, i] = (acc[0, i] + acc[1, i]) + acc[2, i] if boundary_weight > 0 else acc[0, i]
    return out
