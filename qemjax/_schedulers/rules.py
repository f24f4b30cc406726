"""The validity rules of a contraction (b into a at x), compiled (numba): each rule written once, used by
both schedulers, the greedy queue's verified batches (`greedy.speculate`, in the order of `greedy.checks`),
its one-at-a-time loop (`greedy.loop`) and the parallel round (`selection._rules`, called by `selection.select_validate`). A contraction is refused
when it would break one of them:

* **link condition** (`link_holds`): the pair is a manifold edge (one or two faces), its endpoints' common
  neighbours are exactly the apexes of its faces, it does not pinch two boundaries together through an
  interior edge, and no apex of an interior edge has three neighbours or fewer. Otherwise the contraction
  makes the surface non-manifold (a fin, a pinch, or a tetrahedron's two coincident faces).
  `link_common` gathers its inputs from each vertex's face list (the greedy queue); the parallel round
  gathers them in its one scan of the endpoints' faces, from the degrees it keeps.
* **coincident faces** (`coincide_at_apexes`, `coincident_drop`): two faces left with the same three
  corners bound nothing. In manifold mode such a contraction is refused; in non-manifold mode the faces are
  dropped (oppositely oriented ones cancel in pairs, lower index first; of what is left the first stays).
* **flip test** (`flips`, `any_flip`): a face that stays turns its normal past the threshold against its
  own normal or against the input face it continues, or collapses to a sliver: the surface would fold.
  With ``Topology.min_angle``, the same test refuses a face whose shape ends below the quality bound and
  worse than it was (the triangle-quality guard).
* **part rule** (`part_vanishes`): with ``keep_parts``, no face of the pair stays: the contraction would
  remove the last faces of a connected part.
* **seam rule** (`seam_allows`): with kept attributes, a pair at a seam vertex contracts only onto an
  endpoint whose wedges it keeps (or freely where both sides have one wedge): the seam stays sharp.
* **lock rule** (`locked_endpoint_bare`, `stranded_by_step`, `stranded_by_pass`, `drops_locked`): a locked
  vertex never leaves the mesh, neither as an endpoint with no face staying nor as a third corner whose
  faces all die; in non-manifold mode no face at a locked vertex is dropped as coincident.

Other execution forms of the same rules, where a run needs them: the device kernel of the flip test
(`_kernels.flips`, JAX) and the vectorised link condition and coincident-face rule of the parallel round's
numpy stages (`_mesh.topology.link_ok`, `coincident_removals`). The numpy twins the tests compare with live
in tests/reference_rules.py.

Faces are the corner array ``T`` (or ``F``) and each vertex's face list (``fs``/``fl`` start and length into
``fpool``; a face listed once at each of its distinct corners). The flip test runs the float32 operations of
the device kernel in its order (products, then sums x + y, then + z, each rounded to float32)."""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .._mesh import seam_rule
from .._mesh.compiled import njit


class Faces(NamedTuple):
    """The faces as the schedulers' compiled loops hold them: corners T (m,3), which are alive, and each
    vertex's faces as a list in a pool (start, length into ``pool``; `_mesh.incidence.FaceLists`' ``off``,
    ``cnt``, ``pool``)."""
    T: Any
    alive: Any
    start: Any
    count: Any
    pool: Any


def faces_of(lists) -> Faces:
    """A `FaceLists`' arrays as `Faces` (the lists' arrays are replaced as they grow: bundle them per call)."""
    return Faces(lists.F, lists.alive, lists.off, lists.cnt, lists.pool)


@njit(cache=True, inline="always")
def has(pool, start, length, v):
    """Whether v is in pool[start:start + length]."""
    for i in range(start, start + length):
        if pool[i] == v:
            return True
    return False


