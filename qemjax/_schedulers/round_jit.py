"""The parallel round's host side, compiled (numba): selection passes with validation, and the contraction.

The numpy stages (`parallel.StagedRound`) spend a round in hundreds of numpy calls on small arrays; the same
steps as two loops over integer arrays take a small fraction of that (docs/benchmarks.md). This module holds those two
loops, for the common case (`fits`): manifold mode with the pairs updated through the contractions (no
non-edge pairs), at most `MAX_FACES` faces (kept attributes' seam rule runs inside, through `wedges_jit`, and
locked vertices' rule, `rules.stranded_by_pass`). They make exactly the choices of the numpy stages they
replace (`select.independent_sets` with `parallel.StagedRound.validate`, then `FaceLists.contract_touched` and
the edge update of `parallel.pairs.EdgeUpdate`): the golden outputs are the same bits, and tests/test_round_jit.py compares each
loop with the numpy code on random meshes.

* `select_validate`: the independent-set passes (each pair that holds the smallest key among the
  candidates touching its endpoints' closed 1-rings), each selected pair's rules (link condition,
  coincident faces, the part rule, the locks' rule, the seam rule, the flip test with the device kernel's
  float32 operations, `rules.flips`), the locking of accepted 1-rings and each copy's pass rule
  (`select._copies_staying`; one run is one copy).
* `contract`: the accepted pairs' faces (dead ones out, b's corners to a, new runs in the pool) and
  pairs (merged, moved, counted, compacted), with the degrees after and which pairs are stale.

A vertex's neighbours are read from its faces: in this mode every pair is an edge of a live face, and every
such edge is a pair (`topology.contract_edges` keeps exactly those).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from .._mesh import wedges_jit
from . import rules as rule
from .rules import Faces
from .outcome import COINCIDENT, FLIP, LOCKED, PART, SEAM, TOPOLOGY

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
    """The flip test's limits (float32 cos_max and sliver) and whether parts are kept."""
    cos_max: Any
    sliver: Any
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


MAX_FACES = 1 << 17  # runs on more faces keep the numpy stages: see `fits`


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


@njit(cache=True)
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
    cos_max, sliver, keep_parts = limits
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
        free, nba, nab, _, _ = wedges_jit.modes(F, alive, cnt, off, pool, C, multi, a, b, T)
        if not rule.seam_allows(free, nba >= 0, nab >= 0, VQ, a, b, x):
            why = SEAM
    if why == 0:
        for i in range(nk):
            if rule.flips(VQ, N0, F, fk[i], fc[i], x, cos_max, sliver):
                why = FLIP
                break
    return why


@njit(cache=True)
def select_validate(E, ecount, cand, kbits, local, salt, vcopy, need, max_passes, pass_yield, keep_parts,
                    F, alive, cnt, off, pool, VQ, N0, X, bvert, deg, cos_max, sliver, free, active, mark,
                    keys, rows, verts, corner_wedge, multi, locked, partner):
    """`select.independent_sets` with `parallel.StagedRound.validate` (manifold mode).

    E (P,2) pairs, ecount (P,) their faces; cand (P,) bool: the candidates (rejected ones are cleared);
    kbits (P,) int32: the float32 bits of each pair's ranking key; local (P,): each pair's index within its
    copy; salt: the round's scramble; vcopy (n,): each vertex's copy, need (C,): each copy's face budget;
    the faces (`FaceLists` arrays), positions VQ (n, ≥3) and reference normals N0, the pairs' placements X (P,3),
    boundary vertices and degrees; free, active (n,) bool and mark (n,) int32 zeros: scratch (free comes
    back with the locked vertices False); keys (≥ P,) int64, rows (2, ≥ P) int32 and verts (2, n) int64:
    working arrays, kept from round to round (fresh arrays this large would be mapped and faulted in anew on
    every call). corner_wedge (m,3) and multi (n,): the wedge of each face corner and the vertices on a
    seam, when attributes are kept (else (0,3) and all False). locked (n,) bool: the locked vertices (empty:
    none), and partner (n,) int32 all -1 (left so): scratch of their rule (`rules.stranded_by_pass`).
    Returns (accepted pair indices in pass order, their apexes (S,2), the rejected indices and their
    rules)."""
    P = len(E)
    n = len(vcopy)
    C = len(need)
    K, one, bo = keys, rows[0], rows[1]  # each pair's key (NO_KEY: not a candidate, or rejected)
    m1, m2 = verts[0], verts[1]
    faces, mesh = Faces(F, alive, off, cnt, pool), Mesh(VQ, N0, bvert, deg)
    limits, seams, locks = Limits(cos_max, sliver, keep_parts), Seams(corner_wedge, multi), Locks(locked, partner)
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
    # without a branch (about half the pairs are in it, in no pattern a branch predictor learns)
    k1 = nbo = 0
    for i in range(P):
        pa, pb = active[E[i, 0]], active[E[i, 1]]
        one[k1] = i
        k1 += pa | pb
        bo[nbo] = i
        nbo += pa & pb
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
        live_any = False
        for j in range(nbo):
            i = bo[j]
            u, v = E[i, 0], E[i, 1]
            m1[u] = m1[v] = m2[u] = m2[v] = NO_KEY
            live_any |= cand[i]
        if not live_any:
            break
        for j in range(nbo):
            i = bo[j]
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
        for j in range(nbo):
            i = bo[j]
            k = K[i]
            if k != NO_KEY and k == m2[E[i, 0]] and k == m2[E[i, 1]]:
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
    return acc[:na].copy(), apex[:na].copy(), rej[:nr].copy(), why[:nr].copy()


