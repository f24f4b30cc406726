"""Kept attributes (wedges, `_mesh.wedges.Tracker`) in the greedy queue's verified batches (`speculate`):
the seam rule, the wedge updates and the pricing of pairs at seam vertices, where and as the one-at-a-time
loop (`loop._run`) applies them, with every change journaled so that a batch's undo restores it.

The loop calls the tracker at three points, all of which read or change the corners' wedges ``C``, the
wedge values ``val`` and the seam flags ``multi`` (`seam_rule.modes` narrows a vertex's flag to whether it
has two or more wedges now; a flag set on a vertex with no faces left changes how its pairs are priced, so
the flags follow the loop's exactly):

* at a push (the pairs re-priced after a contraction, and the first push of all pairs): `constrain`, which
  places a pair touching a seam vertex at its allowed endpoint of smaller price. The batches call
  `seam_rule.modes` at the same moment (`push_modes`, right after the step's contraction on the host) and
  keep its answer (`mode`); the endpoint price needs the kept vertex's merged row, so it is computed after
  the batch's merge call, from each stale interval's own rows (`constrain_rows`). A blocked pair that comes
  back around the contraction is priced at once (its rows are current): its stored price before the
  constraint (``R``: position and cost after `_locks.adjust`) with the constraint of now (`reprice`);
* at the pop: the seam rule (`seam_ok`, `wedges.Tracker.allowed`), between the lock rule and the flip test;
* at the contraction, before the faces relink: the corners' wedges and the kept wedge's value
  (`contract`, `wedges.Tracker.contract`).

Journal rows (``J``, as `speculate` writes them: kind, index, old, old): `J_MULTI` (vertex, old flag),
`J_WC` (face, corner, old wedge), `J_VAL` (wedge, row of ``VJ`` holding its old value)."""
from __future__ import annotations

import numpy as np

from ..._mesh import seam_rule as wj
from ..._mesh.compiled import njit
from ..rules import seam_allows

J_MULTI, J_WC, J_VAL = 8, 9, 10  # journal kinds (after `speculate`'s)
KEEP_A, KEEP_B = 1, 2  # mode bits: keeping the pair's first (second) vertex is allowed
FREE = -1  # the mode of a pair of single-wedge vertices (no constraint; nor is there with mode 0: none allowed)
M32 = 0xFFFFFFFF


@njit(cache=True, inline="always")
def _jw(J, ctr, jl, kind, i, o0, o1):
    j = ctr[jl]
    J[j, 0], J[j, 1], J[j, 2], J[j, 3] = kind, i, o0, o1
    ctr[jl] = j + 1


@njit(cache=True)
def fit(TS, need):
    """The integer scratch of `seam_rule` (12 rows) with room for face lists of ``need``."""
    if TS.shape[1] >= need:
        return TS
    return np.empty((12, 2 * need), np.int64)


@njit(cache=True)
def modes(T, alive, fs, fl, fpool, C, multi, a, b, TS, J, ctr, jl):
    """`seam_rule.modes` of the pair (a, b) on the batch's face lists, its flag changes journaled; returns
    the pair's mode (`FREE`, or `KEEP_A` | `KEEP_B` where allowed). TS: room for fl[a], fl[b]."""
    ma, mb = multi[a], multi[b]
    free, nba, nab, _, _ = wj.modes(T, alive, fl, fs, fpool, C, multi, a, b, TS)
    if multi[a] != ma:
        _jw(J, ctr, jl, J_MULTI, a, 1 if ma else 0, 0)
    if multi[b] != mb:
        _jw(J, ctr, jl, J_MULTI, b, 1 if mb else 0, 0)
    if free:
        return FREE
    return (KEEP_A if nba >= 0 else 0) | (KEEP_B if nab >= 0 else 0)


@njit(cache=True)
def seam_ok(T, alive, fs, fl, fpool, C, multi, VQ, a, b, x, TS, J, ctr, jl):
    """`wedges.Tracker.allowed` for contracting b into a at x (x: VQ's dtype). TS: room for fl[a], fl[b]."""
    if not (multi[a] or multi[b]):
        return True
    mode = modes(T, alive, fs, fl, fpool, C, multi, a, b, TS, J, ctr, jl)
    return seam_allows(mode == FREE, (mode & KEEP_A) != 0, (mode & KEEP_B) != 0, VQ, a, b, x)