@njit(cache=True)
def flips(VQ, N0, F, f, corner, x, cos_max, shape):
    """The flip test for face f (corners F[f], positions VQ (n, ≥3), reference normal N0[f]) with its
    corner ``corner`` moved to x (x, VQ, N0, cos_max float32): the device kernel's float32 operations in
    its order (`_kernels.flips`), on scalars (no small arrays per face: the parallel round tests
    thousands). ``shape``: float32 (collapse, min_quality), the bounds on the moved face's 2·area /
    longest edge² (`_kernels.flips.SLIVER`: below it the face counts as collapsed; the quality guard of
    `Topology.min_angle`, 0: off, refuses a face that ends below it and below what it was)."""
    i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
    g0x, g0y, g0z = VQ[i0, 0], VQ[i0, 1], VQ[i0, 2]
    g1x, g1y, g1z = VQ[i1, 0], VQ[i1, 1], VQ[i1, 2]
    g2x, g2y, g2z = VQ[i2, 0], VQ[i2, 1], VQ[i2, 2]
    q0x, q0y, q0z = g0x, g0y, g0z
    q1x, q1y, q1z = g1x, g1y, g1z
    q2x, q2y, q2z = g2x, g2y, g2z
    if corner == 0:
        q0x, q0y, q0z = x[0], x[1], x[2]
    elif corner == 1:
        q1x, q1y, q1z = x[0], x[1], x[2]
    else:
        q2x, q2y, q2z = x[0], x[1], x[2]
    u0x, u0y, u0z = g1x - g0x, g1y - g0y, g1z - g0z
    v0x, v0y, v0z = g2x - g0x, g2y - g0y, g2z - g0z
    u1x, u1y, u1z = q1x - q0x, q1y - q0y, q1z - q0z
    v1x, v1y, v1z = q2x - q0x, q2y - q0y, q2z - q0z
    n0x, n0y, n0z = u0y * v0z - u0z * v0y, u0z * v0x - u0x * v0z, u0x * v0y - u0y * v0x
    n1x, n1y, n1z = u1y * v1z - u1z * v1y, u1z * v1x - u1x * v1z, u1x * v1y - u1y * v1x
    e1x, e1y, e1z = q2x - q1x, q2y - q1y, q2z - q1z
    e2x, e2y, e2z = q0x - q2x, q0y - q2y, q0z - q2z
    rx, ry, rz = N0[f, 0], N0[f, 1], N0[f, 2]
    d11 = n1x * n1x + n1y * n1y + n1z * n1z
    d01 = n0x * n1x + n0y * n1y + n0z * n1z
    d00 = n0x * n0x + n0y * n0y + n0z * n0z
    de0 = u1x * u1x + u1y * u1y + u1z * u1z
    de1 = e1x * e1x + e1y * e1y + e1z * e1z
    de2 = e2x * e2x + e2y * e2y + e2z * e2z
    dr1 = rx * n1x + ry * n1y + rz * n1z
    drr = rx * rx + ry * ry + rz * rz
    l1 = np.float32(np.sqrt(d11))
    if d01 <= cos_max * np.float32(np.sqrt(d00)) * l1:
        return True
    longest2 = de0 if (de0 >= de1 or de0 != de0) else de1  # np.maximum: a NaN wins
    longest2 = longest2 if (longest2 >= de2 or longest2 != longest2) else de2
    collapse, min_quality = shape
    if l1 <= collapse * longest2 and cos_max > -1.0:
        return True
    if l1 < min_quality * longest2:  # the quality guard: below the bound, and below the face before
        o0 = u0x * u0x + u0y * u0y + u0z * u0z
        o1x, o1y, o1z = g2x - g1x, g2y - g1y, g2z - g1z
        o2x, o2y, o2z = g0x - g2x, g0y - g2y, g0z - g2z
        o1 = o1x * o1x + o1y * o1y + o1z * o1z
        o2 = o2x * o2x + o2y * o2y + o2z * o2z
        before2 = o0 if (o0 >= o1 or o0 != o0) else o1
        before2 = before2 if (before2 >= o2 or before2 != before2) else o2
        if l1 * before2 < np.float32(np.sqrt(d00)) * longest2:
            return True
    return dr1 <= cos_max * np.float32(np.sqrt(drr)) * l1


@njit(cache=True, inline="always")
def link_holds(nfaces, ncommon, both_boundary, low_apex):
    """The link condition: ``nfaces`` faces at the pair (a manifold edge has one or two), ``ncommon``
    common neighbours of its endpoints (exactly the apexes of its faces), ``both_boundary`` (both endpoints
    on a boundary: an interior edge would pinch them together) and ``low_apex`` (an apex with three
    neighbours or fewer: a tetrahedron's faces would coincide); the last two count for an interior edge."""
    return 1 <= nfaces <= 2 and ncommon == nfaces and not (nfaces == 2 and (both_boundary or low_apex))


