"""Independent-set scheduler: many non-interacting contractions per round.

A round:
1. cost the current edges with the batched placement kernel (fixed-size chunks: one compilation per
   size); only pairs at vertices the last round moved are re-costed, the rest keep their numbers;
2. select, in passes, pairs that are the cheapest among all candidate pairs touching their endpoints'
   closed 1-rings (ties broken by pair index through an int64 key), so no two selected pairs share a
   vertex, a face or a 1-ring neighbour; validate them (flip kernel, link test); invalid ones leave the
   candidate set, valid ones lock their 1-rings, and the next pass selects among what is still free;
3. contract the accepted set at once (vectorised remap, quadric sums, degenerate-face removal); in
   manifold mode the sorted edge list is updated through the contractions (`topo.contract_edges`)
   rather than rebuilt from the faces.
Because accepted contractions are two edges apart, the validity computed for each stays true when all
happen together. The last round takes only as many, in cost order, as the exact face target allows.
"""
from __future__ import annotations

import functools
import time
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np

from .. import _topology as topo
from .._kernels import flips, placement
from .common import DTYPE, Settings, Timer, bucket, chunks, pad_rows, set_rows

MAX_PASSES = 8
PASS_YIELD = 0.1  # stop a round's passes once one accepts under this fraction of what the round took
GATE = 1.2  # take pairs up to GATE × the cost of the k-th cheapest candidate, where
GATE_FRACTION = 0.05  # k = min(contractions still needed / (2·TAIL), GATE_FRACTION × live pairs):
TAIL = 10  # near the target a round takes at most about 1/(2·TAIL) of what is still needed
FREE_COST = 1e-10  # costs below this (squared, unit extent) always pass the gate: flat regions
MERGE_CHUNK = 4096
NO_KEY = np.iinfo(np.int64).max
# rows of 2-D arrays: numpy's A[idx] / A[mask] are several times slower than these (measured 4-15×)
_take = functools.partial(np.take, axis=0)


def _keep(A, mask):
    return np.compress(mask, A, axis=0)


def _sort_keys(cost: np.ndarray, salt: int = 0) -> np.ndarray:
    """Unique, monotonic int64 keys: float32 cost bits (non-negative) in the high word and a fixed
    bijective scramble of the pair index in the low word. Ties (flat regions have many exact zeros)
    are broken deterministically but in a spatially incoherent order: breaking them by raw index would
    make neighbouring pairs form long descending chains with one local minimum each."""
    bits = np.ascontiguousarray(cost, dtype=np.float32).view(np.int32).astype(np.int64)
    m32 = np.uint64(0xFFFFFFFF)
    h = (np.arange(len(cost), dtype=np.uint64) + np.uint64(salt)) & m32
    for mult, shift in ((0x85EBCA6B, 16), (0xC2B2AE35, 13), (1, 16)):  # murmur3's fmix32: a bijection
        h ^= h >> np.uint64(shift)
        h = (h * np.uint64(mult)) & m32
    return (bits << 32) | h.astype(np.int64)


def _place(VQd, P, settings):
    """Placement x (K,3), cost (K,), branch (K,) int8 for index pairs P (K,2) into device rows VQd."""
    args = settings.kernel_args()
    outs = [placement.place_pairs(VQd, part, *args) for _, part in chunks(P.astype(np.int32))]
    out = np.concatenate([np.asarray(o) for o in outs], 1)[:, : len(P)] if outs else np.zeros((5, 0), DTYPE)
    return np.ascontiguousarray(out[:3].T), out[3], out[4].astype(np.int8)


def _merged(VQd, P, x):
    """(K,10) merged quadrics of pairs P (K,2) in the frames of their targets x (K,3). One chunk shape
    (MERGE_CHUNK) whatever K: a few more calls in early rounds, one compilation."""
    outs = [placement.merged_quadrics(VQd, pp, xx) for (_, pp), (_, xx)
            in zip(chunks(P.astype(np.int32), size=MERGE_CHUNK), chunks(x, size=MERGE_CHUNK))]
    return np.concatenate([np.asarray(o) for o in outs])[: len(P)]