@njit(cache=True)
def contract(T, alive, fs, fl, fpool, C, val, multi, VQ, a, b, x, x64, m_solved, solved, weights, frozen, TS, W,
             VJ, slot, J, ctr, jl):
    """`wedges.Tracker.contract` for b into a at x (VQ's dtype; x64 the same in float64; ``frozen``: the
    locked vertices, whose wedges keep their values), before the faces
    relink, journaled: the flags of a and b, the wedge of each live corner at a and at b, and the value of
    a's wedge when it has one (the only value the update can change) in VJ[slot]. Returns False where the
    seam rule refuses it (the rules ran before: never). TS: room for fl[a], fl[b]."""
    _jw(J, ctr, jl, J_MULTI, a, 1 if multi[a] else 0, 0)
    _jw(J, ctr, jl, J_MULTI, b, 1 if multi[b] else 0, 0)
    one, wa = True, -1
    for v in (a, b):
        for i in range(fs[v], fs[v] + fl[v]):
            f = fpool[i]
            if alive[f]:
                k = wj._corner_of(T, f, v)
                _jw(J, ctr, jl, J_WC, f, k, C[f, k])
                if v == a:
                    if wa >= 0 and C[f, k] != wa:
                        one = False
                    wa = C[f, k]
    if one and wa >= 0:
        VJ[slot] = val[wa]
        _jw(J, ctr, jl, J_VAL, wa, slot, 0)
    return wj._contract(T, alive, fl, fs, fpool, C, val, multi, VQ, a, b, x64, x, m_solved, solved, weights, frozen,
                        TS, W)


@njit(cache=True)
def undo_one(kind, i, o0, o1, C, val, multi, VJ):
    """One journal row of the kinds above, undone."""
    if kind == J_MULTI:
        multi[i] = o0 != 0
    elif kind == J_WC:
        C[i, o0] = o1
    else:
        val[i] = VJ[o0]


@njit(cache=True)
def place(VQ, ra, rb, mode, m, W):
    """`seam_rule.constrain`'s placement (`seam_rule.endpoint`) of a pair whose rows are ra, rb (its first
    and second vertex) and whose mode (> 0) allows keeping one of them: (row of the endpoint taken, its price)."""
    return wj.endpoint(VQ, ra, rb, (mode & KEEP_A) != 0, (mode & KEEP_B) != 0, m, W)


@njit(cache=True)
def constrain_rows(VQ, rows, mode, x, cost, m):
    """`wedges.Tracker.constrain` of pairs whose rows are ``rows`` (k,2) (each interval's versions) with the
    modes taken when they were pushed: x (k,3) and cost (k,) in place."""
    W = np.empty((4, max(m, 1)))
    for i in range(len(rows)):
        if mode[i] <= 0:
            continue
        v, c = place(VQ, rows[i, 0], rows[i, 1], mode[i], m, W)
        for k in range(3):
            x[i, k] = VQ[v, k]
        cost[i] = c


@njit(cache=True)
def ordered_bits(c):
    """`batches.ordered_bits` of one float32."""
    buf = np.empty(1, np.float32)
    buf[0] = c + np.float32(0.0)
    u = np.uint64(buf.view(np.uint32)[0])
    if u >> np.uint64(31):
        return ~u & np.uint64(M32)
    return u | np.uint64(0x80000000)


@njit(cache=True)
def reprice(s, u, w, mode, VQ, K, X, cost, R, has_locks, locked, m, W):
    """Stamp s of the pair (u, w) priced as a push prices it now: its price before the constraint (R[s]),
    placed by ``mode``, a locked first vertex pinned (`_locks.pin`); its key's cost bits updated."""
    X[s, 0], X[s, 1], X[s, 2], cost[s] = R[s, 0], R[s, 1], R[s, 2], R[s, 3]
    if mode > 0:
        v, c = place(VQ, u, w, mode, m, W)
        X[s, 0], X[s, 1], X[s, 2] = VQ[v, 0], VQ[v, 1], VQ[v, 2]
        cost[s] = c
    if has_locks and locked[u]:
        X[s, 0], X[s, 1], X[s, 2] = VQ[u, 0], VQ[u, 1], VQ[u, 2]
    K[s, 0] = (ordered_bits(cost[s]) << np.uint64(32)) | (K[s, 0] & np.uint64(M32))
