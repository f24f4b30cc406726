"""Garland & Heckbert's algorithm as published: one priority queue of all valid pairs, contract the
cheapest, re-cost the pairs whose cost changed. The quality reference for the parallel scheduler.

It runs on the same rules as the parallel scheduler, one contraction at a time: the faces in
`FaceLists`, the manifold rules of `topo.link_ok` (as a scalar check on the pair's neighbourhood), the
coincident-face rule of `topo.coincident_removals`, the flip test (`flips.flips_host`, the flip kernel's
numpy twin: one contraction's few faces cost less on the host than a device call), and the cost model's
batched price and merge on the device rows.

A run takes one of two paths, with the same contractions in the same order and the same outputs:
* models whose price reads only the pair's two rows (`greedy_compiled.eligible`: QEM and its attribute
  form without memoryless, ring support, refresh or ranking weights): the queue in verified speculative
  batches with its host side compiled (`greedy_compiled`, `greedy_jit`, `greedy_rules_jit`): one merge and
  one price call per few dozen contractions instead of per contraction, in both modes, on any mesh, with
  or without locks and weights, and with kept attributes (the seam rule, the wedge updates and the seam
  pricing at each push, journaled: `greedy_wedges_jit`);
* everything else (ring-support, refreshed or rank-weighted models), and any run where numba is missing
  (a core dependency: only a safety net): the loop below, one contraction and one device round trip at
  a time. It is the reference the compiled path is tested against (tests/test_greedy_compiled.py).
"""
from __future__ import annotations

import heapq

import jax.numpy as jnp
import numpy as np

from . import locks as _locks
from .._mesh import topology as topo
from .._costs import MeshView
from .._mesh.incidence import FaceLists
from . import outcome
from .._kernels import flips
from .common import DTYPE, Options, bucket, face_normals, gc_paused, set_rows, start_merge, start_price
from .outcome import BUDGET
from .queue import Queue as _Queue, stop_report as _stop



SMALL = 64  # a contraction's re-pricing (a 1-ring's pairs) goes in pieces of this shape, not the smallest of
# `batching.CHUNKS`: the kernels then price a few dozen pairs, not mostly padding


def _link_ok(faces: FaceLists, a: int, b: int, nshared: int) -> bool:
    """`topo.link_ok` for the one pair (a, b) with ``nshared`` faces, on Python sets of its neighbourhood
    (a scalar check costs a few microseconds where the vectorised one costs hundreds): a manifold edge
    whose endpoints' common neighbours are exactly the apexes of its faces, that does not pinch two
    boundaries together through an interior edge, and no apex of an interior edge of degree 3."""
    if not 1 <= nshared <= 2:
        return False
    w, f = faces.around(np.array([a, b]))
    G = np.take(faces.F, f, axis=0)
    ring_a, ring_b = G[w == 0], G[w == 1]
    common = (set(ring_a.ravel().tolist()) & set(ring_b.ravel().tolist())) - {a, b}
    if len(common) != nshared:
        return False
    if nshared == 2:
        if _on_boundary(ring_a, a) and _on_boundary(ring_b, b):
            return False
        for c in common:
            if len(set(np.take(faces.F, faces.around(np.array([c]))[1], axis=0).ravel().tolist())) - 1 <= 3:
                return False
    return True


def _on_boundary(ring: np.ndarray, v: int) -> bool:
    """Whether v has an edge with one face, from its faces ``ring`` (k,3): a neighbour seen in one face."""
    others = ring.ravel()
    return bool(np.any(np.unique(others[others != v], return_counts=True)[1] == 1))


def _compiled():
    """`greedy_compiled`, or None without numba (a core dependency; then the loop below runs)."""
    try:
        from . import greedy_compiled
    except ImportError:  # pragma: no cover
        return None
    return greedy_compiled


def run(V: np.ndarray, S: np.ndarray, F: np.ndarray, extra_pairs: np.ndarray, target_faces: int, model,
        options: Options, progress=None, wedges=None, edges=None, part_scale=None, locks=None):
    """`_run` with Python's garbage collector paused (`common.gc_paused`)."""
    with gc_paused():
        return _run(V, S, F, extra_pairs, target_faces, model, options, progress, wedges, locks)