def _flip_bad(VQd, N0d, F, fids, corner, owner, x, S, settings):
    """(S,) bool: does moving the given corner of faces F (k,3) to x[owner] flip any of them?
    fids (k,): the input faces they continue (reference normals N0d[fids]). Fixed-size chunks."""
    cos_max = np.asarray(settings.cos_max, DTYPE)
    parts = zip(chunks(F), chunks(fids.astype(np.int32)), chunks(corner.astype(np.int32)), chunks(np.take(x, owner, axis=0)))
    outs = [flips.face_flips_at(VQd, N0d, ff, ii, kk, xx, cos_max)
            for (_, ff), (_, ii), (_, kk), (_, xx) in parts]
    bad = np.concatenate([np.asarray(o) for o in outs])[: len(F)] if outs else np.zeros(0, bool)
    res = np.zeros(S, bool)
    res[owner[bad]] = True
    return res


def _select(E, key, cand, need, n, validate, F):
    """Passes of independent-set selection with validation. Returns (accepted, rejected) pair indices
    and the extra faces (coincident ones) each accepted pair removes, (len(E),) int.

    E (P,2) are all candidate pairs (mesh edges and, with aggregation, close vertex pairs): the conflict
    graph. ``validate(pairs, idx, faces, face_idx, pairs_at_free)`` returns (ok, extra faces removed).

    Each pass takes the candidates that hold the smallest key among all candidates touching their
    endpoints' closed 1-rings, validates them (flips, duplicate faces, link condition), and locks the
    1-rings of the accepted ones. Later passes only look at what is still free, so they cost little.
    """
    def narrow(avail, ws):
        """Working sets, narrowed to what touches ``avail`` vertices: pairs with an available endpoint
        (locking, link test) and their rows, which of those have both endpoints available (selection),
        faces with an available corner (validation) and their rows."""
        one, Eo, _, fsub, Fo = ws
        a0, a1 = avail[Eo[:, 0]], avail[Eo[:, 1]]
        k1 = a0 | a1
        ff = avail[Fo]
        kf = ff[:, 0] | ff[:, 1] | ff[:, 2]
        return one[k1], _keep(Eo, k1), (a0 & a1)[k1], fsub[kf], _keep(Fo, kf)

    def endpoints(mask):
        v = np.zeros(n, bool)
        v[_keep(E, mask).reshape(-1)] = True
        return v

    everything = (np.arange(len(E)), E, None, np.arange(len(F)), F)
    free = np.ones(n, bool)
    # only vertices with a candidate pair matter: the rest never select and never conflict
    active = endpoints(cand)
    ws = narrow(active, everything)
    accepted, rejected = [], []
    extra = np.zeros(len(E), np.int64)
    n_acc = 0
    for p in range(MAX_PASSES):
        one, Eo, bmask, fsub, Fo = ws
        both, Eb = one[bmask], _keep(Eo, bmask)
        live = cand[both]
        if not live.any():
            break
        kl = np.where(live, key[both], NO_KEY)
        m1 = np.full(n, NO_KEY)
        np.minimum.at(m1, Eb[:, 0], kl)
        np.minimum.at(m1, Eb[:, 1], kl)
        m2 = m1.copy()
        np.minimum.at(m2, Eb[:, 0], m1[Eb[:, 1]])
        np.minimum.at(m2, Eb[:, 1], m1[Eb[:, 0]])
        sel = both[live & (kl == m2[Eb[:, 0]]) & (kl == m2[Eb[:, 1]])]
        if sel.size == 0:
            break
        ok, extra_sel = validate(_take(E, sel), sel, Fo, fsub, Eo)
        extra[sel] = extra_sel
        cand[sel[~ok]] = False
        rejected.append(sel[~ok])
        good = sel[ok]
        accepted.append(good)
        # lock the closed 1-rings of accepted endpoints; shrink the working sets to what is free
        lock = np.zeros(n, bool)
        lock[_take(E, good).reshape(-1)] = True
        ring = lock[Eo[:, 0]] | lock[Eo[:, 1]]
        free[_keep(Eo, ring).reshape(-1)] = False
        ws = narrow(active & free, ws)
        n_acc += good.size
        if good.size < PASS_YIELD * n_acc or (good.size * 50 < need // 2 and p > 2):
            break  # later passes would add little: leave the rest to the next round
    cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0, np.int64)  # noqa: E731
    return cat(accepted), cat(rejected), extra