@njit(cache=True)
def link_common(T, alive, fs, fl, fpool, cnt, a, b, nshared, out, simple):
    """`link_holds` for the pair (a, b) with ``nshared`` faces, from the face lists (live faces only): the
    common neighbours of a and b into ``out`` (their number), or -1 where it fails. ``cnt`` (n,3): zeros,
    left zeros. ``simple``: the lists hold live faces only, on a `greedy.batches.simple` mesh (then an apex
    with 4 faces or more has 4 neighbours or more, and only apexes with 3 faces or fewer are counted)."""
    if nshared < 1 or nshared > 2:
        return -1
    for side in range(2):  # corners of a's faces counted in column 0, of b's in column 1
        v = a if side == 0 else b
        for i in range(fs[v], fs[v] + fl[v]):
            if alive[fpool[i]]:
                for c in T[fpool[i]]:
                    cnt[c, side] += 1
    k = 0
    bound = np.zeros(2, np.bool_)  # a (b) on a boundary: a neighbour counted once
    for side in range(2):
        v = a if side == 0 else b
        for i in range(fs[v], fs[v] + fl[v]):
            if not alive[fpool[i]]:
                continue
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
    low = False  # asked only where the rest holds
    if k == nshared == 2 and not (bound[0] and bound[1]):
        for j in range(2):
            c = out[j]
            # k distinct faces at c need k <= C(d, 2) of its d neighbours: 4 faces or more, 4 or more
            if (fl[c] <= 3 or not simple) and _distinct_corners(T, alive, fs, fl, fpool, c) - 1 <= 3:
                low = True
                break
    return k if link_holds(nshared, k, bound[0] and bound[1], low) else -1


@njit(cache=True)
def _distinct_corners(T, alive, fs, fl, fpool, c):
    seen = np.empty(3 * fl[c], np.int64)
    k = 0
    for i in range(fs[c], fs[c] + fl[c]):
        if not alive[fpool[i]]:
            continue
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
def coincident_drop(a, b, T, A, nka, B, nkb, R):
    """`topo.coincident_removals` of the faces kept around the pair once b is contracted into a (those at
    a, then those at b with b replaced by a; taken in face order): the faces to drop into R (ascending), and
    their number. Of a group of faces with the same three corners, oppositely oriented ones cancel in pairs,
    lower index first, and of what is left (all of one orientation) the first is kept. Every kept face holds
    a afterwards, so two coincide when their other two corners do: none in the usual case, found without
    sorting."""
    k = nka + nkb
    S = np.empty((k, 3), np.int64)
    for i in range(k):
        f = A[i] if i < nka else B[i - nka]
        t0, t1, t2 = T[f, 0], T[f, 1], T[f, 2]
        if i >= nka:
            t0, t1, t2 = (a if t0 == b else t0), (a if t1 == b else t1), (a if t2 == b else t2)
        if t0 > t1:
            t0, t1 = t1, t0
        if t1 > t2:
            t1, t2 = t2, t1
        if t0 > t1:
            t0, t1 = t1, t0
        S[i, 0], S[i, 1], S[i, 2] = t0, t1, t2
    any_pair = False
    for i in range(k):
        for j in range(i + 1, k):
            if S[i, 0] == S[j, 0] and S[i, 1] == S[j, 1] and S[i, 2] == S[j, 2]:
                any_pair = True
                break
        if any_pair:
            break
    if not any_pair:
        return 0
    fid = np.empty(k, np.int64)
    for i in range(k):
        fid[i] = A[i] if i < nka else B[i - nka]
    order = np.argsort(fid)
    G = np.empty((k, 3), np.int64)  # the faces after, in face order, and their sorted corners
    Ss = np.empty((k, 3), np.int64)
    pos = np.empty(k, np.bool_)
    for r in range(k):
        i = order[r]
        f = fid[i]
        for c in range(3):
            t = T[f, c]
            G[r, c] = a if (i >= nka and t == b) else t
            Ss[r, c] = S[i, c]
        inv = (1 if G[r, 0] > G[r, 1] else 0) + (1 if G[r, 0] > G[r, 2] else 0) + (1 if G[r, 1] > G[r, 2] else 0)
        pos[r] = inv % 2 == 0
    m = 0
    for r in range(k):
        npos = nneg = rank = 0
        for q in range(k):
            if Ss[q, 0] == Ss[r, 0] and Ss[q, 1] == Ss[r, 1] and Ss[q, 2] == Ss[r, 2]:
                if pos[q]:
                    npos += 1
                else:
                    nneg += 1
                if q < r and pos[q] == pos[r]:
                    rank += 1
        c = min(npos, nneg)
        mine = npos if pos[r] else nneg
        if rank < c or (mine > c and rank > c):
            R[m] = fid[order[r]]
            m += 1
    return m


