"""The parallel round's selection passes with validation as one compiled loop (numba), and when a run takes it.

The numpy stages (`parallel.StagedRound`) spend a round in hundreds of numpy calls on small arrays; the same
steps as loops over integer arrays (this one and `contraction`'s) take a small fraction of that
(docs/benchmarks.md). They serve the common case (`fits`): manifold mode with the pairs updated through the
contractions (no non-edge pairs), at most `MAX_FACES` faces (kept attributes' seam rule runs inside, through
`seam_rule`, and locked vertices' rule, `rules.stranded_by_pass`). They make exactly the choices of the numpy
stages they replace (`select.independent_sets` with `parallel.StagedRound.validate`): the golden outputs are
the same bits, and tests/test_round_loops.py compares each loop with the numpy code on random meshes.

`select_validate` runs the independent-set passes (each pair that holds the smallest key among the candidates
touching its endpoints' closed 1-rings), each selected pair's rules (link condition, coincident faces, the
part rule, the locks' rule, the seam rule, the flip test with the device kernel's float32 operations,
`rules.flips`), the locking of accepted 1-rings and each copy's pass rule (`select._copies_staying`; one run
is one copy).

A vertex's neighbours are read from its faces: in this mode every pair is an edge of a live face, and every
such edge is a pair (the edge update keeps exactly those).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..._mesh import seam_rule
from .. import rules as rule
from ..._mesh.compiled import njit
from ..outcome import COINCIDENT, FLIP, LOCKED, PART, SEAM, TOPOLOGY

NO_KEY = np.iinfo(np.int64).max
_SCRAMBLE = np.uint32(0x9E3779B1)


class Mesh(NamedTuple):
    """What `_rules` reads of the mesh besides its faces: positions VQ (n, ≥3), the input faces' reference
    normals N0, which vertices are on a boundary and each vertex's degree."""
    VQ: Any
    N0: Any
    bvert: Any
    deg: Any


class Limits(NamedTuple):
    """The flip test's limits (float32 cos_max, and ``shape``: `rules.flips`' float32 (collapse,
    min_quality)) and whether parts are kept."""
    cos_max: Any
    shape: Any
    keep_parts: bool


class Seams(NamedTuple):
    """Kept attributes: the wedge of each face corner (m,3) and the seam vertices (n,) ((0,3) and all False
    without attributes)."""
    corner_wedge: Any
    multi: Any


class Locks(NamedTuple):
    """Locked vertices (n,) bool (empty: none) and ``partner`` (n,): each selected pair's endpoints name
    each other in a pass, -1 elsewhere (`rules.stranded_by_pass`)."""
    locked: Any
    partner: Any


class Scratch(NamedTuple):
    """`_rules`' working arrays: ``mark`` (n,) zeros, left so (a's neighbours marked 1, common ones 2 while a
    pair is tested); nb, fk, fc (≥ the faces at a and b): a's neighbours, the faces that stay and their
    moving corners; T (12, ≥ the faces at a and b): the seam rule's."""
    mark: Any
    nb: Any
    fk: Any
    fc: Any
    T: Any


class Pairs(NamedTuple):
    """A round's pairs for `select_validate`: E (P,2), their face counts ecount (P,), the candidates cand (P,)
    bool, the float32 bits of each pair's ranking key kbits (P,) int32, each pair's index within its copy
    ``local`` (P,) and its placement X (P,3)."""
    E: Any
    ecount: Any
    cand: Any
    kbits: Any
    local: Any
    X: Any


class Passes(NamedTuple):
    """The copies and the passes: each vertex's copy vcopy (n,), each copy's face budget need (C,), the round's
    scramble ``salt``, and the schedule's max_passes and pass_yield."""
    vcopy: Any
    need: Any
    salt: Any
    max_passes: Any
    pass_yield: Any


class Work(NamedTuple):
    """`select_validate`'s working arrays: free, active (n,) bool and mark (n,) int32 zeros (free comes back
    with the locked vertices False); keys (≥ P,) int64, rows (2, ≥ P) int32 and verts (2, n) int64, kept from
    round to round (fresh arrays this large would be mapped and faulted in anew on every call)."""
    free: Any
    active: Any
    mark: Any
    keys: Any
    rows: Any
    verts: Any


MAX_FACES = 1 << 18  # runs on more faces keep the numpy stages: see `fits`