def _with_extra_pairs(E, ecount, extra_pairs, n):
    """Candidate pairs = mesh edges ∪ extra (non-edge) pairs, sorted by key; non-edges count 0 faces."""
    if len(extra_pairs) == 0:
        return E, ecount
    xk = np.unique(topo.edge_keys(extra_pairs[:, 0], extra_pairs[:, 1], n))
    ek = topo.edge_keys(E[:, 0], E[:, 1], n)
    xk = xk[~np.isin(xk, ek)]
    keys = np.concatenate([ek, xk])
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    E = np.stack([keys // n, keys % n], 1).astype(E.dtype)
    return E, np.concatenate([ecount, np.zeros(len(xk), np.int64)])[order]


def _validate(P, idx, Fs, fs, Efree, *, ctx):
    """(ok, faces made coincident) for vertex-disjoint pairs P (indices idx into this round's pairs).
    Fs (rows fs of the current faces) holds every face around them, Efree every pair at them."""
    tv = time.perf_counter()
    rows, corner, owner, G = topo.contraction_faces(Fs, P, ctx.n)
    ok = ~_flip_bad(ctx.VQd, ctx.N0d, _take(Fs, rows), ctx.fid[fs[rows]], corner, owner, _take(ctx.x, idx),
                    len(P), ctx.settings)
    gone = topo.coincidence_count(G, owner, len(P))
    if ctx.settings.preserve_topology:  # no coincident faces, link condition
        ok &= (gone == 0) & topo.link_ok(P, ctx.ecount[idx], Efree, ctx.n, ctx.bvert, ctx.deg)
    ctx.timer.add("validity_s", time.perf_counter() - tv)
    return ok, gone


def _fits_target(removes: np.ndarray, need: int) -> np.ndarray:
    """Mask over contractions in cost order: take them while the faces they remove (``removes``) fit in
    ``need``, then fill what is left with later ones that still fit, so the face target is met exactly
    when the mesh allows it."""
    csum = np.cumsum(removes)
    take = csum <= need
    if take.all():
        return take
    left = need - (csum[take][-1] if take.any() else 0)
    for i in np.flatnonzero(~take):  # a few at most: only the tail of the last round
        if removes[i] <= left:
            take[i] = True
            left -= removes[i]
    return take


def _touched_vertices(F, P, n):
    """(n,) bool: endpoints of the pairs P and every vertex sharing a face with one."""
    t = np.zeros(n, bool)
    t[P.reshape(-1)] = True
    tf = t[F]
    t[F[tf[:, 0] | tf[:, 1] | tf[:, 2]].reshape(-1)] = True
    return t


def _relink_faces(F, fid, kept, n, drop_coincident):
    """After remapping F (removed vertices replaced by kept ones): drop faces with a repeated corner,
    and with ``drop_coincident`` resolve faces that now coincide (they all touch a kept vertex).
    Returns F, fid and the faces that collapsed (remapped, with a repeated corner)."""
    deg = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    collapsed = _keep(F, deg)
    F, fid = _keep(F, ~deg), fid[~deg]
    if drop_coincident:
        merged = np.zeros(n, bool)
        merged[kept] = True
        mf = merged[F]
        rows = np.flatnonzero(mf[:, 0] | mf[:, 1] | mf[:, 2])
        keep = np.ones(len(F), bool)
        keep[rows[topo.coincident_removals(_take(F, rows))]] = False
        F, fid = _keep(F, keep), fid[keep]
    return F, fid, collapsed


def _history_arrays(rounds):
    """Per-round (kept, removed, positions, costs) -> pairs (k,2) int64, positions (k,3), costs (k,)."""
    if not rounds:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0)
    pairs = np.concatenate([np.stack([a, b], 1) for a, b, _, _ in rounds]).astype(np.int64)
    return pairs, np.concatenate([x for _, _, x, _ in rounds]), np.concatenate([c for _, _, _, c in rounds])


def run(V, Q, F, extra_pairs, target_faces, settings: Settings, progress=None):
    """Simplify. V (n,3) float32 normalised positions, Q (n,10) quadrics, F (m,3) int64 faces,
    extra_pairs (k,2) non-edge pairs that may also contract (aggregation; k may be 0).
    Returns (V, Q, F, alive, history, info): F (m,3) rows are the input faces re-linked, alive (m,)
    marks the survivors, history = (pairs (k,2), positions (k,3), costs (k,)) in contraction order."""
    n, m = len(V), len(F)
    manifold = settings.preserve_topology
    n_cap = bucket(n + 1)
    VQ = pad_rows(np.concatenate([V, Q], 1).astype(DTYPE), n_cap)  # rows [position, quadric]
    V = VQ[:, :3]  # views
    F = F.astype(np.int32)  # halves the memory traffic of every gather (n < 2**31)
    extra_pairs = np.asarray(extra_pairs, np.int32).reshape(-1, 2)
    fid = np.arange(len(F))  # input face each current face continues
    p = V[F]
    N0 = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).astype(DTYPE)  # input normals, by fid
    N0d = jnp.asarray(pad_rows(N0, bucket(m)))  # padded: one compilation per size class
    VQd = jnp.asarray(VQ)  # device copy, updated row by row
    timer = Timer()
    history = []
    branches = np.zeros(3, np.int64)
    rounds = rejected = 0
    max_cost_used = 0.0
    faces_per_round = []
    invalid_keys = np.zeros(0, np.int64)  # edges found invalid whose neighbourhood has not changed since
    prev = None  # (edge keys, targets, costs, branches, moved vertices) of the last round
    # manifold mode: the edges are updated through each round's contractions instead of rebuilt
    incremental = manifold and len(extra_pairs) == 0
    updated = None  # (E, ecount, src) after the last round's contractions, when incremental
    while len(F) > target_faces:
        rounds += 1
        t0 = time.perf_counter()
        if updated is None:
            E, ecount = topo.edges(F, n)
            E, ecount = _with_extra_pairs(E, ecount, extra_pairs, n)
            src = None
        else:
            E, ecount, src = updated
        ekeys = topo.edge_keys(E[:, 0], E[:, 1], n)
        deg = topo.vertex_degree(E if incremental else _keep(E, ecount > 0), n)
        bvert = np.zeros(n, bool)
        bvert[_keep(E, ecount == 1).reshape(-1)] = True
        timer.add("topology_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        # re-cost only pairs at vertices the last round moved; the rest keep their cost and target
        if prev is None:
            x, cost, branch = _place(VQd, E, settings)
        else:
            pkeys, px, pcost, pbranch, changed = prev
            dirty = changed[E].any(1)
            if src is None:  # rebuilt: find each edge's predecessor by key
                src = np.minimum(np.searchsorted(pkeys, ekeys), len(pkeys) - 1)
                dirty |= pkeys[src] != ekeys
            x, cost, branch = _take(px, src), pcost[src], pbranch[src]
            d = np.flatnonzero(dirty)
            x[d], cost[d], branch[d] = _place(VQd, _take(E, d), settings)
        timer.add("kernels_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        need = len(F) - target_faces
        n_alive = len(E)  # ~3× the live vertices; only the ratio matters for the gate
        known_bad = np.zeros(len(E), bool)
        if invalid_keys.size:
            pos = np.minimum(np.searchsorted(invalid_keys, ekeys), invalid_keys.size - 1)
            known_bad = invalid_keys[pos] == ekeys
        valid = (cost <= settings.max_cost) & ~known_bad & (ecount <= need)
        if manifold:
            valid &= (ecount >= 1) & (ecount <= 2)
        if not valid.any():
            break
        k = min(max(need // (2 * TAIL), 1), int(valid.sum()), max(int(GATE_FRACTION * n_alive), 1))
        kth = np.partition(cost[valid], k - 1)[k - 1]
        key = _sort_keys(cost, salt=rounds * 7919)
        cand = valid & (cost <= max(GATE * kth, FREE_COST))

        ctx = SimpleNamespace(VQd=VQd, N0d=N0d, fid=fid, x=x, ecount=ecount, bvert=bvert, deg=deg, n=n,
                              settings=settings, timer=timer)
        acc, bad, extra = _select(E, key, cand, need, n, functools.partial(_validate, ctx=ctx), F)
        rejected += bad.size
        acc = acc[np.argsort(key[acc], kind="stable")]
        acc = acc[_fits_target(ecount[acc] + extra[acc], need)]
        timer.add("select_s", time.perf_counter() - t0)
        if bad.size:
            invalid_keys = np.union1d(invalid_keys, ekeys[bad])
        if acc.size == 0:
            if bad.size:  # the invalid ones are out now: select again among the rest (same edges)
                prev = (ekeys, x, cost, branch, np.zeros(n, bool))
                updated = (E, ecount, np.arange(len(E))) if incremental else None
                continue
            break

        t0 = time.perf_counter()
        P = _take(E, acc)
        a, b = P[:, 0], P[:, 1]
        xs = _take(x, acc)
        VQ[a, 3:] = _merged(VQd, P, xs)
        VQ[a, :3] = xs
        VQd = set_rows(VQd, a, _take(VQ, a), size=MERGE_CHUNK)
        changed = np.zeros(n, bool)
        changed[a] = True
        prev = (ekeys, x, cost, branch, changed)
        branches += np.bincount(branch[acc], minlength=3)
        max_cost_used = max(max_cost_used, float(cost[acc].max()))
        history.append((a.copy(), b.copy(), xs, cost[acc].astype(np.float64)))
        if invalid_keys.size:  # pairs whose faces change get another chance
            touched = _touched_vertices(F, P, n)
            invalid_keys = invalid_keys[~(touched[invalid_keys // n] | touched[invalid_keys % n])]
        rep = np.arange(n, dtype=np.int32)
        rep[b] = a
        F, fid, collapsed = _relink_faces(rep[F], fid, a, n, drop_coincident=not manifold)
        if incremental:
            updated = topo.contract_edges(E, ecount, a, b, collapsed, n)
        if len(extra_pairs):
            extra_pairs = rep[extra_pairs]
            extra_pairs = extra_pairs[extra_pairs[:, 0] != extra_pairs[:, 1]]
        faces_per_round.append(len(F))
        timer.add("contract_s", time.perf_counter() - t0)
        if progress is not None:
            progress(len(F))
    alive = np.zeros(m, bool)
    Fout = np.zeros((m, 3), F.dtype)
    Fout[fid] = F
    alive[fid] = True
    hist = _history_arrays(history)
    info = {"contractions": len(hist[0]), "rejected": rejected, "rounds": rounds, "max_cost": max_cost_used,
            "branches": branches, "faces_per_round": faces_per_round}
    info.update(timer.t)
    return VQ[:n, :3], VQ[:n, 3:], Fout, alive, hist, info