@njit(cache=True)  # not inlined: the one-at-a-time loop calls it from Python too (`_ahead` lists it)
def part_vanishes(keep_parts, nkept):
    """The part rule: with ``keep_parts``, no face of the pair stays (``nkept`` faces do): they are all its
    connected part has left."""
    return keep_parts and nkept == 0


@njit(cache=True, inline="always")
def seam_allows(free, keep_a, keep_b, VQ, a, b, x):
    """The seam rule (`_mesh.wedges.Tracker.allowed`) from the pair's wedge modes (`seam_rule.modes`):
    ``free`` (both sides one wedge), else x must be at an endpoint whose keeping is allowed (``keep_a``,
    ``keep_b``)."""
    return free or (keep_a and seam_rule._at(VQ, a, x)) or (keep_b and seam_rule._at(VQ, b, x))


@njit(cache=True)  # not inlined: the one-at-a-time loop calls it from Python too (`_ahead` lists it)
def locked_endpoint_bare(nkept, locked, a, b):
    """The lock rule at the endpoints: a or b locked and no face of the pair staying."""
    return nkept == 0 and (locked[a] or locked[b])


@njit(cache=True)
def stranded_by_step(a, b, nd, locked, T, fl, D):
    """The lock rule at the third corners, one contraction at a time (the greedy queue; `_locks.strands`):
    a locked corner c of the dead faces D[:nd] all of whose ``fl[c]`` faces are among them."""
    for i in range(nd):
        for c in T[D[i]]:
            if c != a and c != b and locked[c]:
                k = 0  # c's corners among the dead faces
                for j in range(nd):
                    for v in T[D[j]]:
                        if v == c:
                            k += 1
                if k >= fl[c]:
                    return True
    return False


@njit(cache=True)  # not inlined: the one-at-a-time loop calls it from Python too (`_ahead` lists it)
def drops_locked(R, nr, T, locked):
    """The lock rule in non-manifold mode: a face the contraction drops as coincident (R[:nr]) has a locked
    corner. Those drops can take a locked vertex's last faces (a small part folding away with it), which
    the counts before them do not see; such a contraction is refused."""
    for i in range(nr):
        f = R[i]
        if locked[T[f, 0]] or locked[T[f, 1]] or locked[T[f, 2]]:
            return True
    return False


@njit(cache=True)
def stranded_by_pass(c, F, alive, cnt, off, pool, partner):
    """The lock rule at a third corner c over a pass of the parallel round, whose pairs contract together:
    every live face at c dies, holding both endpoints of one of the pass's pairs (``partner``: each
    selected pair's endpoints name each other, -1 elsewhere). `locks.strands`' count (the dying faces at c,
    over the pass's pairs, at least c's live faces)."""
    for i in range(off[c], off[c] + cnt[c]):
        f = pool[i]
        if not alive[f]:
            continue
        g0, g1, g2 = F[f, 0], F[f, 1], F[f, 2]
        u, v = (g1, g2) if g0 == c else ((g0, g2) if g1 == c else (g0, g1))
        if partner[u] != v:
            return False
    return True


@njit(cache=True, inline="always")
def coincide_at_apexes(T, A, nka, B, nkb, u, w):
    """Coincident faces where the link condition holds on a mesh with no two faces on the same corners:
    only a face (a, u, w) kept at a and a face (b, u, w) kept at b can coincide, u and w the pair's two
    apexes (A[:nka], B[:nkb]: the faces kept at a and at b). Looked up in the kept faces' corners,
    O(fl[a] + fl[b]); not in u's and w's face lists, O(fl[u] fl[w])."""
    hit_a = hit_b = False
    for i in range(nka + nkb):
        f = A[i] if i < nka else B[i - nka]
        t0, t1, t2 = T[f, 0], T[f, 1], T[f, 2]
        if (t0 == u or t1 == u or t2 == u) and (t0 == w or t1 == w or t2 == w):
            if i < nka:
                hit_a = True
            else:
                hit_b = True
    return hit_a and hit_b


@njit(cache=True)
def any_flip(VQ, N0, F, fids, corner, x, cos_max, shape):
    """`flips` for faces ``fids`` each with its moving corner, to x: whether any flips."""
    for i in range(len(fids)):
        if flips(VQ, N0, F, fids[i], corner[i], x, cos_max, shape):
            return True
    return False
