"""Long-edge splitting after simplification (ESQEM's second half, Zhang 2022), within an exact face budget.

Every edge longer than TargetLength = b × (mean edge length of the simplified mesh) is split at its
midpoint: each face on the edge becomes two (an interior edge's two triangles become four, a boundary
edge's one becomes two). A split face keeps its orientation, and both halves keep its source face.

Passes. A pass splits a set of long edges no two of which share a face (longest first, ties by edge key:
each face takes the best of its edges, an edge whose faces all chose it is split, repeated until the
pass can take no more), so every split sees whole triangles. Passes repeat, with TargetLength fixed,
until no edge is longer (the halves of an edge over 2 × TargetLength are split again) or the budget is
spent.

Budget. With a face target T, the result must have exactly T faces (the paper's Table 1 gives ESQEM and
QEM the same counts), but how many faces splitting adds is known only on a simplified mesh. So `plan`
simplifies to T first, counts the faces its splitting would add (s), and simplifies further to T − s (the
greedy queue goes on from T where it can; else the input is simplified again), but never below T/2
(MAX_SPLIT_SHARE: QEM's anisotropic output has many long edges, about 20 % of the Cow's, so s reaches
60-70 % of T; without the floor the contraction would have to go to a third of the target, and a mesh of
many small parts could be simplified to a single face and then split back up); `split_edges` then spends
exactly the budget T − (faces left): the long edges longest first (some stay unsplit when the floor
holds), and if the budget is not spent when none is left, the longest remaining edges, until the count is
T. A closed mesh gains faces in pairs, so an odd budget on a closed mesh is rounded up (`apply`): the
result ends one face above T, the documented parity case of face targets. Without a face target, every
long edge is split.
"""
from __future__ import annotations

import inspect
from typing import NamedTuple

import numpy as np

from .fit_rules import shape

MAX_PASSES = 64  # a pass at least halves the longest edges it splits; 64 passes is far beyond any mesh
MAX_SPLIT_SHARE = 0.5  # splitting makes at most this fraction of the final faces (see `plan`)


class Split(NamedTuple):
    """The mesh after splitting: V (n',3) float64 (the input's n vertices first, then one midpoint per
    split), F (m',3) int64 (the input's faces first, in place, then the new halves), face_parent (m',)
    int64: the input face each face lies in, edge (n'−n, 2) int64: the endpoints of the edge each new
    vertex splits, length: TargetLength, passes: how many passes ran."""

    V: np.ndarray
    F: np.ndarray
    face_parent: np.ndarray
    edge: np.ndarray
    length: float
    passes: int


def _edges(F: np.ndarray, n: int):
    """Unique edges of F: (edges (E,2) sorted pairs, edge of each half-edge (3m,), face of each half-edge
    (3m,), corner j of each half-edge: it runs from F[f, j] to F[f, (j+1) % 3])."""
    m = len(F)
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    uk, inv = np.unique(key, return_inverse=True)
    return np.stack([uk // n, uk % n], 1), inv, np.repeat(np.arange(m), 3), np.tile(np.arange(3), m)


def _long(V, F, length):
    """(E,) bool: which unique edges of F are longer than ``length``."""
    E = _edges(np.asarray(F, np.int64), len(V))[0]
    return np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1) > length


def mean_edge_length(V: np.ndarray, F: np.ndarray) -> float:
    """Mean length of the unique edges of F (float64)."""
    E = _edges(np.asarray(F, np.int64), len(V))[0]
    return float(np.mean(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1))) if len(E) else 0.0


def _choose(rank: np.ndarray, he_edge: np.ndarray, he_face: np.ndarray, m: int) -> np.ndarray:
    """Edges to split in one pass: rank (E,) int64 (smaller is better, -1: not a candidate); no two chosen
    edges share a face. Local minima of the rank over the faces, repeated on what is still free."""
    chosen = np.zeros(len(rank), bool)
    free_face = np.ones(m, bool)
    cand = rank >= 0
    big = np.iinfo(np.int64).max
    nface = np.bincount(he_edge, minlength=len(rank))
    while True:
        live = cand & ~chosen
        hr = np.where(live[he_edge], rank[he_edge], big)
        best = np.full(m, big)
        np.minimum.at(best, he_face, hr)
        ok = live[he_edge] & (best[he_face] == hr) & free_face[he_face]
        win = (np.bincount(he_edge, ok, minlength=len(rank)) == nface) & live
        if not win.any():
            return chosen
        chosen |= win
        used = np.zeros(m, bool)
        used[he_face[win[he_edge]]] = True
        free_face &= ~used
        blocked = np.bincount(he_edge, ~free_face[he_face], minlength=len(rank)) > 0
        cand &= ~blocked


