"""The shape term of the parallel round's ranking (``quality_threshold``): a contraction that would leave a
badly shaped face waits until nothing cheaper is left near it.

A face's shape is q = 2·area / longest edge² (within a factor of two the sine of its smallest angle; √3/2
for an equilateral triangle). With a threshold s > 0, a pair ranks by max(cost, free cost) · s / q instead
of its cost when q, the smallest shape among its kept faces (those at its endpoints that do not hold both,
the moved corner at the pair's placement) that end worse than they were, is under s. The VCG library
(MeshLab's quadric edge collapse) divides its priority by the smallest quality under its threshold alike,
over every kept face; counting only the faces a move makes worse leaves the pairs around a face the input
made thin as they rank, and kept the Hausdorff distance where counting them all lost it (docs/methods.md).
Nor do faces that were nearly degenerate already (under NEAR_DEGENERATE · s): the long faces of a spike
are, and a spike whose every neighbouring pair waited was contracted away instead.
The free cost is the floor because pairs on flat regions cost about nothing, and a multiple of nothing would
rank them by cost alone (with ``Schedule(free_cost=0)`` such pairs are not lifted).

A round computes the term for the cheapest pairs only (`rerank`): its N candidates under the gate and the
other valid pairs up to the 2N-th cheapest cost. Of those, the N with the smallest shaped keys are the
round's candidates: the round takes as many pairs as the gate on the costs admits, and a pair the term lifts
gives its place to a pair that costs up to twice the round's share more. Near the target the pairs the term
lifts round after round are the cheapest, and so set that gate: those rounds take a pair or two, and a run
takes more rounds than without the term. A gate set without the lifted pairs takes fewer rounds but ranks
worse on the Hausdorff distance (experiments/probes/shape_gate.py): the small rounds keep the last
contractions nearly in order. Nothing is refused: the face target is reached as without the term. The cost
itself (``max_error``, the stats, the record) stays the model's.
"""
from __future__ import annotations

import contextlib

import numpy as np

from .._kernels.batching import DTYPE
from .._mesh import threads
from . import segments
from .._mesh.compiled import njit

# the faces under this fraction of the threshold (at s = 0.4, a smallest angle under about 2-5°) lift nothing:
# faces already nearly degenerate (a spike's, a crease strip's) are not the move's doing; `kept_quality`
NEAR_DEGENERATE = 0.1
SPAN = 2  # the pairs a round shapes: the cheapest SPAN × its candidates (see the module docstring)
MIN_BLOCK = 8192  # pairs a thread shapes at least (fewer: one thread, as handing off costs more)


@njit(cache=True, inline="always")
def _quality(p0x, p0y, p0z, p1x, p1y, p1z, p2x, p2y, p2z):
    """2·area / longest edge² of a triangle (float32; 0 for a point)."""
    ux, uy, uz = p1x - p0x, p1y - p0y, p1z - p0z
    wx, wy, wz = p2x - p0x, p2y - p0y, p2z - p0z
    ex, ey, ez = p2x - p1x, p2y - p1y, p2z - p1z
    nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    twice_area = np.float32(np.sqrt(nx * nx + ny * ny + nz * nz))
    longest2 = max(ux * ux + uy * uy + uz * uz, max(wx * wx + wy * wy + wz * wz, ex * ex + ey * ey + ez * ez))
    return twice_area / longest2 if longest2 > 0 else np.float32(0.0)


