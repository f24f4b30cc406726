"""Exact nearest triangles for many points, compiled: a uniform grid searched in growing shells (numba).

For the re-fit's attachment and the measured distance (`_pipeline.measure`): many points (the input's
vertices and face centroids) against a coarser mesh (the output). `_mesh.nearest` answers the same question
with a KD-tree and numpy blocks, whose per-call overhead dominated at these sizes; here one compiled loop
does all of it.

Grid: cubes of side h over the triangles' bounding box; each triangle is listed in every cube its bounding box
meets. h starts at half the median edge and grows until the grid has at most ``CUBES_PER_FACE`` cubes per
triangle and the listing at most ``PAIRS_PER_FACE`` entries per triangle (a few huge triangles would
otherwise fill millions of cubes).

Query of a point p: the cube c of p's projection p' onto the grid's box, then the shells of cubes at
Chebyshev distance r = 0, 1, 2, ... from c; each triangle met is measured exactly (closest point, Ericson's
regions); after shell r, every point of the box within r·h + w of p' has been seen (w: p''s distance to the
walls of its own cube), and since projecting onto a box never lengthens a distance to a point inside it, a
best distance below that is final. Ties go to the lowest
triangle index, so the answer does not depend on the order of the search. Plain multiplies and adds in a
fixed order (numba fuses none): the same bits on every CPU.
"""
from __future__ import annotations

import threading

import numpy as np

from . import threads
from .box_bounds import face_boxes, used_bounds
from .compiled import njit
from .pointtri import _FLAT_REL

CUBE_EDGE = 0.5  # the cubes' side at first, times the triangles' median edge
PAIRS_PER_FACE = 16  # (triangle, cube) listings per triangle at most, on average
CUBES_PER_FACE = 32  # cubes per triangle at most (the grid's memory)
# ... for a structure that few points query, set up once over many triangles (the input's, which the moves
# after a re-fit query with the output's samples): most of its cubes are empty, and filling and summing
# them cost more than the larger cubes' extra triangles cost those few queries
FEW_QUERIES_CUBES_PER_FACE = 8
MEDIAN_EDGES = 1 << 20  # the cubes' side from the median of at most about this many edges (evenly spaced)
BLOCK = 65_536  # points per query call at most; several blocks run on threads
MIN_BLOCK = 2_048  # ... and at least this many (a thread's hand-off costs about as much as these)


@njit(cache=True, nogil=True)
def _segment_d2(px, py, pz, X, g0, g1):
    """Squared distance from p to the segment (X[g0], X[g1])."""
    ex, ey, ez = X[g1, 0] - X[g0, 0], X[g1, 1] - X[g0, 1], X[g1, 2] - X[g0, 2]
    wx, wy, wz = px - X[g0, 0], py - X[g0, 1], pz - X[g0, 2]
    e2 = ex * ex + ey * ey + ez * ez
    t = 0.0 if e2 == 0.0 else min(max((wx * ex + wy * ey + wz * ez) / e2, 0.0), 1.0)
    qx, qy, qz = wx - t * ex, wy - t * ey, wz - t * ez
    return qx * qx + qy * qy + qz * qz


@njit(cache=True, nogil=True)
def _edges_d2(px, py, pz, X, g0, g1, g2):
    """Squared distance from p to a sliver (`slivers`), as the closest point of its three edges."""
    return min(_segment_d2(px, py, pz, X, g0, g1), _segment_d2(px, py, pz, X, g0, g2),
               _segment_d2(px, py, pz, X, g1, g2))


@njit(cache=True, nogil=True, inline="always")
def _max(a, b):
    """np.maximum of two values: a NaN wins."""
    return a if (a >= b or a != a) else b