def _run(V: np.ndarray, S: np.ndarray, F: np.ndarray, extra_pairs: np.ndarray, target_faces: int, model,
         options: Options, progress=None, wedges=None, locks=None):
    """Simplify. V (n,3) float32 normalised positions, S (n, model.width) the model's vertex state,
    F (m,3) int64, extra_pairs (k,2) non-edge pairs that may also contract (aggregation). Returns the
    `outcome.Outcome` (``wedges``: as in `parallel.run`; ``edges`` and ``part_scale``, which the parallel
    scheduler uses, are not needed by the queue; ``locks``: a `_locks.RunLocks` or None, as there)."""
    n = len(V)
    manifold = options.preserve_topology
    params = model.kernel_params()
    faces = FaceLists(F, n)
    E, _ = topo.edges(F, n)
    pairs = np.concatenate([E, np.sort(np.asarray(extra_pairs, np.int64).reshape(-1, 2), axis=1)])
    compiled = _compiled()
    if compiled is not None and compiled.eligible(model):  # the same run, in verified batches
        return compiled.run(V, S, F, pairs, target_faces, model, options, progress, locks, wedges)
    VQ = np.zeros((bucket(n + 1), 3 + model.width), DTYPE)
    VQ[:n, :3], VQ[:n, 3:] = V, S
    VQd = jnp.asarray(VQ)
    N0 = face_normals(np.asarray(V, DTYPE), F).astype(DTYPE)  # each input face's normal: the reference
    nbr = [set() for _ in range(n)]  # pair partners (not a vertex itself: the edge of a face with a repeated
    for a, b in pairs.tolist():       # corner, which is no pair)
        if a != b:
            nbr[a].add(b)
            nbr[b].add(a)
    q = _Queue()
    weights = None if locks is None or locks.weights is None else np.array(locks.weights, np.float64)

    def push(plist):
        if plist:
            pa = np.array(plist, np.int64)
            d = VQ[pa[:, 0], :3] - VQ[pa[:, 1], :3]
            priced = start_price(model, VQd, pa, params, faces, n, size=SMALL if len(pa) <= SMALL else None)()
            if locks is not None:  # locked kept vertices priced where they stand, and the weights
                priced = _locks.adjust(locks, weights, model, VQ, VQd, pa, priced, params, faces, n)
            if wedges is not None:  # pairs at seam vertices: placed at an allowed endpoint
                priced = priced._replace(x=priced.x.copy(), cost=priced.cost.copy())
                wedges.constrain(faces, VQ, pa, priced.x, priced.cost)  # refused ones: at the pop
                if locks is not None:
                    _locks.pin(locks, VQ, pa, priced.x)
            q.push(plist, priced, np.einsum("ij,ij->i", d, d))
            if locks is not None:  # pairs of two locked vertices never contract
                for k in np.flatnonzero(_locks.both_locked(locks, pa)).tolist():
                    q.blocked[plist[k]] = outcome.LOCKED

    ranked = model.rank_weights is not None
    reweights, history_parts = [], []

    def reweigh():
        """Weights from the unblocked pairs (the candidates), when the model ranks by weighted parts."""
        live = [p[3] for key, p in q.placed.items() if key not in q.blocked]
        w = model.rank_weights(np.array(live, np.float64).reshape(-1, len(model.parts)))
        q.reweigh(w)
        reweights.append((faces.count, w))

    push(sorted({tuple(p) for p in pairs.tolist() if p[0] != p[1]}))
    if ranked:
        reweigh()
    history = []
    removed_at = np.full(len(F), -1, np.int64)  # the contraction that removed each face (-1: survives)
    coincident = np.zeros(len(F), bool)  # removed as a coincident face (non-manifold mode), not degenerate
    rejected_by = np.zeros(len(outcome.REJECT) + 1, np.int64)
    max_cost_used = 0.0
    branches = np.zeros(len(model.branches), np.int64)
    stop = None

    def block(pair, code):
        q.blocked[pair] = code
        if code != BUDGET:
            rejected_by[code] += 1

    while faces.count > target_faces and q.heap:
        if ranked and faces.count <= (1.0 - model.reweight_step) * reweights[-1][0]:
            reweigh()
            if not q.heap:  # every pair left is blocked (the rebuilt heap holds only unblocked ones)
                break
        key, l2, tie, a, b, s = heapq.heappop(q.heap)
        if q.stamp.get((a, b)) != s or (a, b) in q.blocked:
            continue
        x, br, cost, parts, _ = q.placed[(a, b)]
        if ranked and cost > options.max_cost:  # ranked by more than the cost: others may still fit
            block((a, b), BUDGET)
            continue
        if cost > options.max_cost:
            heapq.heappush(q.heap, (key, l2, tie, a, b, s))  # still a pair: the stop report counts it
            stop = "max_error"
            break
        P = np.array([[a, b]])
        (fids, before, corner, owner, after), kept, (dead, _) = faces.touched_with_dead(P)
        nshared = len(dead)
        if faces.count - nshared < target_faces:
            block((a, b), BUDGET)
            continue
        if manifold and not _link_ok(faces, a, b, nshared):
            block((a, b), outcome.TOPOLOGY)
            continue
        if manifold and options.keep_parts and len(fids) == 0:  # its faces are all its part has left
            block((a, b), outcome.PART)
            continue
        if locks is not None and ((len(fids) == 0 and (locks.locked[a] or locks.locked[b])) or
                                  _locks.strands(locks, faces, P, (dead, np.zeros(len(dead), np.int64)))[0]):
            block((a, b), outcome.LOCKED)  # a locked vertex never leaves the mesh with its last faces
            continue
        if wedges is not None and not wedges.allowed(faces, VQ, a, b, x):
            block((a, b), outcome.SEAM)
            continue
        if len(fids) and flips.flips_host(VQ, N0, before, fids, corner, x, options.cos_max):
            block((a, b), outcome.FLIP)
            continue
        # faces that would coincide after the contraction: forbidden in manifold mode, else dropped
        order = np.argsort(fids, kind="stable")
        drop = fids[order][topo.coincident_removals(after[order])]
        if len(drop) and (manifold or faces.count - nshared - len(drop) < target_faces):
            block((a, b), outcome.COINCIDENT if manifold else BUDGET)
            continue
        if wedges is not None:  # the corners' wedges, before the vertex moves and the faces relink
            wedges.contract(faces, VQ, a, b, x)
        # the merge runs on the device while the host relinks the faces and pairs (which read no state
        # row); its result is waited for just before the rows are next read
        merged = start_merge(model, VQd, P, x[None], params)
        branches[br] += 1
        _locks.carry(weights, np.array([a]), np.array([b]))
        max_cost_used = max(max_cost_used, float(cost))
        history.append((a, b, np.array(x), float(cost)))
        if len(model.parts):
            history_parts.append(np.append(parts, key))
        faces.contract_touched(P, kept, dead)
        removed_at[dead] = len(history) - 1
        if len(drop):
            faces.remove(drop)
            removed_at[drop] = len(history) - 1
            coincident[drop] = True
        for w in nbr[b]:
            nbr[w].discard(b)
            if w != a:
                nbr[w].add(a)
                nbr[a].add(w)
            q.forget((min(w, b), max(w, b)))
        nbr[a].discard(b)
        nbr[b] = set()
        q.forget((a, b))
        row = np.concatenate([x[None], merged()], 1)
        VQ[a] = row[0]
        if model.refresh is None:  # else the refresh below writes row a to the device with its 1-ring
            VQd = set_rows(VQd, np.array([a]), row, size=1)
        ring = sorted(nbr[a])
        if model.support == "ring" or model.refresh is not None:
            around = np.unique(np.take(faces.F, faces.around(np.array([a]))[1], axis=0))
            if model.refresh is not None:
                verts = np.union1d(around, [a])
                VQ[verts, 3:] = np.asarray(model.refresh(MeshView(faces, VQ[:n]), verts), DTYPE)
                VQd = set_rows(VQd, verts, VQ[verts], size=16)
            if model.support == "ring":
                ring = sorted(set(ring) | set(around.tolist()) - {a})
        # re-cost pairs at a (ring support: at its whole 1-ring); pairs around a whose validity may
        # have changed are unblocked
        at_a = [(min(a, w), max(a, w)) for w in sorted(nbr[a])]
        if model.support == "ring":
            more = {(min(u, w), max(u, w)) for u in ring for w in nbr[u]} - set(at_a)
        else:
            more = {(min(u, w), max(u, w)) for u in ring for w in nbr[u] if (min(u, w), max(u, w)) in q.blocked}
        push(at_a + sorted(more))  # one kernel call
        q.compact()
        if progress is not None:
            progress(faces.count)
    blocked = {}
    if faces.count > target_faces:
        stop, blocked = _stop(faces, q, options, target_faces, stop)
    nparts = len(model.parts)
    return outcome.Outcome(
        VQ[:n, :3], VQ[:n, 3:], faces.F, faces.alive, outcome.History.of(history), stop or "target", blocked,
        outcome.count_reasons(np.repeat(np.arange(len(rejected_by)), rejected_by)),
        rejected=int(rejected_by.sum()), rounds=len(history), worst_cost=max_cost_used, branches=branches,
        parts=np.array(history_parts, np.float64).reshape(-1, nparts + 1) if nparts else None,
        reweights=reweights, history_rounds=np.arange(len(history), dtype=np.int64), removed_at=removed_at,
        coincident=coincident)