def _shape(A, B, C):
    return shape(A, B, C, np.cross(B - A, C - A))


def _worsens(V, F, E, he_edge, he_face, he_corner, cand, min_quality) -> np.ndarray:
    """(E,) bool: candidate edges whose split would leave a half below ``min_quality`` and worse than its
    face: the quality guard of contractions, applied to the splits."""
    hs = np.flatnonzero(cand[he_edge])
    f, j = he_face[hs], he_corner[hs]
    u, v, w = V[F[f, j]], V[F[f, (j + 1) % 3]], V[F[f, (j + 2) % 3]]
    mid = 0.5 * u + 0.5 * v
    q0 = _shape(u, v, w)
    bad = np.zeros(len(hs), bool)
    for q in (_shape(u, mid, w), _shape(mid, v, w)):
        bad |= (q < min_quality) & (q < q0)
    return np.bincount(he_edge[hs], bad, minlength=len(E)) > 0


def split_edges(V: np.ndarray, F: np.ndarray, factor: float, budget: int | None = None,
                fill: bool = True, fixed: np.ndarray | None = None, min_quality: float = 0.0) -> Split:
    """Split the edges of (V (n,3), F (m,3)) longer than factor × the mean edge length (module
    docstring). ``budget``: the most faces to add (None: no limit); with ``fill``, a budget left when no
    edge is long is spent on the longest remaining edges, so exactly ``budget`` faces are added when the
    mesh allows it. ``fixed`` (n,) bool: locked vertices; an edge between two of them is never split, as it
    is never contracted (a vertex on it would change a border the caller holds, such as a tile's seam).
    ``min_quality``: the quality guard (`Topology.min_angle`, 0: off): no split leaves a half below it and
    worse than the face it halves."""
    V = np.array(V, np.float64)
    F = np.array(F, np.int64)
    n0 = len(V)
    fixed = np.zeros(n0, bool) if fixed is None else np.asarray(fixed, bool)
    parent = np.arange(len(F), dtype=np.int64)
    length = factor * mean_edge_length(V, F)
    new_edges = []
    left = np.inf if budget is None else int(budget)
    filling, passes = False, 0
    while left > 0 and passes < MAX_PASSES:
        E, he_edge, he_face, he_corner = _edges(F, len(V))
        nface = np.bincount(he_edge, minlength=len(E))
        ell = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
        cand = (nface <= left) & (filling | (ell > length)) & ~(fixed[E[:, 0]] & fixed[E[:, 1]])
        if min_quality > 0 and cand.any():
            cand &= ~_worsens(V, F, E, he_edge, he_face, he_corner, cand, min_quality)
        if not cand.any():
            if filling or budget is None or not fill:
                break
            filling = True
            continue
        order = np.lexsort((np.arange(len(E)), -ell))  # longest first; ties by edge key (E is sorted)
        rank = np.full(len(E), -1, np.int64)
        rank[order] = np.arange(len(E))
        rank[~cand] = -1
        chosen = _choose(rank, he_edge, he_face, len(F))
        idx = np.flatnonzero(chosen)
        idx = idx[np.argsort(rank[idx], kind="stable")]
        if budget is not None:  # longest first, as many as the budget holds
            idx = idx[np.cumsum(nface[idx]) <= left]
        if idx.size == 0:
            break
        passes += 1
        mid = len(V) + np.arange(len(idx))
        V = np.concatenate([V, 0.5 * V[E[idx, 0]] + 0.5 * V[E[idx, 1]]])
        fixed = np.concatenate([fixed, np.zeros(len(idx), bool)])  # a midpoint is free
        new_edges.append(E[idx])
        vid = np.full(len(E), -1, np.int64)
        vid[idx] = mid
        # each face on a chosen edge (u -> v at corner j, apex w): (u, m, w) in place, (m, v, w) appended
        hs = np.flatnonzero(vid[he_edge] >= 0)
        f, j = he_face[hs], he_corner[hs]
        u, v, w = F[f, j], F[f, (j + 1) % 3], F[f, (j + 2) % 3]
        mv = vid[he_edge[hs]]
        F[f] = np.stack([u, mv, w], 1)
        F = np.concatenate([F, np.stack([mv, v, w], 1)])
        parent = np.concatenate([parent, parent[f]])
        left -= len(hs)
    edge = np.concatenate(new_edges) if new_edges else np.zeros((0, 2), np.int64)
    assert len(V) == n0 + len(edge)
    return Split(V, F, parent, edge, length, passes)


def added_faces(V: np.ndarray, F: np.ndarray, factor: float, fixed: np.ndarray | None = None,
                min_quality: float = 0.0) -> int:
    """How many faces splitting (V, F) without a budget would add (``fixed``, ``min_quality``: as
    `split_edges`): the planning count of the budget."""
    return len(split_edges(V, F, factor, fixed=fixed, min_quality=min_quality).F) - len(F)