@njit(cache=True, inline="always")
def kept_quality(VQ, F, alive, off, cnt, pool, a, b, x, least, cap=np.float32(1.0)):
    """The smallest 2·area / longest² (float32) of the live faces at a or b that do not hold both, with
    their corner a or b at x (VQ (n, ≥3) float32 positions; x (3,) float32), among those that end lower
    than they were and were at least ``least`` (float32) before; ``cap`` where there are none under it (a
    face at or over the cap is not looked at twice). (A face the move
    leaves as poor as it was, or makes better, is not the contraction's doing: without that, every pair
    around a face the input made thin would be lifted, and the run would bend around it. A face that was
    already nearly degenerate, under ``least``, is where a spike or a crease's strip is: lifting every pair at
    it wore the spike away.)"""
    best = cap
    for side in range(2):
        v = a if side == 0 else b
        w = b if side == 0 else a
        for i in range(off[v], off[v] + cnt[v]):
            f = pool[i]
            if not alive[f]:
                continue
            g0, g1, g2 = F[f, 0], F[f, 1], F[f, 2]
            if g0 == w or g1 == w or g2 == w:
                continue
            p0x, p0y, p0z = (x[0], x[1], x[2]) if g0 == v else (VQ[g0, 0], VQ[g0, 1], VQ[g0, 2])
            p1x, p1y, p1z = (x[0], x[1], x[2]) if g1 == v else (VQ[g1, 0], VQ[g1, 1], VQ[g1, 2])
            p2x, p2y, p2z = (x[0], x[1], x[2]) if g2 == v else (VQ[g2, 0], VQ[g2, 1], VQ[g2, 2])
            q = _quality(p0x, p0y, p0z, p1x, p1y, p1z, p2x, p2y, p2z)
            if q >= best:
                continue
            before = _quality(VQ[g0, 0], VQ[g0, 1], VQ[g0, 2], VQ[g1, 0], VQ[g1, 1], VQ[g1, 2],
                              VQ[g2, 0], VQ[g2, 1], VQ[g2, 2])
            if q < before and before >= least:
                best = q
    return best


@njit(cache=True, nogil=True)
def _shape_rows(out, key, rows, floor, E, X, VQ, F, alive, off, cnt, pool, s):
    """`shaped_keys` of the pairs ``rows`` into ``out``."""
    tiny = s * np.float32(1e-6)
    least = s * np.float32(NEAR_DEGENERATE)
    for i in rows:
        q = kept_quality(VQ, F, alive, off, cnt, pool, E[i, 0], E[i, 1], X[i], least, s)  # s: not lifted
        if q < s:
            lo = floor[i if len(floor) > 1 else 0]
            out[i] = (key[i] if key[i] >= lo else lo) * (s / (q if q > tiny else tiny))


def shaped_keys(key, which, floor, E, X, VQ, F, alive, off, cnt, pool, s):
    """A copy of the float32 keys (P,) with the shape term (module docstring) on the pairs ``which``:
    max(key, floor) · s / q where their kept faces' smallest q is under s (q floored at s·1e-6: a face that
    collapses ranks last, the flip test refuses it anyway). ``floor``: (1,) or one per pair. Each pair's
    key is its own: blocks of at least MIN_BLOCK pairs run on threads, with the same bits."""
    out = key.copy()
    rows = np.flatnonzero(which)

    def block(cut):
        _shape_rows(out, key, rows[cut[0]:cut[1]], floor, E, X, VQ, F, alive, off, cnt, pool, s)
    threads.blocks(block, threads.spans(len(rows), MIN_BLOCK))
    return out


def rerank(key, valid, cand, free, E, X, VQ, faces, s: float, starts=None):
    """The round's shaped keys (P,) float32 and its candidates (module docstring): per copy (pairs
    starts[c] … starts[c+1] − 1; None: one run), as many as it had: those under their free cost that the term
    leaves as they were, then the smallest shaped keys among the other candidates and the valid pairs up to
    the SPAN·N-th cheapest. ``free``: the free cost, a scalar or per
    pair; ``faces``: the run's `FaceLists`. The same pairs get the same keys alone and in a batch: the
    thresholds are order statistics of each copy's own pairs. Two compiled passes around the shaping
    (`_shaped_rows`, `_chosen`): a small mesh's round is a few thousand pairs, where a dozen numpy calls a
    round cost more than the arithmetic."""
    key = np.ascontiguousarray(key, DTYPE)
    starts = np.array([0, len(key)], np.int64) if starts is None else np.ascontiguousarray(starts, np.int64)
    valid, cand = np.ascontiguousarray(valid, bool), np.ascontiguousarray(cand, bool)
    floor = np.atleast_1d(np.asarray(free, DTYPE))
    mesh = (E, X, VQ, faces.F, faces.alive, faces.off, faces.cnt, faces.pool, np.float32(s))
    if len(key) < MIN_BLOCK:  # one thread shapes them all: the three steps in one call
        return _rerank_one(key, valid, cand, starts, floor, *mesh)
    n, which = _shaped_rows(key, valid, cand, starts)
    shaped = shaped_keys(key, which, floor, *mesh)
    return shaped, _chosen(key, shaped, cand, which, floor, starts, n)