@njit(cache=True)
def contract_faces(a, b, F, alive, cnt, off, pool, end):
    """`FaceLists.contract_touched` for vertex-disjoint pairs (a, b) two edges apart: the faces holding
    both endpoints die, b's other faces take a, and a's run (its surviving faces, then b's) is written at
    the pool's end (which must have room for cnt[a] + cnt[b] more entries). Returns the new end and the
    faces that died, pair by pair."""
    dead = np.empty(2 * len(a), np.int64)
    nd = 0
    for s in range(len(a)):
        u, v = a[s], b[s]
        for i in range(off[v], off[v] + cnt[v]):
            f = pool[i]
            if alive[f] and (F[f, 0] == u or F[f, 1] == u or F[f, 2] == u):
                alive[f] = False
                if nd == len(dead):
                    dead = np.concatenate((dead, np.empty(len(dead), np.int64)))
                dead[nd] = f
                nd += 1
        start = end
        for i in range(off[u], off[u] + cnt[u]):
            f = pool[i]
            if alive[f]:
                pool[end] = f
                end += 1
        for i in range(off[v], off[v] + cnt[v]):
            f = pool[i]
            if alive[f]:
                for c in range(3):
                    if F[f, c] == v:
                        F[f, c] = u
                pool[end] = f
                end += 1
        off[u] = start
        cnt[u] = end - start
        cnt[v] = 0
    return end, dead[:nd].copy()


@njit(cache=True, nogil=True)
def contract_edges(E, ecount, deg, a, b, apex, label):
    """`topology.contract_edges` for vertex-disjoint pairs (a, b) that passed the link test, with their
    apexes (S,2) (-1 where a pair has one face): (b, c) merges into (a, c) for an apex c (which loses the
    vanished face and gains (b, c)'s others), b's other pairs move to a, the contracted pair goes.
    ``label`` (n,) int32 scratch, all -1 (left so). Returns (E', ecount', keep, degree', stale'): the
    pairs that stay in their order, which old rows they continue, the degrees after, and which of them
    are at a kept vertex (their cost is stale).

    In five steps, which `parallel.EdgeUpdate` also runs with the two passes over every pair shared between
    two threads: the endpoints labelled; the rows at an endpoint listed with their labels (`list_rows`);
    what becomes of each listed row (`listed_rows`); every row that stays copied (`copy_rows`) and the
    listed ones rewritten (`rewrite_rows`)."""
    P = len(E)
    label_pairs(a, b, label)
    rows, lab, far, nu, nv, cnt = listing(E, ecount, P)
    nr = list_rows(E, ecount, label, 0, P, rows, lab, far, nu, nv, cnt)
    rows, nu, nv, cnt = rows[:nr], nu[:nr], nv[:nr], cnt[:nr]
    keep, d2, m = listed_rows(E, deg, a, b, apex, label, rows, lab[:nr], far[:nr], nu, nv, cnt)
    E3 = np.empty((m, 2), E.dtype)
    c3 = np.empty(m, ecount.dtype)
    copy_rows(E, ecount, keep, 0, P, E3, c3, 0)
    s3 = rewrite_rows(rows, keep, nu, nv, cnt, E3, c3)
    return E3, c3, keep, d2, s3


@njit(cache=True, nogil=True)
def label_pairs(a, b, label):
    """label[a[s]] = s and label[b[s]] = S + s (``label`` all -1 before; `listed_rows` undoes it)."""
    S = len(a)
    for s in range(S):
        label[a[s]] = s
        label[b[s]] = S + s