def plan(run, args, target: int, model, options, factor: float, progress=None,
         fixed: np.ndarray | None = None, min_quality: float = 0.0, planned=None):
    """Runs the scheduler ``run`` on ``args`` = (V, S, F, extra pairs) (``progress``: its progress callback)
    to the face target from which splitting can bring the count back to ``target``: first to ``target``,
    to count the faces splitting that result would add (``fixed``: the locked vertices in the run's
    numbering), then to ``target`` less those, but to at least (1 − MAX_SPLIT_SHARE) × target faces.
    ``planned``: called with that face target before the run goes to it. A scheduler that takes ``replan``
    (`greedy.run`) goes on from the first result where it can, instead of running again from the input.
    Returns (the outcome, the face target, the faces splitting the first result would add, the first
    result: `fills` may fall back to it)."""
    V, S, F, extra = args
    first = []

    def replan(out):
        s = added_faces(np.asarray(out.positions, np.float64), out.faces[out.alive], factor, fixed, min_quality)
        lower = max(target - s, int(np.ceil((1.0 - MAX_SPLIT_SHARE) * target)), 1)
        first.append((out, s, lower))
        if planned is not None:
            planned(lower)
        return lower

    takes = "replan" in inspect.signature(run).parameters
    out = run(V, S, F, extra, max(target, 1), model, options, progress, **({"replan": replan} if takes else {}))
    if len(first) > 1:
        name = getattr(getattr(run, "func", run), "__name__", "?")  # (a partial of it, with the run's keywords)
        raise ValueError(f"scheduler {name!r} called replan {len(first)} times: a "
                         "scheduler that takes replan calls it once, at its first target")
    if not first:  # the scheduler ran to the target it was given: a second run, from the input
        out = run(V, S, F, extra, replan(out), model, options, progress)
    (out1, s, lower), = first
    return out, lower, s, out1


def fills(out, target: int, factor: float, fixed: np.ndarray | None = None, min_quality: float = 0.0) -> bool:
    """Whether splitting the run's result ``out`` (simplified to the planned face target, `plan`) can bring
    it back up to ``target``: always where the run reached its own target (the plan left room), else (it
    stopped above it, blocked: by locks, say) only when its splittable edges add enough faces. Where they
    do not, a run falls back to `plan`'s first result, at the target, unsplit."""
    if out.stop_reason == "target":
        return True
    F = out.faces[out.alive]
    if len(F) >= target:
        return True
    V = np.asarray(out.positions, np.float64)
    # one short is the parity of splits, which add an interior edge's two faces at once
    return len(split_edges(V, F, factor, _budget(F, len(V), target), fixed=fixed,
                           min_quality=min_quality).F) >= target - 1


def _budget(F: np.ndarray, n: int, target: int) -> int:
    """The faces splitting (F, n vertices) may add to reach ``target``: on a closed mesh faces come in
    pairs, so an odd count is rounded up (one above the target, like contraction's parity)."""
    budget = max(target - len(F), 0)
    if budget % 2:
        E, he_edge = _edges(np.asarray(F, np.int64), n)[:2]
        if not np.any(np.bincount(he_edge, minlength=len(E)) == 1):
            budget += 1
    return budget


def apply(V, F, ids, fids, verr, factor: float, target: int, fixed: np.ndarray | None = None,
          min_quality: float = 0.0):
    """Split the simplified mesh (V (k,3) float64 mesh units, F (j,3)) and carry its per-vertex and
    per-face arrays along: ids (k,) source vertices (a midpoint takes its edge's first endpoint's),
    fids (j,) source faces (a half keeps its face's), verr (k,) vertex errors (a midpoint takes the larger
    of its endpoints'). ``target``: the face target (0: none, split every long edge); ``fixed`` (k,) bool:
    the locked vertices (`split_edges`). Returns (V, F, ids, fids, verr, stats)."""
    sp = split_edges(V, F, factor, _budget(F, len(V), target) if target else None, fixed=fixed,
                     min_quality=min_quality)
    ids, verr = list(ids), list(verr)
    for u, v in sp.edge.tolist():  # in creation order: an endpoint may be an earlier midpoint
        ids.append(ids[u])
        verr.append(max(verr[u], verr[v]))
    stats = {"length": sp.length, "passes": sp.passes, "faces_added": len(sp.F) - len(F),
             "vertices_added": len(sp.edge), "simplified_to": len(F),
             "long_edges_left": int(np.sum(_long(sp.V, sp.F, sp.length)))}
    return sp.V, sp.F, np.array(ids, np.int64), np.asarray(fids)[sp.face_parent], np.array(verr, np.float64), stats
