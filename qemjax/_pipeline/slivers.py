"""Sliver moves after the polish (a method's ``sliver_moves``): corners of slivers moved until their smallest
angle reaches SLIVER_DEG, wherever the distance allows it.

A sliver (a face whose smallest angle is under SLIVER_DEG, as `metrics.triangle_quality` counts them) is
left where the contractions ended on a thin strip of the surface or where the re-fit pulled a corner
across. Most can be undone by moving one corner a little along the surface. In each pass over the slivers,
worst first, every free corner v of a sliver gets two directions: toward the apex of the equilateral
triangle on the sliver's other two corners (in the sliver's plane) and toward the mean of v's neighbours
(in the plane of v's faces). Along each, the shortest step that takes the sliver's smallest angle to
TARGET_DEG is found by bisection; the shortest of these steps is tried first, the resulting point put on
the input surface (its nearest point there), and at most TRIES moves per sliver and pass. A move is made
(`moves.Moves.attempt`) when:

- the faces at v have fewer slivers than before and their smallest angle is no smaller;
- every sample the move touches stays below the largest distance the polish left, so the sampled
  Hausdorff distance does not rise;
- the two-way rms stays within RMS_SLACK of the re-fit's (the polish's share included);
- the re-fit's rules hold (flip angle, the input face a face continues, the quality guard) and no fixed
  vertex moves.

When no step fixes the sliver, partial ones (WEAK_STEPS of each direction) are tried that raise its faces'
smallest angle without adding a sliver, for a later pass to finish. A sliver is tried again in a later pass
only if a vertex of the faces around its corners moved since. The face count and the connectivity never
change: only positions do.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .fit_rules import COS_SLIVER, SLIVER_DEG, _min_cos
from .moves import Moves, shape_of

TARGET_DEG = SLIVER_DEG + 0.5  # the smallest angle a fixing step aims at: a margin for the move onto the input
RMS_SLACK = 0.03  # the two-way rms may rise this much (a fraction) over the re-fit's, the polish's included
WEAK_STEPS = ((0.125,), (0.5, 0.125))  # partial steps toward the apex and toward the neighbours' mean
PASSES = 4  # passes over the slivers at most
TRIES = 6  # moves tried on one sliver in one pass at most
COS_TARGET = float(np.cos(np.radians(TARGET_DEG)))


@njit(cache=True, nogil=True)
def _fix_step(X, G, g, v, delta, cos_target):
    """The least t in (0, 1] (by bisection) with face g's smallest angle at its target (cosine at most
    ``cos_target``) once corner v moves by t·delta; 0 when t = 1 does not reach it. X is left as it was."""
    x0, y0, z0 = X[v, 0], X[v, 1], X[v, 2]
    one = np.array([g])
    X[v, 0], X[v, 1], X[v, 2] = x0 + delta[0], y0 + delta[1], z0 + delta[2]
    ok = _min_cos(X, G, one)[0] <= cos_target
    lo, hi = 0.0, 1.0
    if ok:
        for _ in range(24):
            mid = 0.5 * (lo + hi)
            X[v, 0], X[v, 1], X[v, 2] = x0 + mid * delta[0], y0 + mid * delta[1], z0 + mid * delta[2]
            if _min_cos(X, G, one)[0] <= cos_target:
                hi = mid
            else:
                lo = mid
    X[v, 0], X[v, 1], X[v, 2] = x0, y0, z0
    return hi if ok else 0.0


@njit(cache=True, nogil=True)
def _apex(X, G, g, v):
    """The step from corner v of face g to the apex of the equilateral triangle on its other two corners,
    in the face's plane, on v's side."""
    k = 0
    while G[g, k] != v:
        k += 1
    p, q = G[g, (k + 1) % 3], G[g, (k + 2) % 3]
    ex, ey, ez = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
    fx, fy, fz = X[v, 0] - X[p, 0], X[v, 1] - X[p, 1], X[v, 2] - X[p, 2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    ux, uy, uz = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex  # n × e: in the plane, across e
    lu = np.sqrt((ux * ux + uy * uy) + uz * uz)
    le = np.sqrt((ex * ex + ey * ey) + ez * ez)
    out = np.zeros(3)
    if lu == 0.0:
        return out
    mx, my, mz = X[p, 0] + 0.5 * ex, X[p, 1] + 0.5 * ey, X[p, 2] + 0.5 * ez
    h = 0.8660254037844386 * le / lu  # √3/2 of the edge, across it
    if (X[v, 0] - mx) * ux + (X[v, 1] - my) * uy + (X[v, 2] - mz) * uz < 0.0:
        h = -h
    out[0], out[1], out[2] = mx + h * ux - X[v, 0], my + h * uy - X[v, 1], mz + h * uz - X[v, 2]
    return out


@njit(cache=True, nogil=True)
def _tangential(X, G, R, v):
    """The step from vertex v toward the mean of the other corners of its faces R, in the plane of their
    area-weighted normal; sums left to right."""
    cx, cy, cz, cnt = 0.0, 0.0, 0.0, 0
    nx, ny, nz = 0.0, 0.0, 0.0
    for t in range(len(R)):
        g = R[t]
        a, b, c = G[g, 0], G[g, 1], G[g, 2]
        ux, uy, uz = X[b, 0] - X[a, 0], X[b, 1] - X[a, 1], X[b, 2] - X[a, 2]
        wx, wy, wz = X[c, 0] - X[a, 0], X[c, 1] - X[a, 1], X[c, 2] - X[a, 2]
        nx += uy * wz - uz * wy
        ny += uz * wx - ux * wz
        nz += ux * wy - uy * wx
        for k in range(3):
            u = G[g, k]
            if u != v:
                cx += X[u, 0]
                cy += X[u, 1]
                cz += X[u, 2]
                cnt += 1
    out = np.zeros(3)
    if cnt == 0:
        return out
    dx, dy, dz = cx / cnt - X[v, 0], cy / cnt - X[v, 1], cz / cnt - X[v, 2]
    ln = np.sqrt((nx * nx + ny * ny) + nz * nz)
    if ln > 0.0:
        nx, ny, nz = nx / ln, ny / ln, nz / ln
        p = (dx * nx + dy * ny) + dz * nz
        dx, dy, dz = dx - p * nx, dy - p * ny, dz - p * nz
    out[0], out[1], out[2] = dx, dy, dz
    return out


def _candidates(m: Moves, g: int) -> tuple[list, dict]:
    """(length, corner, step, strict) of the moves tried on sliver g, in order: the fixing steps, shortest
    first, then the partial ones (module docstring); and the faces at each free corner."""
    X, G = m.X, m.G
    out, rings = [], {}
    for v in G[g]:
        if not m.free[v]:
            continue
        R = rings[int(v)] = m.ring([v])
        for delta, weak in ((_apex(X, G, g, v), WEAK_STEPS[0]), (_tangential(X, G, R, v), WEAK_STEPS[1])):
            t = _fix_step(X, G, g, v, delta, COS_TARGET)
            if t > 0:
                out.append((t * np.sqrt((delta[0] * delta[0] + delta[1] * delta[1]) + delta[2] * delta[2]),
                            int(v), t * delta, True))
            out += [(np.inf, int(v), s * delta, False) for s in weak]
    out.sort(key=lambda c: (not c[3], c[0]))  # stable: ties keep the corners' and directions' order
    return out, rings


def lift_slivers(m: Moves, moves: int) -> int:
    """At most ``moves`` sliver moves on ``m`` (module docstring); the number made."""
    if moves <= 0 or not m.ok:
        return 0
    X, G = m.X, m.G
    start = m.made
    H = m.worst()[2]  # the samples' largest distance: no move takes a sample to it
    lim = m.limit(RMS_SLACK)
    stamp = np.full(len(X), -1, np.int64)  # the move count after each vertex's last move
    tried = np.full(len(G), -2, np.int64)  # the move count when each sliver was last tried
    for _ in range(PASSES):
        mc = _min_cos(X, G, np.arange(len(G)))
        bad = np.flatnonzero(mc > COS_SLIVER)
        bad = bad[np.argsort(-mc[bad], kind="stable")]  # the thinnest first
        before = m.made
        for g in bad:
            if m.made - start >= moves:
                return m.made - start
            if _min_cos(X, G, np.array([g]))[0] <= COS_SLIVER:
                continue  # a neighbour's move fixed it
            if stamp[G[m.ring(G[g])]].max() <= tried[g]:
                continue  # nothing around it moved since it was last tried
            tried[g] = m.made
            tries, rings = _candidates(m, g)
            shape = {}  # each corner's faces as they are: a move not made leaves them so, bit for bit
            for _, v, step, strict in tries[:TRIES]:
                x1 = m.onto_input(X[v] + step)
                if v not in shape:
                    shape[v] = shape_of(X, G, rings[v])
                if m.attempt({v: x1 - X[v]}, H, lim, (*shape[v], strict), rings[v]):
                    stamp[v] = m.made
                    break
        if m.made == before:
            break
    return m.made - start