@njit(cache=True, nogil=True)
def listing(E, ecount, P):
    """Room for `list_rows` of P rows: (rows int64, lab int32, far, nu, nv in E's dtype, cnt in ecount's)."""
    return (np.empty(P, np.int64), np.empty(P, np.int32), np.empty(P, E.dtype), np.empty(P, E.dtype),
            np.empty(P, E.dtype), np.empty(P, ecount.dtype))


@njit(cache=True, nogil=True)
def list_rows(E, ecount, label, lo, hi, rows, lab, far, nu, nv, cnt):
    """The rows of E in [lo, hi) with a labelled endpoint, ascending, written from rows[0], with what
    `listed_rows` reads of each: the endpoint's label (lab; -1 for the contracted pair itself, both of
    whose endpoints are labelled), the row's other vertex (far) and the row (nu, nv, cnt). Every row is
    written, then the count moves past it or not (no branch: the rows at an endpoint follow no pattern), so
    each array must have room for hi - lo entries. Returns how many."""
    nr = 0
    for i in range(lo, hi):
        u, v = E[i, 0], E[i, 1]
        l0, l1 = label[u], label[v]
        rows[nr], nu[nr], nv[nr], cnt[nr] = i, u, v, ecount[i]
        at0 = l0 >= 0
        lab[nr] = -1 if (at0 and l1 >= 0) else (l0 if at0 else l1)
        far[nr] = v if at0 else u
        nr += at0 | (l1 >= 0)
    return nr


@njit(cache=True, nogil=True)
def listed_rows(E, deg, a, b, apex, label, rows, lab, far, nu, nv, cnt):
    """What becomes of the listed rows (`list_rows`' arrays, cut to the listed ones): their new (u, v, face
    count) written over nu, nv, cnt, which rows stay (keep (P,) bool: all but dropped listed ones), the
    degrees after, and how many rows stay. Unlabels the endpoints."""
    S = len(a)
    P = len(E)
    nr = len(rows)
    keep = np.ones(P, np.bool_)
    delta = np.zeros((S, 2), np.int64)
    m = P  # the rows that stay
    for t in range(nr):  # pairs at a b: merge into (a, apex) or move to a
        if lab[t] < 0:  # the contracted pair itself
            keep[rows[t]] = False
            m -= 1
            continue
        if lab[t] < S:
            continue
        s, c = lab[t] - S, far[t]
        if c == apex[s, 0] or c == apex[s, 1]:
            delta[s, 0 if c == apex[s, 0] else 1] = cnt[t] - 2
            keep[rows[t]] = False
            m -= 1
        else:
            u = a[s]
            nu[t], nv[t] = min(u, c), max(u, c)
    for t in range(nr):  # pairs (a, apex): their new face counts
        s, c = lab[t], far[t]
        if s < 0 or s >= S:
            continue
        if c == apex[s, 0] or c == apex[s, 1]:
            cnt[t] += delta[s, 0 if c == apex[s, 0] else 1]
            if cnt[t] <= 0:
                keep[rows[t]] = False
                m -= 1
    d2 = deg.copy()
    for s in range(S):
        k = 0
        for j in range(2):
            if apex[s, j] >= 0:
                k += 1
                d2[apex[s, j]] -= 1
        d2[a[s]] += deg[b[s]] - 2 - k
        d2[b[s]] = 0
        label[a[s]] = -1
        label[b[s]] = -1
    return keep, d2, m


@njit(cache=True, nogil=True)
def copy_rows(E, ecount, keep, lo, hi, E3, c3, k):
    """The kept rows of E and ecount in [lo, hi) copied in order into E3 and c3 from row k (the kept rows
    before lo)."""
    for i in range(lo, hi):
        if keep[i]:  # (a dropped row is rare: a predictable branch)
            E3[k, 0], E3[k, 1], c3[k] = E[i, 0], E[i, 1], ecount[i]
            k += 1


@njit(cache=True, nogil=True)
def rewrite_rows(rows, keep, nu, nv, cnt, E3, c3):
    """The listed rows that stay take their new values, at their row less the rows dropped before; returns
    which rows of E3 are at a kept vertex (stale)."""
    s3 = np.zeros(len(E3), np.bool_)
    gone = 0
    for t in range(len(rows)):
        i = rows[t]
        if keep[i]:
            k = i - gone
            E3[k, 0], E3[k, 1], c3[k], s3[k] = nu[t], nv[t], cnt[t], True
        else:
            gone += 1
    return s3


@njit(cache=True)
def clear_bad(E, bad, touched):
    """Pairs known invalid get another chance where an endpoint is in ``touched`` (the round's rings)."""
    for i in range(len(E)):
        if bad[i] != 0 and (touched[E[i, 0]] or touched[E[i, 1]]):
            bad[i] = 0
