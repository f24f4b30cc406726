"""The greedy queue one contraction at a time: pop the cheapest pair, apply the rules (`.._schedulers.rules`,
in this order: the face budget, the link condition, the part rule, the lock rule, the seam rule, the flip
test, the coincident faces), contract it, re-price the pairs around it on the device. It runs the models
the verified batches (`batches`) do not (ring-support, refreshed or rank-weighted ones), and is what the
batches are tested against.
"""
from __future__ import annotations

import heapq

import jax.numpy as jnp
import numpy as np

from .. import locks as _locks
from .. import outcome
from .. import rules
from ..._costs import MeshView
from ..._kernels.flips import host_limits
from ..._mesh import topology as topo
from ..._mesh.incidence import FaceLists
from ..._kernels.batching import DTYPE, bucket, set_rows
from ..._mesh.arrays import face_normals
from ..._options import Options
from ..device import start_merge, start_price
from ..outcome import BUDGET
from .queue import Queue as _Queue, stop_report as _stop



SMALL = 64  # a contraction's re-pricing (a 1-ring's pairs) goes in pieces of this shape, not the smallest of
# `batching.CHUNKS`: the kernels then price a few dozen pairs, not mostly padding


def _link_ok(faces: FaceLists, a: int, b: int, nshared: int, cnt=None) -> bool:
    """The link condition (`rules.link_common`) for the one pair (a, b) with ``nshared`` faces, on the face
    lists (which still list dead faces: the lists are not `batches.simple`'s). ``cnt`` (n,3) int64 zeros,
    left so (a fresh one when None)."""
    if cnt is None:
        cnt = np.zeros((len(faces.cnt), 3), np.int64)
    return rules.link_common(faces.F, faces.alive, faces.off, faces.cnt, faces.pool, cnt, a, b, nshared,
                             np.empty(2, np.int64), False) >= 0


def run(V: np.ndarray, S: np.ndarray, F: np.ndarray, pairs: np.ndarray, target_faces: int, model,
        options: Options, progress=None, wedges=None, locks=None, normals=None, replan=None):
    """Simplify (`greedy.run`, whose arguments these are; ``pairs`` (k,2): the edges, then the extra pairs,
    each sorted). Returns the `outcome.Outcome`.

    ``replan``: as `greedy.run`'s. The queue goes on from where it stopped when nothing it did on the way
    depended on the target: it stopped at the target (not blocked, nor at the cost limit) and no pair was
    held back by the face budget. Every step to the lower target is then the one a fresh run to it takes,
    and the run to ``target_faces`` is all of such a run's first part. Otherwise a fresh run goes to it."""
    n = len(V)
    manifold = options.preserve_topology
    params = model.kernel_params()
    faces = FaceLists(F, n)
    cnt = np.zeros((n, 3), np.int64)  # the link condition's scratch
    cos_max, shape = host_limits(options.cos_max, options.min_quality)
    VQ = np.zeros((bucket(n + 1), 3 + model.width), DTYPE)
    VQ[:n, :3], VQ[:n, 3:] = V, S
    VQd = jnp.asarray(VQ)
    # each input face's normal: the reference
    N0 = (face_normals(np.asarray(V, DTYPE), F) if normals is None else normals).astype(DTYPE)
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
                priced = _locks.adjust(locks, weights, model, VQ, VQd, pa, priced, params, faces, n,
                                       held=None if wedges is None else wedges.held)
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
    held = False  # a pair was held back by the face budget: a lower target would have taken it
    goes_on = False  # the run may go on to a lower target from where it stopped

    def block(pair, code):
        q.blocked[pair] = code
        if code != BUDGET:
            rejected_by[code] += 1

    def until(target_faces, last):
        """Contract until ``target_faces`` (or no pair is left, or the cost limit); the outcome. ``last``:
        whether the run ends here (else its arrays are copied when it may go on)."""
        nonlocal VQd, stop, max_cost_used, held, goes_on
        while faces.count > target_faces and q.heap:
            if ranked and faces.count <= (1.0 - model.reweight_step) * reweights[-1][0]:
                reweigh()
                if not q.heap:  # every pair left is blocked (the rebuilt heap holds only unblocked ones)
                    break
            key, l2, tie, a, b, s = heapq.heappop(q.heap)
            if q.stamp.get((a, b)) != s or (a, b) in q.blocked:
                continue
            x, br, cost, parts = q.entry((a, b))
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
                held = True
                block((a, b), BUDGET)
                continue
            if manifold and not _link_ok(faces, a, b, nshared, cnt):
                block((a, b), outcome.TOPOLOGY)
                continue
            if manifold and rules.part_vanishes(options.keep_parts, len(fids)):
                block((a, b), outcome.PART)
                continue
            if locks is not None and (rules.locked_endpoint_bare(len(fids), locks.locked, a, b) or
                                      _locks.strands(locks, faces, P, (dead, np.zeros(len(dead), np.int64)))[0]):
                block((a, b), outcome.LOCKED)  # a locked vertex never leaves the mesh with its last faces
                continue
            if wedges is not None and not wedges.allowed(faces, VQ, a, b, x):
                block((a, b), outcome.SEAM)
                continue
            if len(fids) and rules.any_flip(VQ, N0, faces.F, fids, corner, np.asarray(x, DTYPE), cos_max, shape):
                block((a, b), outcome.FLIP)
                continue
            # faces that would coincide after the contraction: forbidden in manifold mode, else dropped
            order = np.argsort(fids, kind="stable")
            drop = fids[order][topo.coincident_removals(after[order])]
            if len(drop) and (manifold or faces.count - nshared - len(drop) < target_faces):
                held = held or not manifold
                block((a, b), outcome.COINCIDENT if manifold else BUDGET)
                continue
            if len(drop) and locks is not None and rules.drops_locked(drop, len(drop), faces.F, locks.locked):
                block((a, b), outcome.LOCKED)
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

        goes_on = stop is None and not held and faces.count <= target_faces  # (`run`'s docstring)
        blocked = {}
        if faces.count > target_faces:
            stop, blocked = _stop(faces, q, options, target_faces, stop)
        # a run that goes on after this outcome (`replan`) changes these arrays in place: it is given copies
        own = (lambda a: a.copy()) if goes_on and not last else (lambda a: a)
        nparts = len(model.parts)
        return outcome.Outcome(
            own(VQ[:n, :3]), own(VQ[:n, 3:]), own(faces.F), own(faces.alive), outcome.History.of(history),
            stop or "target", blocked, outcome.count_reasons(np.repeat(np.arange(len(rejected_by)), rejected_by)),
            rejected=int(rejected_by.sum()), rounds=len(history), worst_cost=max_cost_used, branches=own(branches),
            parts=np.array(history_parts, np.float64).reshape(-1, nparts + 1) if nparts else None,
            reweights=own(reweights), history_rounds=np.arange(len(history), dtype=np.int64),
            removed_at=own(removed_at), coincident=own(coincident))

    out = until(target_faces, replan is None)
    if replan is None:
        return out
    lower = replan(out)
    if goes_on and lower <= target_faces:
        return until(lower, True)
    return run(V, S, F, pairs, lower, model, options, progress, wedges, locks, normals)
