"""Garland & Heckbert's algorithm as published: one priority queue of all valid pairs, contract the
cheapest, re-cost the pairs whose cost changed. The quality reference for the parallel scheduler.

It runs on the same pieces as the parallel scheduler, one contraction at a time: the faces in
`FaceLists`, the manifold rules of `topo.link_ok` (on the pair's neighbourhood, relabelled to a few local
ids), the coincident-face rule of `topo.coincident_removals`, the flip kernel, and the cost model's
batched price and merge on the device rows.
"""
from __future__ import annotations

import heapq

import jax.numpy as jnp
import numpy as np

from .. import _topology as topo
from .._costs import MeshView
from .._incidence import FaceLists
from . import outcome
from .common import (DTYPE, Options, bucket, face_normals, pad_rows, set_rows, start_flips, start_merge,
                     start_price)

BUDGET = 0  # code of a pair held back only because it would remove more faces than are still needed


def _local_link_ok(faces: FaceLists, a: int, b: int, nfaces: int) -> bool:
    """`topo.link_ok` for the one pair (a, b), on its neighbourhood relabelled to local ids: the edges at
    a and b with their face counts, the boundary flags of a and b, and the degrees of their neighbours,
    all read from the live faces."""
    _, f = faces.around(np.array([a, b]))
    G = np.take(faces.F, np.unique(f), axis=0).astype(np.int64)
    verts = np.unique(G)
    loc = np.searchsorted(verts, G)  # faces in local ids
    la, lb = np.searchsorted(verts, [a, b])
    E, count = topo.edges(loc, len(verts))
    at = (E == la) | (E == lb)
    keep = at.any(1)
    E, count = E[keep], count[keep]  # every edge at a or b, counted over all its faces
    bvert = np.zeros(len(verts), bool)
    bvert[E[count == 1].reshape(-1)] = True
    # degree of each neighbour: its distinct neighbours over its own faces
    w, f2 = faces.around(verts)
    G2 = np.take(faces.F, f2, axis=0).astype(np.int64)
    me = verts[w]
    keys = np.unique(np.concatenate([w * len(faces.cnt) + G2[:, j] for j in range(3)])[
        np.concatenate([G2[:, j] != me for j in range(3)])])
    deg = np.bincount(keys // len(faces.cnt), minlength=len(verts))
    ok = topo.link_ok(np.array([[la, lb]]), np.array([nfaces]), E, len(verts), bvert, deg)
    return bool(ok[0])


def _tie(a: int, b: int) -> int:
    """A fixed scramble of the pair (a, b) that orders pairs of equal cost. Flat regions tie exactly (cost
    0); ordering them by index made each vertex absorb its neighbours one after another into a fan whose
    slivers then refused thousands of contractions (a flat 50×50 grid took 27 s)."""
    return ((a * 0x9E3779B1) ^ (b * 0x85EBCA77)) & 0xFFFFFFFF


class _Queue:
    """The priority queue of pairs with lazy deletion: an entry is current while its stamp is. Entries
    are ranked by the cost, or for a model with `rank_weights` by cost + parts @ ``weights``."""

    def __init__(self):
        self.heap, self.stamp, self.placed, self.blocked = [], {}, {}, {}
        self.weights = None

    def _key(self, cost, parts):
        if self.weights is None:
            return cost
        return float(np.float32(cost + float(np.asarray(parts, np.float64) @ self.weights)))

    def push(self, pairs, priced):
        for k, ((a, b), c) in enumerate(zip(pairs, priced.cost.tolist())):
            s = self.stamp.get((a, b), 0) + 1
            self.stamp[(a, b)] = s
            parts = priced.parts[:, k]
            self.placed[(a, b)] = (priced.x[k], int(priced.branch[k]), c, parts)
            self.blocked.pop((a, b), None)
            heapq.heappush(self.heap, (self._key(c, parts), _tie(a, b), a, b, s))

    def reweigh(self, weights):
        """New ranking weights: every current, unblocked entry is ranked again (the heap is rebuilt)."""
        self.weights = weights
        self.heap = [(self._key(c, parts), _tie(a, b), a, b, self.stamp[(a, b)])
                     for (a, b), (_, _, c, parts) in self.placed.items() if (a, b) not in self.blocked]
        heapq.heapify(self.heap)

    def forget(self, pair):
        self.stamp.pop(pair, None)
        self.placed.pop(pair, None)
        self.blocked.pop(pair, None)


def run(V: np.ndarray, S: np.ndarray, F: np.ndarray, extra_pairs: np.ndarray, target_faces: int, model,
        options: Options, progress=None):
    """Simplify. V (n,3) float32 normalised positions, S (n, model.width) the model's vertex state,
    F (m,3) int64, extra_pairs (k,2) non-edge pairs that may also contract (aggregation). Same return as
    `parallel.run`."""
    n, m = len(V), len(F)
    manifold = options.preserve_topology
    params = model.kernel_params()
    faces = FaceLists(F, n)
    E, _ = topo.edges(F, n)
    pairs = np.concatenate([E, np.sort(np.asarray(extra_pairs, np.int64).reshape(-1, 2), axis=1)])
    VQ = np.zeros((bucket(n + 1), 3 + model.width), DTYPE)
    VQ[:n, :3], VQ[:n, 3:] = V, S
    VQd = jnp.asarray(VQ)
    N0d = jnp.asarray(pad_rows(face_normals(np.asarray(V, DTYPE), F).astype(DTYPE), bucket(m)))
    nbr = [set() for _ in range(n)]  # pair partners
    for a, b in pairs.tolist():
        nbr[a].add(b)
        nbr[b].add(a)
    q = _Queue()

    def push(plist):
        if plist:
            pa = np.array(plist, np.int64)
            q.push(plist, start_price(model, VQd, pa, params, faces, n)())

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
        key, tie, a, b, s = heapq.heappop(q.heap)
        if q.stamp.get((a, b)) != s or (a, b) in q.blocked:
            continue
        x, br, cost, parts = q.placed[(a, b)]
        if ranked and cost > options.max_cost:  # ranked by more than the cost: others may still fit
            block((a, b), BUDGET)
            continue
        if cost > options.max_cost:
            heapq.heappush(q.heap, (key, tie, a, b, s))  # still a pair: the stop report counts it
            stop = "max_error"
            break
        P = np.array([[a, b]])
        (fids, before, corner, owner, after), kept, (dead, _) = faces.touched_with_dead(P)
        nshared = len(dead)
        if faces.count - nshared < target_faces:
            block((a, b), BUDGET)
            continue
        if manifold and not (1 <= nshared <= 2 and _local_link_ok(faces, a, b, nshared)):
            block((a, b), outcome.TOPOLOGY)
            continue
        if manifold and options.keep_parts and len(fids) == 0:  # its faces are all its part has left
            block((a, b), outcome.PART)
            continue
        if len(fids) and start_flips(VQd, N0d, before, fids, corner, np.zeros(len(fids), np.int64), x[None], 1,
                                     options.cos_max)()[0]:
            block((a, b), outcome.FLIP)
            continue
        # faces that would coincide after the contraction: forbidden in manifold mode, else dropped
        order = np.argsort(fids, kind="stable")
        drop = fids[order][topo.coincident_removals(after[order])]
        if len(drop) and (manifold or faces.count - nshared - len(drop) < target_faces):
            block((a, b), outcome.COINCIDENT if manifold else BUDGET)
            continue
        merged = start_merge(model, VQd, P, x[None], params)()
        row = np.concatenate([x[None], merged], 1)
        VQ[a] = row[0]
        VQd = set_rows(VQd, np.array([a]), row, size=1)
        branches[br] += 1
        max_cost_used = max(max_cost_used, float(cost))
        history.append((a, b, np.array(x), float(cost)))
        if len(model.parts):
            history_parts.append(np.append(parts, key))
        faces.contract_touched(P, kept, dead)
        if len(drop):
            faces.remove(drop)
        for w in nbr[b]:
            nbr[w].discard(b)
            if w != a:
                nbr[w].add(a)
                nbr[a].add(w)
            q.forget((min(w, b), max(w, b)))
        nbr[a].discard(b)
        nbr[b] = set()
        q.forget((a, b))
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
        push([(min(a, w), max(a, w)) for w in sorted(nbr[a])])
        if model.support == "ring":
            push(sorted({(min(u, w), max(u, w)) for u in ring for w in nbr[u]} - {(min(a, w), max(a, w))
                                                                                   for w in nbr[a]}))
        else:
            push(sorted({(min(u, w), max(u, w)) for u in ring for w in nbr[u]
                         if (min(u, w), max(u, w)) in q.blocked}))
        if progress is not None:
            progress(faces.count)
    blocked = {}
    if faces.count > target_faces:
        stop, blocked = _stop(faces, q, options, target_faces, stop)
    hist = (np.array([(a, b) for a, b, _, _ in history], np.int64).reshape(-1, 2),
            np.array([x for _, _, x, _ in history], np.float64).reshape(-1, 3),
            np.array([c for _, _, _, c in history], np.float64))
    info = {"contractions": len(history), "rejected": int(rejected_by.sum()), "rounds": len(history),
            "max_cost": max_cost_used, "branches": branches, "stop_reason": stop or "target",
            "blocked_by": blocked, "reweights": reweights,
            "parts": np.array(history_parts, np.float64).reshape(-1, len(model.parts) + 1) if len(model.parts)
            else None,
            "rejected_by": outcome.count_reasons(np.repeat(np.arange(len(rejected_by)), rejected_by))}
    return VQ[:n, :3], VQ[:n, 3:], faces.F, faces.alive, hist, info


def _stop(faces: FaceLists, q: _Queue, options: Options, target: int, stop):
    """(stop reason, blocked_by) from the pairs left in the queue (`outcome.classify`)."""
    live = sorted(p for p in q.placed)
    if not live:
        return stop or "blocked", {"non_manifold": 0}
    P = np.array(live, np.int64)
    w, f = faces.around(P.reshape(-1))
    # faces shared by both endpoints of a pair: seen once from each side
    key = (w >> 1) * len(faces.alive) + f
    ks, c = np.unique(key, return_counts=True)
    removes = np.bincount(ks[c == 2] // len(faces.alive), minlength=len(P))
    bad = np.array([q.blocked.get(p, BUDGET) for p in live], np.int8)
    cost = np.array([q.placed[p][2] for p in live])
    ok = (removes >= 1) & (removes <= 2) if options.preserve_topology else np.ones(len(P), bool)
    reason, blocked = outcome.classify(faces.count, target, bad, removes, cost > options.max_cost, ok)
    return (stop or reason), blocked