@njit(cache=True, nogil=True)
def _rerank_one(key, valid, cand, starts, floor, E, X, VQ, F, alive, off, cnt, pool, s):
    """`rerank`'s three steps in one compiled call, the shaping on this thread."""
    n, which = _shaped_rows(key, valid, cand, starts)
    shaped = key.copy()
    _shape_rows(shaped, key, np.flatnonzero(which), floor, E, X, VQ, F, alive, off, cnt, pool, s)
    return shaped, _chosen(key, shaped, cand, which, floor, starts, n)


@njit(cache=True, nogil=True)
def _shaped_rows(key, valid, cand, starts):
    """(each copy's candidates (C,), the rows the term shapes (P,) bool): of each copy with candidates (n of
    them), its valid pairs up to the min(SPAN·n, valid)-th smallest key (`segments.kth`), and its candidates."""
    C = len(starts) - 1
    n = np.zeros(C, np.int64)
    span = np.zeros(C, np.int64)
    for c in range(C):
        nc = m = 0
        for i in range(starts[c], starts[c + 1]):
            nc += cand[i]
            m += valid[i]
        n[c] = nc
        if nc > 0 and m > 0:
            span[c] = min(SPAN * nc, m)
    widest = segments.kth(key, valid, starts, span)
    which = np.zeros(len(key), np.bool_)
    for c in range(C):
        if span[c] > 0:
            for i in range(starts[c], starts[c + 1]):
                which[i] = valid[i] and (key[i] <= widest[c] or cand[i])
    return n, which


@njit(cache=True, nogil=True)
def _chosen(key, shaped, cand, which, floor, starts, n):
    """The round's candidates (P,) bool: per copy, the candidates under their free cost (``floor``: (1,) or one
    per pair) that the term left as they were, then of the other shaped rows the rest of its n places, by
    the smallest shaped keys (`segments.kth`; ties at the cut all in)."""
    C = len(starts) - 1
    out = np.zeros(len(key), np.bool_)
    others = np.zeros(len(key), np.bool_)
    rest = np.zeros(C, np.int64)
    one = len(floor) == 1
    for c in range(C):
        # the candidates under their own free cost that the term did not lift stay (with parts of several
        # sizes the free cost is each part's, so they need not be the cheapest); the rest go by shaped key
        kept = 0
        for i in range(starts[c], starts[c + 1]):
            out[i] = cand[i] and shaped[i] == key[i] and key[i] <= (floor[0] if one else floor[i])
            kept += out[i]
            others[i] = which[i] and not out[i]
        rest[c] = max(n[c] - kept, 0)  # none left: no k-th, so no other row comes in
    cut = segments.kth(shaped, others, starts, rest)
    for c in range(C):
        if rest[c] > 0:
            for i in range(starts[c], starts[c + 1]):
                if others[i] and shaped[i] <= cut[c]:
                    out[i] = True
    return out


@contextlib.contextmanager
def ranking(st, run, valid, cand, free, starts=None):
    """The round's candidates, with ``st.key`` the keys its selection passes and their order read: with the
    run's ``quality_threshold``, the shaped keys and the candidates `rerank` takes, else the keys and
    candidates as they are. The cost keys are back in ``st.key`` afterwards (the record and the next round
    read them), also when the passes fail."""
    cost_key = st.key
    s = run.options.quality_threshold
    if s:
        st.key, cand = rerank(st.key, valid, cand, free, st.E, st.x, run.VQ, run.faces, s, starts)
    try:
        yield cand
    finally:
        st.key = cost_key