def fits(manifold: bool, incremental: bool, locks, faces: int) -> bool:
    """Whether a run's rounds take the compiled loops: the mode of the module docstring, on at most
    `MAX_FACES` faces. Both give the same bits; the choice is speed alone. The loops test one pair after
    another, and on a large mesh each pair's faces are cache misses that wait in turn, where numpy's
    whole-array gathers keep many in flight (and share the round with a worker thread): the loops win on small
    and mid-sized meshes and lose on meshes of millions of faces, with the same bits
    (`python experiments/probes/round_paths.py`; the figures in docs/benchmarks.md).

    ``locks`` (a `locks.RunLocks` or None) does not change the answer: locked vertices' rule runs inside the
    loops (`_rules`), and the prices' part of them (`locks.adjust`, pairs of two locked vertices,
    seam placements pinned at a locked vertex) is applied around the compiled calls (`parallel.LoopRound`), with
    the same bits as the numpy stages (tests/test_locks_compiled.py). The parameter stays so that callers
    need not know."""
    return manifold and incremental and faces <= MAX_FACES


@njit(cache=True, inline="always")
def _key(kbits, idx, local, salt):
    """`select.sort_keys` of one pair: its key's float32 bits over a scramble of its index in its copy."""
    h = (np.uint32(local) * _SCRAMBLE + np.uint32(salt)) & np.uint32(0xFFFFFFFF)
    return (np.int64(kbits[idx]) << 32) | np.int64(h)


@njit(cache=True, inline="always")  # once per selected pair: inlined, the loop passes it no bundles of arrays
def _rules(a, b, nf, x, faces, mesh, limits, seams, locks, scratch, apex, s):
    """The rule pair (a, b) with nf faces breaks (0: none), as `parallel.StagedRound.validate` decides it in
    manifold mode: coincident faces after the contraction, then the part rule, then the link condition
    override each other in that order; the locks' rule, the seam rule and then the flip test count only
    for a pair that passes the rest.
    Writes the pair's apexes (its first two common neighbours by vertex id, -1 where fewer) to apex[s].
    The bundles: ``faces`` (`rules.Faces`), ``mesh`` (`Mesh`), ``limits`` (`Limits`), ``seams`` (`Seams`),
    ``locks`` (`Locks`), ``scratch`` (`Scratch`)."""
    F, alive, off, cnt, pool = faces
    VQ, N0, bvert, deg = mesh
    cos_max, shape, keep_parts = limits
    C, multi = seams
    locked, partner = locks
    mark, nb, fk, fc, T = scratch
    # one scan of each endpoint's faces: the link condition (the common neighbours are the apexes of the
    # pair's faces) and the faces that stay (not holding both endpoints), each with the corner that moves
    ka = nk = 0
    for i in range(off[a], off[a] + cnt[a]):  # a's neighbours marked 1; a's faces without b kept
        f = pool[i]
        if not alive[f]:
            continue
        g0, g1, g2 = F[f, 0], F[f, 1], F[f, 2]
        for u in (g0, g1, g2):
            if u != a and mark[u] != 1:
                mark[u] = 1
                nb[ka] = u
                ka += 1
        if g0 != b and g1 != b and g2 != b:
            fk[nk], fc[nk] = f, 0 if g0 == a else (1 if g1 == a else 2)
            nk += 1
    nka = nk  # the first nka kept faces are a's
    ncommon = 0
    c0, c1 = -1, -1
    bad_apex = False
    stranded = False  # a locked third vertex of a face that dies would be left in no face
    for i in range(off[b], off[b] + cnt[b]):
        f = pool[i]
        if not alive[f]:
            continue
        g0, g1, g2 = F[f, 0], F[f, 1], F[f, 2]
        if len(locked) and (g0 == a or g1 == a or g2 == a):  # a face that dies: its third vertex
            c = g0 if (g0 != a and g0 != b) else (g1 if (g1 != a and g1 != b) else g2)
            if locked[c] and not stranded:
                stranded = rule.stranded_by_pass(c, F, alive, cnt, off, pool, partner)
        for u in (g0, g1, g2):
            if u != b and u != a and mark[u] == 1:
                mark[u] = 2  # counted once
                ncommon += 1
                if c0 < 0 or u < c0:
                    c0, c1 = u, c0
                elif c1 < 0 or u < c1:
                    c1 = u
                if nf == 2 and deg[u] <= 3:
                    bad_apex = True
        if g0 != a and g1 != a and g2 != a:
            fk[nk], fc[nk] = f, 0 if g0 == b else (1 if g1 == b else 2)
            nk += 1
    for i in range(ka):  # the marks of a's neighbours, undone
        mark[nb[i]] = 0
    apex[s, 0], apex[s, 1] = c0, c1
    linked = rule.link_holds(nf, ncommon, bvert[a] and bvert[b], bad_apex)
    # coincident faces: only asked of a pair that passes the link condition (one that fails is refused for
    # that, whatever else holds); no two live faces share three corners (the input has none, and this rule
    # keeps it so), so only the apexes' faces can coincide
    gone = linked and nf == 2 and rule.coincide_at_apexes(F, fk, nka, fk[nka:], nk - nka, c0, c1)
    why = 0
    if gone:
        why = COINCIDENT
    if rule.part_vanishes(keep_parts, nk):
        why = PART
    if not linked:
        why = TOPOLOGY
    if why == 0 and len(locked) and (rule.locked_endpoint_bare(nk, locked, a, b) or stranded):
        why = LOCKED
    if why == 0 and (multi[a] or multi[b]):  # kept attributes: the seam rule
        free, nba, nab, _, _ = seam_rule.modes(F, alive, cnt, off, pool, C, multi, a, b, T)
        if not rule.seam_allows(free, nba >= 0, nab >= 0, VQ, a, b, x):
            why = SEAM
    if why == 0:
        for i in range(nk):
            if rule.flips(VQ, N0, F, fk[i], fc[i], x, cos_max, shape):
                why = FLIP
                break
    return why


