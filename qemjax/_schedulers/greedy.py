"""Garland & Heckbert's algorithm as published: one priority queue of all valid pairs, contract the
cheapest, re-cost the pairs touching the new vertex. The quality reference for the parallel scheduler.

Per contraction the host keeps exact adjacency (Python sets); the JAX kernels re-cost the touched pairs
(placement) and test the surviving faces for flips, in small padded batches.
"""
from __future__ import annotations

import heapq

import numpy as np

from .. import _topology as topo
from .._kernels import flips
from .common import DTYPE, Settings, chunk_size, face_normals, pad_rows, place_gathered


def run(V: np.ndarray, Q: np.ndarray, F: np.ndarray, extra_pairs: np.ndarray, target_faces: int,
        settings: Settings, progress=None):
    """Simplify. V (n,3) float32 normalised positions, Q (n,10) quadrics, F (m,3) int64, extra_pairs
    (k,2) non-edge pairs that may also contract (aggregation). Same return as `parallel.run`."""
    n, m = len(V), len(F)
    E, _ = topo.edges(F, n)
    pairs = np.concatenate([E, np.sort(np.asarray(extra_pairs, np.int64).reshape(-1, 2), axis=1)])
    V, Q, F = V.copy(), Q.copy(), F.copy()
    alive = np.ones(m, bool)
    vfaces = [set() for _ in range(n)]
    for f, (a, b, c) in enumerate(F.tolist()):
        vfaces[a].add(f)
        vfaces[b].add(f)
        vfaces[c].add(f)
    nbr = [set() for _ in range(n)]  # pair partners
    for a, b in pairs.tolist():
        nbr[a].add(b)
        nbr[b].add(a)
    # boundary vertices for the manifold test: vertices on an edge with a single face
    ecount: dict[tuple[int, int], int] = {}
    for a, b, c in F.tolist():
        for u, v in ((a, b), (b, c), (c, a)):
            k = (u, v) if u < v else (v, u)
            ecount[k] = ecount.get(k, 0) + 1
    cos_max = np.asarray(settings.cos_max, DTYPE)
    N0 = face_normals(V, F).astype(DTYPE)  # input normals

    stamp: dict[tuple[int, int], int] = {}
    placed: dict = {}  # pair -> (position, branch, summed quadric) of its current cost
    heap: list = []
    blocked: set = set()

    def push(plist):
        if not plist:
            return
        pa = np.array(plist, np.int64)
        x, cost, branch, qsum = place_gathered(Q[pa[:, 0]], Q[pa[:, 1]], V[pa[:, 0]], V[pa[:, 1]], settings)
        for k, ((a, b), c) in enumerate(zip(plist, cost.tolist())):
            s = stamp.get((a, b), 0) + 1
            stamp[(a, b)] = s
            placed[(a, b)] = (x[k], branch[k], qsum[k])
            blocked.discard((a, b))
            heapq.heappush(heap, (c, a, b, s))

    push(sorted({tuple(p) for p in pairs.tolist() if p[0] != p[1]}))
    faces_now = m
    history = []
    n_invalid = 0
    max_cost_used = 0.0
    branches = np.zeros(3, np.int64)

    def unlink(f):
        alive[f] = False
        for w in F[f]:
            vfaces[w].discard(f)
        fa, fb, fc = F[f]
        for u, v in ((fa, fb), (fb, fc), (fc, fa)):
            ecount[(u, v) if u < v else (v, u)] -= 1

    def edge_faces(a, b):
        return vfaces[a] & vfaces[b]

    def is_boundary_vertex(v):
        for w in nbr[v]:
            k = (v, w) if v < w else (w, v)
            if ecount.get(k, 0) == 1:
                return True
        return False

    def link_ok(a, b, shared):
        k = len(shared)
        if k == 0 or k > 2:
            return False
        na = {w for f in vfaces[a] for w in F[f] if w != a}
        nb = {w for f in vfaces[b] for w in F[f] if w != b}
        common = (na & nb) - {a, b}
        if len(common) != k:
            return False
        if k == 2:
            if is_boundary_vertex(a) and is_boundary_vertex(b):
                return False
            for c in common:
                deg = len({w for f in vfaces[c] for w in F[f] if w != c})
                if deg <= 3:
                    return False
        return True

    while faces_now > target_faces and heap:
        cost, a, b, s = heapq.heappop(heap)
        if stamp.get((a, b)) != s or (a, b) in blocked:
            continue
        if cost > settings.max_cost:
            break
        shared = edge_faces(a, b)
        if faces_now - len(shared) < target_faces:
            blocked.add((a, b))
            continue
        if settings.preserve_topology and not link_ok(a, b, shared):
            blocked.add((a, b))
            n_invalid += 1
            continue
        x, br, qsum = placed[(a, b)]
        around = [(f, a) for f in vfaces[a] - shared] + [(f, b) for f in vfaces[b] - shared]
        if around:
            K = chunk_size(len(around))
            fi = np.array([f for f, _ in around])
            corner = np.array([list(F[f]).index(v) for f, v in around])
            p = pad_rows(V[F[fi]], K)
            ok_mask = np.arange(K) < len(around)
            if bool(flips.local_flips(p, pad_rows(corner, K), x, ok_mask, pad_rows(N0[fi], K), cos_max)):
                blocked.add((a, b))
                n_invalid += 1
                continue
        # faces that would coincide after the contraction: forbidden in manifold mode, else dropped
        rest = sorted((vfaces[a] | vfaces[b]) - shared)
        G = np.array([[a if w == b else w for w in F[f]] for f in rest], np.int64).reshape(-1, 3)
        drop = [rest[i] for i in np.flatnonzero(topo.coincident_removals(G))]
        if drop and (settings.preserve_topology or faces_now - len(shared) - len(drop) < target_faces):
            blocked.add((a, b))
            n_invalid += 1
            continue
        V[a] = x
        Q[a] = qsum
        branches[br] += 1
        max_cost_used = max(max_cost_used, float(cost))
        history.append((a, b, x.copy(), float(cost)))
        for f in list(shared) + drop:
            unlink(f)
        faces_now -= len(shared) + len(drop)
        for f in list(vfaces[b]):
            fa, fb, fc = F[f]
            for u, v in ((fa, fb), (fb, fc), (fc, fa)):
                k = (u, v) if u < v else (v, u)
                ecount[k] -= 1
            F[f][F[f] == b] = a
            fa, fb, fc = F[f]
            for u, v in ((fa, fb), (fb, fc), (fc, fa)):
                k = (u, v) if u < v else (v, u)
                ecount[k] = ecount.get(k, 0) + 1
            vfaces[a].add(f)
        vfaces[b] = set()
        for w in nbr[b]:
            nbr[w].discard(b)
            if w != a:
                nbr[w].add(a)
                nbr[a].add(w)
            stamp.pop((min(w, b), max(w, b)), None)
            placed.pop((min(w, b), max(w, b)), None)
        nbr[a].discard(b)
        nbr[b] = set()
        stamp.pop((a, b), None)
        # re-cost pairs at a; pairs around a whose validity may have changed are unblocked
        push([(min(a, w), max(a, w)) for w in sorted(nbr[a])])
        ring = sorted(nbr[a])
        push(sorted({(min(u, w), max(u, w)) for u in ring for w in nbr[u]
                     if (min(u, w), max(u, w)) in blocked}))
        if progress is not None:
            progress(faces_now)
    hist = (np.array([(a, b) for a, b, _, _ in history], np.int64).reshape(-1, 2),
            np.array([x for _, _, x, _ in history], np.float64).reshape(-1, 3),
            np.array([c for _, _, _, c in history], np.float64))
    info = {"contractions": len(history), "rejected": n_invalid, "rounds": len(history),
            "max_cost": max_cost_used, "branches": branches}
    return V, Q, F, alive, hist, info