@njit(cache=True, nogil=True)
def slivers(X, G):
    """(j,) bool: which triangles G (j,3) over X (k,3) are too thin for Ericson's regions, as `_mesh.pointtri`
    measures them (twice their area under 1e-8 of their longest edge squared: two corners at one point, three
    in a line): `pointtri.flat_triangles`' arithmetic per face, without its (j,3) temporaries (a large
    output's re-fit and search made them every round). tests/test_fixed_order.py compares the two."""
    j = G.shape[0]
    out = np.empty(j, np.bool_)
    for g in range(j):
        i0, i1, i2 = G[g, 0], G[g, 1], G[g, 2]
        b0, b1, b2 = X[i1, 0] - X[i0, 0], X[i1, 1] - X[i0, 1], X[i1, 2] - X[i0, 2]
        c0, c1, c2 = X[i2, 0] - X[i0, 0], X[i2, 1] - X[i0, 1], X[i2, 2] - X[i0, 2]
        n0, n1, n2 = b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0
        e0, e1, e2 = c0 - b0, c1 - b1, c2 - b2
        longest = _max(_max((b0 * b0 + b1 * b1) + b2 * b2, (c0 * c0 + c1 * c1) + c2 * c2),
                       (e0 * e0 + e1 * e1) + e2 * e2)
        t = _FLAT_REL * longest
        out[g] = (n0 * n0 + n1 * n1) + n2 * n2 <= t * t
    return out