@njit(cache=True)
def select_validate(pairs, passes, faces, mesh, limits, seams, locks, work):
    """`select.independent_sets` with `parallel.StagedRound.validate` (manifold mode), on the round's pairs
    (`Pairs`; the rejected candidates are cleared in ``pairs.cand``), its copies and passes (`Passes`), the
    faces (`rules.Faces`, `FaceLists`' arrays), the mesh (`Mesh`, with the placements in ``pairs.X``), the flip
    test's limits, the seams, the locks and the working arrays (`Work`; ``free`` comes back with the locked
    vertices False). Returns (accepted pair indices in pass order, their apexes (S,2), the rejected indices
    and their rules)."""
    E, ecount, cand, kbits, local, X = pairs
    vcopy, need, salt, max_passes, pass_yield = passes
    free, active, mark, keys, rows, verts = work
    cnt = faces.count
    locked, partner = locks
    P = len(E)
    n = len(vcopy)
    C = len(need)
    K, one, bo = keys, rows[0], rows[1]  # each pair's key (NO_KEY: not a candidate, or rejected)
    m1, m2 = verts[0], verts[1]
    ncand = 0
    for i in range(P):
        if cand[i]:
            ncand += 1
            K[i] = _key(kbits, i, local[i], salt)
            active[E[i, 0]] = True
            active[E[i, 1]] = True
        else:
            K[i] = NO_KEY
    # the working set: pairs with an available endpoint (ascending), and those with both (``bo``); listed
    # without a branch (about half the pairs are in it, in no pattern a branch predictor learns). The
    # candidates among ``bo`` (``cl``, ascending) are the only pairs with a key: the passes take each pair's
    # smallest key and select from them alone, and the pairs of ``bo`` carry those minima to the neighbours
    cl = np.empty(ncand + 1, np.int64)  # (+ 1: the listing below writes one row past the last candidate)
    k1 = nbo = ncl = 0
    for i in range(P):
        pa, pb = active[E[i, 0]], active[E[i, 1]]
        one[k1] = i
        k1 += pa | pb
        bo[nbo] = i
        nbo += pa & pb
        cl[ncl] = i
        ncl += cand[i]
    acc = np.empty(ncand, np.int64)
    apex = np.empty((ncand, 2), np.int64)
    rej = np.empty(ncand, np.int64)
    why = np.empty(ncand, np.int8)
    sel = np.empty(ncand, np.int64)
    n_acc = np.zeros(C, np.int64)
    g = np.zeros(C, np.int64)
    tried = np.zeros(C, np.bool_)
    out = np.zeros(C, np.bool_)
    done = np.zeros(C, np.bool_)
    nb = np.empty(64, np.int64)
    fk, fc = np.empty(64, np.int64), np.empty(64, np.int64)
    T = np.empty((12, 64), np.int64)  # the seam rule's scratch
    na = nr = 0
    for p in range(max_passes):
        # each available vertex's smallest key among its pairs (m1), then among its neighbours' (m2)
        if ncl == 0:
            break
        for j in range(nbo):
            i = bo[j]
            u, v = E[i, 0], E[i, 1]
            m1[u] = m1[v] = m2[u] = m2[v] = NO_KEY
        for j in range(ncl):
            i = cl[j]
            k = K[i]
            u, v = E[i, 0], E[i, 1]
            if k < m1[u]:
                m1[u] = k
            if k < m1[v]:
                m1[v] = k
        for j in range(nbo):
            i = bo[j]
            u, v = E[i, 0], E[i, 1]
            k = min(m1[u], m1[v])
            if k < m2[u]:
                m2[u] = k
            if k < m2[v]:
                m2[v] = k
        ns = 0
        for j in range(ncl):
            i = cl[j]
            k = K[i]
            if k == m2[E[i, 0]] and k == m2[E[i, 1]]:
                sel[ns] = i
                ns += 1
        if ns == 0:
            break
        g[:] = 0
        tried[:] = False
        first = na
        if len(locked):  # the pass's pairs, for the faces they remove together (`rules.stranded_by_pass`)
            for t in range(ns):
                u, v = E[sel[t], 0], E[sel[t], 1]
                partner[u], partner[v] = v, u
        for t in range(ns):
            i = sel[t]
            a, b = E[i, 0], E[i, 1]
            nf = ecount[i]
            if 2 * (cnt[a] + cnt[b]) > len(fk):  # room for the faces of the busiest pair so far
                nb = np.empty(4 * (cnt[a] + cnt[b]), np.int64)
                fk, fc = np.empty(4 * (cnt[a] + cnt[b]), np.int64), np.empty(4 * (cnt[a] + cnt[b]), np.int64)
                T = np.empty((12, 4 * (cnt[a] + cnt[b])), np.int64)
            w = _rules(a, b, nf, X[i], faces, mesh, limits, seams, locks, Scratch(mark, nb, fk, fc, T), apex, na)
            c = vcopy[a]
            tried[c] = True
            if w == 0:
                acc[na] = i
                na += 1
                g[c] += 1
            else:
                cand[i] = False
                K[i] = NO_KEY
                rej[nr] = i
                why[nr] = w
                nr += 1
        if len(locked):  # (undone)
            for t in range(ns):
                partner[E[sel[t], 0]] = partner[E[sel[t], 1]] = -1
        # lock the closed 1-rings of this pass's accepted pairs (every pair at them is in the working set);
        # their endpoints are marked -1 meanwhile
        for t in range(first, na):
            i = acc[t]
            mark[E[i, 0]] = -1
            mark[E[i, 1]] = -1
        for j in range(k1):
            i = one[j]
            u, v = E[i, 0], E[i, 1]
            if mark[u] == -1 or mark[v] == -1:
                free[u] = False
                free[v] = False
        for t in range(first, na):
            i = acc[t]
            mark[E[i, 0]] = 0
            mark[E[i, 1]] = 0
        # each copy's pass rule (`select._copies_staying`): a copy that selected nothing, or little
        all_done, left = True, False
        for c in range(C):
            n_acc[c] += g[c]
            done[c] = (not tried[c]) or g[c] < pass_yield * n_acc[c] or (g[c] * 50 < need[c] // 2 and p > 2)
            all_done &= done[c]
            left |= done[c] and not out[c]
        if all_done:
            break
        if left:  # some copy leaves the passes now: its vertices are no longer available
            for c in range(C):
                out[c] |= done[c]
            for v in range(n):
                if active[v] and done[vcopy[v]]:
                    active[v] = False
        if p + 1 < max_passes:  # narrow the working set to what touches an available vertex
            k2 = nbo = 0
            for j in range(k1):  # (in place: k2 <= j; without a branch, as above)
                i = one[j]
                u, v = E[i, 0], E[i, 1]
                pa, pb = active[u] & free[u], active[v] & free[v]
                one[k2] = i
                k2 += pa | pb
                bo[nbo] = i
                nbo += pa & pb
            k1 = k2
            n2 = 0
            for j in range(ncl):  # the candidates left in ``bo``: not rejected, both endpoints available
                i = cl[j]
                u, v = E[i, 0], E[i, 1]
                cl[n2] = i
                n2 += cand[i] & active[u] & free[u] & active[v] & free[v]
            ncl = n2
    return acc[:na].copy(), apex[:na].copy(), rej[:nr].copy(), why[:nr].copy()
