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

from .._mesh.compiled import njit
from .fit_rules import COS_SLIVER, SLIVER_DEG, _min_cos
from .._mesh.grid_nearest import stamps
from .moves import Moves, _failed, _onto, _ring, _trial, shape_of

TARGET_DEG = SLIVER_DEG + 0.5  # the smallest angle a fixing step aims at: a margin for the move onto the input
RMS_SLACK = 0.03  # the two-way rms may rise this much (a fraction) over the re-fit's, the polish's included
WEAK_STEPS = ((0.125,), (0.5, 0.125))  # partial steps toward the apex and toward the neighbours' mean
PASSES = 4  # passes over the slivers at most
TRIES = 6  # moves tried on one sliver in one pass at most
COS_TARGET = float(np.cos(np.radians(TARGET_DEG)))
MADE, TRIED, ON_SLIVER = 0, 1, 2  # what a sliver's compiled tries ended with (`_try_sliver`)


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


@njit(cache=True, nogil=True)
def _add(corner, step, strict, length, n, X, G, g, v, delta, weak):
    """Append corner v's moves along ``delta`` to the candidates from row n: its fixing step, if one
    reaches the target, then the partial steps ``weak``; returns the next free row."""
    t = _fix_step(X, G, g, v, delta, COS_TARGET)
    if t > 0:
        corner[n], strict[n] = v, True
        length[n] = t * np.sqrt((delta[0] * delta[0] + delta[1] * delta[1]) + delta[2] * delta[2])
        for c in range(3):
            step[n, c] = t * delta[c]
        n += 1
    for s in weak:
        corner[n] = v
        for c in range(3):
            step[n, c] = s * delta[c]
        n += 1
    return n


@njit(cache=True, nogil=True)
def _candidates(X, G, g, free, ring_start, ring_face):
    """The moves tried on sliver g, in order (module docstring): the fixing steps, shortest first, then the
    partial ones, ties in the corners' and directions' order, as (corner, step, strict) arrays."""
    most = 3 * (2 + len(WEAK_STEPS[0]) + len(WEAK_STEPS[1]))
    corner = np.empty(most, np.int64)
    step = np.empty((most, 3))
    strict = np.zeros(most, np.bool_)
    length = np.full(most, np.inf)
    n = np.int64(0)  # (not the literal 0: one compiled `_add`)
    for k in range(3):
        v = G[g, k]
        if free[v]:
            apex, tangential = _apex(X, G, g, v), _tangential(X, G, _ring(ring_start, ring_face, np.array([v])), v)
            n = _add(corner, step, strict, length, n, X, G, g, v, apex, WEAK_STEPS[0])
            n = _add(corner, step, strict, length, n, X, G, g, v, tangential, WEAK_STEPS[1])
    # a stable sort by (not strict, length), by insertion: the fixing steps first, shortest first
    order = np.arange(n)
    for i in range(1, n):
        j, o = i, order[i]
        while j > 0:
            p = order[j - 1]
            if not ((strict[o] and not strict[p]) or (strict[o] == strict[p] and length[o] < length[p])):
                break
            order[j] = p
            j -= 1
        order[j] = o
    return corner[order], step[order], strict[order]


@njit(cache=True, nogil=True)
def _try_sliver(g, first, free, H, lim, stamp, state):
    """Sliver g's moves (`_candidates`) from the ``first``-th, at most TRIES in all, each put onto the input
    and tested (`moves._trial`, the faces at its corner as they are), compiled: (what happened: MADE, TRIED
    (none passed) or ON_SLIVER (the input point nearest to candidate k lies on a sliver face of the input,
    which `Moves.onto_input` measures by its edges), k, its corner, step and strictness, `_trial`'s answer).
    ``stamp``: the first of `stamps_needed` search stamps."""
    (X, G, n0, cos_max, agreed, source_normals, q0, min_quality, oB, oflat, P, fa, hit, start, order, head, link,
     ring_start, ring_face, vrow, nu, W, V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, src, w, d, e, qw,
     s_in, s_out, sq, sw) = state
    corner, step, strict = _candidates(X, G, g, free, ring_start, ring_face)
    passed = _failed()
    k = first
    while k < min(TRIES, len(corner)):
        v = corner[k]
        x = np.empty(3)
        for c in range(3):
            x[c] = X[v, c] + step[k, c]
        found, y, _ = _onto(x, V, F, iB, iflat, ilo, ih, idims, istart, ifaces, imark, stamp)
        stamp += 1
        if not found:
            return ON_SLIVER, k, v, step[k], strict[k], passed
        R = _ring(ring_start, ring_face, np.array([v]))
        count0, worst0 = shape_of(X, G, R)
        moved = np.empty((1, 3))
        for c in range(3):
            moved[0, c] = y[c] - X[v, c]
        passed = _trial(np.array([v]), moved, R, count0, worst0, strict[k], H, lim, stamp, state)
        stamp += 1 + len(W) * len(R)
        if passed[0]:
            return MADE, k, v, step[k], strict[k], passed
        k += 1
    return TRIED, k, -1, np.zeros(3), False, passed


def stamps_needed(m: Moves, g: int) -> int:
    """Search stamps `_try_sliver` takes at most on sliver g: per try one for the point onto the input and one
    per output sample the move changes."""
    corners = m.G[g]
    most = int((m.ring_start[corners + 1] - m.ring_start[corners]).max())
    return TRIES * (2 + m.nb * most)


def lift_slivers(m: Moves, moves: int) -> int:
    """At most ``moves`` sliver moves on ``m`` (module docstring); the number made."""
    if moves <= 0 or not m.ok:
        return 0
    X, G = m.X, m.G
    start = m.made
    H = float(m.worst()[2])  # the samples' largest distance: no move takes a sample to it
    lim = float(m.limit(RMS_SLACK))
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
            k = 0
            while k < TRIES:
                what, k, v, step, strict, passed = _try_sliver(
                    int(g), k, m.free, H, lim, stamps(m.into, stamps_needed(m, g)), m.state())
                if what == ON_SLIVER:  # this one try in Python, then on from the next
                    R = m.ring([v])
                    x1 = m.onto_input(X[v] + step)
                    if m.attempt({v: x1 - X[v]}, H, lim, (*shape_of(X, G, R), bool(strict)), R):
                        stamp[v] = m.made
                        break
                    k += 1
                    continue
                if what == MADE:
                    m.commit(m.ring([v]), passed)
                    stamp[v] = m.made
                break
        if m.made == before:
            break
    return m.made - start