@njit(cache=True, nogil=True)
def closest_d2(px, py, pz, X, g0, g1, g2):
    """Squared distance from p to the closest point of triangle (X[g0], X[g1], X[g2]) (Ericson, Real-Time
    Collision Detection 5.1.5: vertex, edge or interior region). Not for a sliver (`_edges_d2`): its
    regions need the triangle's sides apart."""
    ax, ay, az = X[g0, 0], X[g0, 1], X[g0, 2]
    abx, aby, abz = X[g1, 0] - ax, X[g1, 1] - ay, X[g1, 2] - az
    acx, acy, acz = X[g2, 0] - ax, X[g2, 1] - ay, X[g2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    u, v = 0.0, 0.0
    if not (d1 <= 0.0 and d2 <= 0.0):
        bpx, bpy, bpz = px - X[g1, 0], py - X[g1, 1], pz - X[g1, 2]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = px - X[g2, 0], py - X[g2, 1], pz - X[g2, 2]
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        va = d3 * d6 - d5 * d4
        vb = d5 * d2 - d1 * d6
        vc = d1 * d4 - d3 * d2
        if d3 >= 0.0 and d4 <= d3:
            u = 1.0
        elif d6 >= 0.0 and d5 <= d6:
            v = 1.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            u = d1 / (d1 - d3) if d1 - d3 != 0.0 else 0.0
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            v = d2 / (d2 - d6) if d2 - d6 != 0.0 else 0.0
        elif va <= 0.0 and d4 >= d3 and d5 >= d6:
            den = (d4 - d3) + (d5 - d6)
            v = (d4 - d3) / den if den != 0.0 else 0.0
            u = 1.0 - v
        else:
            den = va + vb + vc
            if den == 0.0:
                den = 1.0
            u, v = vb / den, vc / den
    qx = ax + u * abx + v * acx - px
    qy = ay + u * aby + v * acy - py
    qz = az + u * abz + v * acz - pz
    return qx * qx + qy * qy + qz * qz


@njit(cache=True, nogil=True)
def _cell_range(lo, h, n, a, b):
    """The cubes [i0, i1] along one axis that the interval [a, b] meets."""
    i0 = min(max(int(np.floor((a - lo) / h)), 0), n - 1)
    i1 = min(max(int(np.floor((b - lo) / h)), 0), n - 1)
    return i0, i1


@njit(cache=True, nogil=True, inline="always")
def _span(X, G, f, lo, h, dims, ax):
    """The cubes [i0, i1] along axis ``ax`` that triangle f's bounding box meets."""
    a = min(X[G[f, 0], ax], X[G[f, 1], ax], X[G[f, 2], ax])
    b = max(X[G[f, 0], ax], X[G[f, 1], ax], X[G[f, 2], ax])
    return _cell_range(lo[ax], h, dims[ax], a, b)


@njit(cache=True, nogil=True, inline="always")
def _cubes(X, G, f, lo, h, dims):
    """The cubes [i0, i1] × [j0, j1] × [k0, k1] that triangle f's bounding box meets, as (i0, i1, j0, j1, k0,
    k1)."""
    return _span(X, G, f, lo, h, dims, 0) + _span(X, G, f, lo, h, dims, 1) + _span(X, G, f, lo, h, dims, 2)


@njit(cache=True, nogil=True)
def _listing(X, G, lo, h, dims):
    """(pairs count) the (triangle, cube) listings a cube side h gives."""
    total = 0
    for f in range(G.shape[0]):
        r = _cubes(X, G, f, lo, h, dims)
        total += (r[1] - r[0] + 1) * (r[3] - r[2] + 1) * (r[5] - r[4] + 1)
    return total


@njit(cache=True, nogil=True)
def edge_lengths(X, G):
    """(3j,): the lengths of each triangle's sides (corner 0 to 1, 1 to 2, 2 to 0), face by face:
    ``np.sqrt(np.sum((X[G[:, [1, 2, 0]]] - X[G]) ** 2, axis=2)).ravel()`` without its (j,3,3) temporaries and
    numpy's slow sum over a short axis, the same bits (its sum adds the three squares left to right)."""
    j = G.shape[0]
    out = np.empty(3 * j)
    for g in range(j):
        for c in range(3):
            p, q = G[g, c], G[g, (c + 1) % 3]
            dx, dy, dz = X[q, 0] - X[p, 0], X[q, 1] - X[p, 1], X[q, 2] - X[p, 2]
            out[3 * g + c] = np.sqrt((dx * dx + dy * dy) + dz * dz)
    return out


@njit(cache=True, nogil=True)
def _build(X, G, lo, h, dims, start, faces):
    """CSR (``start``, ``faces``) of the triangles listed in each cube (cube id = (i·ny + j)·nz + k), in
    triangle order, into the arrays given: ``start`` (cubes + 1,) zeros, ``faces`` (listings,) (`_listing`).
    A counting sort without scratch: each cube's run is filled from its end, triangles last to first, which
    leaves each run's start one entry up; a shift puts it back. (The cubes outnumber the triangles many times:
    a scratch copy of ``start`` cost more memory than the listing itself.)"""
    ncell = dims[0] * dims[1] * dims[2]
    for f in range(G.shape[0]):
        r = _cubes(X, G, f, lo, h, dims)
        for i in range(r[0], r[1] + 1):
            for j in range(r[2], r[3] + 1):
                for k in range(r[4], r[5] + 1):
                    start[(i * dims[1] + j) * dims[2] + k + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    for f in range(G.shape[0] - 1, -1, -1):  # start[c + 1]: where cube c's run ends, then where it begins
        r = _cubes(X, G, f, lo, h, dims)
        for i in range(r[0], r[1] + 1):
            for j in range(r[2], r[3] + 1):
                for k in range(r[4], r[5] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    start[c + 1] -= 1
                    faces[start[c + 1]] = f
    for c in range(ncell):
        start[c] = start[c + 1]
    start[ncell] = len(faces)


@njit(cache=True, nogil=True, inline="always")
def _face_d2(px, py, pz, X, G, flat, f):
    """Squared distance from p to face f of G: its edges' for a sliver (``flat``), else `closest_d2`."""
    if flat[f]:
        return _edges_d2(px, py, pz, X, G[f, 0], G[f, 1], G[f, 2])
    return closest_d2(px, py, pz, X, G[f, 0], G[f, 1], G[f, 2])


@njit(cache=True, nogil=True, inline="always")
def _gap(x, a, b):
    """Distance from x to the interval [a, b] (0 inside)."""
    return a - x if x < a else (x - b if x > b else 0.0)


@njit(cache=True, nogil=True)
def _query(P, X, G, B, flat, lo, h, dims, start, faces, mark, stamp0, seed):
    """Nearest triangles and squared distances of the points P (module docstring); ``mark``: the index's
    (`grid`), where point p marks the triangles it has measured with ``stamp0`` + p (`stamps`)."""
    q = P.shape[0]
    best_f = np.full(q, -1, np.int64)
    best_d2 = np.full(q, np.inf)
    rmax = max(dims[0], dims[1], dims[2])
    slack = 1e-6 * h  # what a box's distance bound gives up, far above its rounding
    for p in range(q):
        px, py, pz = P[p, 0], P[p, 1], P[p, 2]
        wall = np.inf  # p''s distance to its own cube's walls: what shell 0 alone has covered
        c0 = c1 = c2 = 0
        for ax in range(3):
            x = min(max(P[p, ax], lo[ax]), lo[ax] + dims[ax] * h)  # p' (projection onto the box)
            ci = min(max(int(np.floor((x - lo[ax]) / h)), 0), dims[ax] - 1)
            wall = min(wall, x - (lo[ax] + ci * h), (lo[ax] + (ci + 1) * h) - x)
            if ax == 0:
                c0 = ci
            elif ax == 1:
                c1 = ci
            else:
                c2 = ci
        wall = max(wall, 0.0)
        bf, bd2 = -1, np.inf
        lim2 = np.inf  # (best distance + slack)²: a box farther than this holds nothing as close
        stamp = stamp0 + p
        if len(seed) and seed[p] >= 0:  # a face known to be near: the cubes and boxes beyond it are passed over
            f = seed[p]
            mark[f] = stamp
            bd2 = _face_d2(px, py, pz, X, G, flat, f)
            bf = f
            lim2 = (np.sqrt(bd2) + slack) ** 2
        for r in range(rmax + 1):
            for i in range(max(c0 - r, 0), min(c0 + r, dims[0] - 1) + 1):
                gx = _gap(px, lo[0] + i * h, lo[0] + (i + 1) * h)
                for j in range(max(c1 - r, 0), min(c1 + r, dims[1] - 1) + 1):
                    on_shell_ij = abs(i - c0) == r or abs(j - c1) == r
                    gy = _gap(py, lo[1] + j * h, lo[1] + (j + 1) * h)
                    for k in range(max(c2 - r, 0), min(c2 + r, dims[2] - 1) + 1):
                        if not (on_shell_ij or abs(k - c2) == r):
                            continue
                        cell = (i * dims[1] + j) * dims[2] + k
                        if start[cell] == start[cell + 1]:
                            continue
                        # a cube farther than the best so far can be passed over: each triangle listed in it
                        # is also listed in the cube of its own closest point, which is no farther
                        gz = _gap(pz, lo[2] + k * h, lo[2] + (k + 1) * h)
                        if gx * gx + gy * gy + gz * gz > lim2:
                            continue
                        for t in range(start[cell], start[cell + 1]):
                            f = faces[t]
                            if mark[f] == stamp:
                                continue
                            mark[f] = stamp
                            # the triangle's bounding box first: most listed triangles are farther
                            bx = _gap(px, B[f, 0], B[f, 3])
                            by = _gap(py, B[f, 1], B[f, 4])
                            bz = _gap(pz, B[f, 2], B[f, 5])
                            if bx * bx + by * by + bz * bz > lim2:
                                continue
                            d2 = _face_d2(px, py, pz, X, G, flat, f)
                            if d2 < bd2 or (d2 == bd2 and f < bf):
                                bf, bd2 = f, d2
                                lim2 = (np.sqrt(bd2) + slack) ** 2
            # every box point this close to p' has been seen (less a margin for rounding)
            reach = r * h + wall - 1e-6 * h
            if bf >= 0 and reach > 0 and bd2 < reach * reach:  # strict: none as close lies further out
                break
        best_f[p], best_d2[p] = bf, bd2
    return best_f, best_d2


def grid(X: np.ndarray, G: np.ndarray, cubes_per_face: int = CUBES_PER_FACE) -> tuple:
    """The search structure of the triangles G (j,3), j >= 1, over X (k,3) float64 (module docstring), with
    at most ``cubes_per_face`` cubes per triangle (`FEW_QUERIES_CUBES_PER_FACE` where few points will query it):
    (boxes (j,6), slivers (j,) bool, lo (3,), h, dims (3,), start, faces, mark), the arguments `_query` takes
    after X and G (start and faces int32 where their values fit; ``mark``: which point measured each triangle
    last, and the next free stamp, `stamps`). A caller that moves a few vertices may keep it and query with
    the new positions, boxes and slivers: each triangle whose corners did not move is still listed in every
    cube it meets, so the answer is exact among those (`_pipeline.moves` measures the moved ones itself)."""
    lo, hi = used_bounds(X, G)
    ext = np.maximum(hi - lo, 1e-300)
    step = max(1, 3 * len(G) // MEDIAN_EDGES)  # the cube's side only sets the search's speed, not its answers
    some = G if step == 1 else np.ascontiguousarray(G[::step])
    h = max(CUBE_EDGE * float(np.median(edge_lengths(X, some))), float(ext.max()) * 1e-6)
    while True:
        dims = np.minimum(np.floor(ext / h).astype(np.int64) + 1, 1 << 20)
        if int(np.prod(dims)) <= cubes_per_face * len(G) + 4096:
            listings = _listing(X, G, lo, h, dims)
            if listings <= PAIRS_PER_FACE * len(G):
                break
        h *= 1.25
    start = np.zeros(int(np.prod(dims)) + 1, np.int32 if listings < 2**31 else np.int64)
    faces = np.empty(listings, np.int32 if len(G) < 2**31 else np.int64)
    _build(X, G, lo, h, dims, start, faces)
    mark = np.full(len(G) + 1, -1, np.int64)
    mark[-1] = 0  # the next free stamp
    return face_boxes(X, G), slivers(X, G), lo, h, dims, start, faces, mark  # boxes: (min xyz, max xyz)


_STAMPS = threading.Lock()


def stamps(index: tuple, n: int) -> int:
    """The first of n stamps no query of ``index`` (`grid`) has used: point p of a query marks the triangles
    it has measured with its own, so the index's ``mark`` is made once, not once a query (a query of a few
    points on a large mesh spent its time clearing it). Blocks of one query on threads take disjoint stamps:
    where one block overwrites another's mark, a triangle is measured twice, with the same answer."""
    mark = index[-1]
    with _STAMPS:
        first = int(mark[-1])
        mark[-1] = first + n
    return first


def query_here(X: np.ndarray, G: np.ndarray, index: tuple, P: np.ndarray, seed: np.ndarray):
    """(faces, squared distances) of the points P with ``index``, on this thread (`search` without its
    blocks, for a few points)."""
    return _query(P, X, G, *index, stamps(index, len(P)), seed)


def nearest(X: np.ndarray, G: np.ndarray, P: np.ndarray, seed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(faces (q,) int64, distances (q,) float64): for each point P (q,3), the triangle of G (j,3) over
    vertices X (k,3) nearest to it (the lowest index among equals) and its exact distance. G must not be
    empty. ``seed`` (q,): a face of G likely near each point (-1: none), such as its nearest face before
    the vertices moved a little: its distance bounds the search from the start, so fewer faces are
    measured. The answers are the same with or without it: the search still sees every face as close."""
    X = np.ascontiguousarray(X, np.float64)
    G = np.ascontiguousarray(G, np.int64)
    P = np.ascontiguousarray(P, np.float64).reshape(-1, 3)
    # seeds as int32 (the re-fit's faces are: no copy, one compilation of the query with or without them)
    seed = np.zeros(0, np.int32) if seed is None else np.asarray(seed).reshape(-1)
    if not np.issubdtype(seed.dtype, np.integer):
        raise ValueError(f"nearest: seeds must be face indices (integers), got {seed.dtype}")
    if len(seed) and len(seed) != len(P):
        raise ValueError(f"nearest: {len(seed)} seeds for {len(P)} points")
    if len(seed) and seed.max(initial=-1) >= len(G):
        raise ValueError("nearest: a seed face past the last triangle")
    seed = np.ascontiguousarray(seed, np.int32 if len(G) < 2**31 else np.int64)
    if len(G) == 0:
        raise ValueError("nearest: no triangles")
    if G.min() < 0 or G.max() >= len(X):  # (the compiled loops below read X[G] unchecked)
        raise ValueError("nearest: a triangle's corner is not one of the vertices")
    return search(X, G, grid(X, G), P, seed)


def search(X: np.ndarray, G: np.ndarray, index: tuple, P: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`nearest` of the points P (q,3) float64 with the structure ``index`` (`grid`, kept or made now) and
    seeds (q,) or (0,) int32: the query on threads."""
    # blocks of points on threads (the loop releases the GIL): at least MIN_BLOCK points each, as many as there
    # are threads, at most BLOCK each. Each point's answer is its own: any split gives the same bits (queried
    # in the order of their cubes instead, the search alone is faster but whole runs are not: the points
    # keep their own order; docs/benchmarks.md, "Measured choices inside a run")
    cuts = threads.spans(len(P), MIN_BLOCK, BLOCK)
    first = stamps(index, len(P))
    if len(cuts) <= 1:
        f, d2 = _query(P, X, G, *index, first, seed)
        return f, np.sqrt(d2)

    def query(cut):
        a, b = cut
        return _query(P[a:b], X, G, *index, first + a, seed[a:b])
    parts = threads.blocks(query, cuts)
    return np.concatenate([f for f, _ in parts]), np.sqrt(np.concatenate([d for _, d in parts]))
