"""Independent-set scheduler: many non-interacting contractions per round.

A round:
1. cost the current edges with the batched placement kernel (fixed-size chunks: one compilation per
   size); only pairs at vertices the last round moved are re-costed, the rest keep their numbers;
2. select, in passes, pairs that are the cheapest among all candidate pairs touching their endpoints'
   closed 1-rings (ties broken by a scramble of the pair index in an int64 key), so no two selected
   pairs share a vertex, a face or a 1-ring neighbour; validate them (flip kernel, link test); invalid
   ones leave the candidate set, valid ones lock their 1-rings, and the next pass selects among what is
   still free;
3. contract the accepted set at once (quadric sums; the faces through the vertex->face lists of
   `FaceLists`: validation looks them up and the contraction reuses that look-up, so neither scans the
   whole mesh); in manifold mode the edge list and the vertex degrees are updated through the
   contractions (`topo.contract_edges`, with the apexes the link test found) rather than rebuilt.
Kernel calls are asynchronous: the re-costing, the flip test and the quadric merges run on JAX's
threads while the host works on the topology, and are waited for only where their results are needed.
One host worker thread runs the link test and the edge update beside the main thread's face work, half of
each large narrowing pass, and the initial face lists beside the input normals (numpy releases the GIL in
large array passes; the process otherwise used 1.2 of 2 cores).
Because accepted contractions are two edges apart, the validity computed for each stays true when all
happen together. The last round takes only as many, in cost order, as the exact face target allows.
"""
from __future__ import annotations

import functools
import time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np

from .. import _topology as topo
from .._incidence import FaceLists
from .._arrays import any_at, keep_rows as _keep, put_rows, take_rows as _take
from .._kernels import flips, placement
from .common import DTYPE, Settings, Timer, bucket, chunks, face_normals, pad_rows, set_rows

MAX_PASSES = 8
PASS_YIELD = 0.1  # stop a round's passes once one accepts under this fraction of what the round took
GATE = 1.2  # take pairs up to GATE × the cost of the k-th cheapest candidate, where
GATE_FRACTION = 0.05  # k = min(contractions still needed / (2·TAIL), GATE_FRACTION × live pairs):
TAIL = 10  # near the target a round takes at most about 1/(2·TAIL) of what is still needed
FREE_COST = 1e-10  # costs below this (squared, unit extent) always pass the gate: flat regions
MERGE_CHUNK = 4096
SPLIT_ROWS = 1 << 18  # array passes at least this long are shared with the worker thread
NO_KEY = np.iinfo(np.int64).max
_worker = None  # one host thread beside the caller's: numpy releases the GIL in its large array passes


def _submit(fn, *args, **kw):
    """Run fn on the worker thread; returns its future. Only read-only inputs are shared."""
    global _worker
    if _worker is None:
        _worker = ThreadPoolExecutor(1, thread_name_prefix="qemjax-host")
    return _worker.submit(fn, *args, **kw)


def _sort_keys(cost: np.ndarray, idx: np.ndarray, salt: int = 0) -> np.ndarray:
    """Unique, monotonic int64 keys of pairs idx: float32 cost bits (non-negative) in the high word and a
    fixed bijective scramble of the pair index in the low word (a multiplication by an odd constant
    modulo 2³²). Ties (flat regions have many exact zeros) are broken deterministically but in a
    spatially incoherent order: breaking them by raw index would make neighbouring pairs form long
    descending chains with one local minimum each. Only the pairs asked for are keyed (a round looks
    at a small part of them)."""
    bits = np.take(cost, idx).astype(np.float32, copy=False).view(np.int32).astype(np.int64)
    h = idx.astype(np.uint32) * np.uint32(0x9E3779B1) + np.uint32(salt & 0xFFFFFFFF)
    bits <<= 32
    bits |= h
    return bits


def _place(VQd, P, settings):
    """Start the placement of index pairs P (K,2) into device rows VQd. Returns a function that waits
    for it and gives x (K,3), cost (K,), branch (K,) int8: the kernel runs while the host works on."""
    args = settings.kernel_args()
    outs = [placement.place_pairs(VQd, part, *args) for _, part in chunks(P.astype(np.int32))]

    def result():
        out = np.concatenate([np.asarray(o) for o in outs], 1)[:, : len(P)] if outs else \
            np.zeros((5, 0), DTYPE)
        return np.ascontiguousarray(out[:3].T), out[3], out[4].astype(np.int8)
    return result


def _merged(VQd, P, x):
    """Start computing the (K,10) merged quadrics of pairs P (K,2) in the frames of their targets x
    (K,3); returns a function that waits for them. One chunk shape (MERGE_CHUNK) whatever K: a few
    more calls in early rounds, one compilation."""
    outs = [placement.merged_quadrics(VQd, pp, xx) for (_, pp), (_, xx)
            in zip(chunks(P.astype(np.int32), size=MERGE_CHUNK), chunks(x, size=MERGE_CHUNK))]
    return lambda: np.concatenate([np.asarray(o) for o in outs])[: len(P)]


def _flip_bad(VQd, N0d, F, fids, corner, owner, x, S, settings):
    """Start the flip test: does moving the given corner of faces F (k,3) to x[owner] flip any of them?
    fids (k,): the input faces they continue (reference normals N0d[fids]). Fixed-size chunks.
    Returns a function that waits for the kernel and gives (S,) bool per pair."""
    cos_max = np.asarray(settings.cos_max, DTYPE)
    parts = zip(chunks(F), chunks(fids.astype(np.int32)), chunks(corner.astype(np.int32)),
                chunks(np.take(x, owner, axis=0)))
    outs = [flips.face_flips_at(VQd, N0d, ff, ii, kk, xx, cos_max)
            for (_, ff), (_, ii), (_, kk), (_, xx) in parts]

    def result():
        bad = np.concatenate([np.asarray(o) for o in outs])[: len(F)] if outs else np.zeros(0, bool)
        res = np.zeros(S, bool)
        res[owner[bad]] = True
        return res
    return result


def _select(E, key_of, cand, need, n, validate):
    """Passes of independent-set selection with validation. Returns (accepted, rejected) pair indices,
    the extra faces (coincident ones) each accepted pair removes, (len(E),) int, and the vertices the
    accepted pairs lock (their endpoints' closed 1-rings through E), (n,) bool.

    E (P,2) are all candidate pairs (mesh edges and, with aggregation, close vertex pairs): the conflict
    graph. ``key_of(idx)`` gives the (unique) int64 keys of pairs idx (`_sort_keys`).
    ``validate(pairs, idx, rows, pairs_at_free)`` (rows: the indices of pairs_at_free in E) returns
    (ok, extra faces removed).

    Each pass takes the candidates that hold the smallest key among all candidates touching their
    endpoints' closed 1-rings, validates them (flips, duplicate faces, link condition), and locks the
    1-rings of the accepted ones. Later passes only look at what is still free, so they cost little.
    """
    def narrow(avail, ws, split=True):
        """Working sets, narrowed to what touches ``avail`` vertices: pairs with an available endpoint
        (locking, link test) and their rows, and which of those have both endpoints available
        (selection). Large sets are split between this thread and the worker (idle here)."""
        one, Eo, _ = ws
        if split and len(Eo) >= SPLIT_ROWS:
            h = len(Eo) // 2
            half = _submit(narrow, avail, (one[:h], Eo[:h], None), split=False)
            rest = narrow(avail, (one[h:], Eo[h:], None), split=False)
            return tuple(np.concatenate(pair) for pair in zip(half.result(), rest))
        ae = np.take(avail, Eo).view(np.uint16).reshape(-1)  # two bools per edge: 0x0101 = both
        k1 = ae != 0
        return np.compress(k1, one), _keep(Eo, k1), np.compress(k1, ae) == 0x0101

    def endpoints(mask):
        v = np.zeros(n, bool)
        v[_keep(E, mask).reshape(-1)] = True
        return v

    free = np.ones(n, bool)
    # only vertices with a candidate pair matter: the rest never select and never conflict
    active = endpoints(cand)
    ws = narrow(active, (np.arange(len(E)), E, None))
    accepted, rejected = [], []
    extra = np.zeros(len(E), np.int64)
    n_acc = 0
    for p in range(MAX_PASSES):
        one, Eo, bmask = ws
        both, Eb = np.compress(bmask, one), _keep(Eo, bmask)
        live = cand[both]
        if not live.any():
            break
        kl = np.where(live, key_of(both), NO_KEY)
        m1 = np.full(n, NO_KEY)
        np.minimum.at(m1, Eb[:, 0], kl)
        np.minimum.at(m1, Eb[:, 1], kl)
        m2 = m1.copy()
        np.minimum.at(m2, Eb[:, 0], np.take(m1, Eb[:, 1]))
        np.minimum.at(m2, Eb[:, 1], np.take(m1, Eb[:, 0]))
        sel = np.compress(live & (kl == np.take(m2, Eb[:, 0])) & (kl == np.take(m2, Eb[:, 1])), both)
        if sel.size == 0:
            break
        ok, extra_sel = validate(_take(E, sel), sel, one, Eo)
        extra[sel] = extra_sel
        cand[sel[~ok]] = False
        rejected.append(sel[~ok])
        good = sel[ok]
        accepted.append(good)
        # lock the closed 1-rings of accepted endpoints; shrink the working sets to what is free
        lock = np.zeros(n, bool)
        lock[_take(E, good).reshape(-1)] = True
        free[_keep(Eo, any_at(lock, Eo)).reshape(-1)] = False
        n_acc += good.size
        if good.size < PASS_YIELD * n_acc or (good.size * 50 < need // 2 and p > 2):
            break  # later passes would add little: leave the rest to the next round
        if p + 1 < MAX_PASSES:
            ws = narrow(active & free, ws)
    cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0, np.int64)  # noqa: E731
    return cat(accepted), cat(rejected), extra, ~free


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
    E = topo.key_pairs(keys, n, E.dtype)
    return E, np.concatenate([ecount, np.zeros(len(xk), np.int64)])[order]


def _validate(P, idx, free_rows, Efree, *, ctx):
    """(ok, faces made coincident) for vertex-disjoint pairs P (indices idx into this round's pairs).
    Efree (rows free_rows of this round's pairs) holds every pair at them; the faces come from
    ``ctx.faces`` (`FaceLists`). In manifold mode the link test runs on the worker thread. What the
    contraction will need again (the faces' look-up and, in manifold mode, the apexes and the pairs at
    the endpoints that the link test found, for `topo.contract_edges`) is appended to ``ctx.found``."""
    tv = time.perf_counter()
    if ctx.settings.preserve_topology:
        link = _submit(topo.link_ok, P, ctx.ecount[idx], Efree, ctx.n, ctx.bvert, ctx.deg, apexes=True,
                       edges_at=True)
    (fids, before, corner, owner, G), kept, dead = ctx.faces.touched_with_dead(P)
    flipped = _flip_bad(ctx.VQd, ctx.N0d, before, fids, corner, owner,
                        _take(ctx.x, idx), len(P), ctx.settings)  # runs while the host tests the rest
    gone = topo.coincidence_count(G, owner, len(P))
    ok = np.ones(len(P), bool)
    at = None
    if ctx.settings.preserve_topology:  # no coincident faces, link condition
        linked, apex, r, owner_r = link.result()
        ok = (gone == 0) & linked
        at = (apex, np.take(free_rows, r), owner_r)
    ctx.found.append((idx, kept, dead, at))
    ok &= ~flipped()
    ctx.timer.add("validity_s", time.perf_counter() - tv)
    return ok, gone


def _accepted(E, found, take):
    """The pairs marked in ``take`` (len(E),) bool with what validation found for them (``found``: pair
    indices, kept faces, dead faces and, in manifold mode, (apexes, rows of E at the endpoints, their
    pairs) per pass; `FaceLists.touched_with_dead`, `topo.link_ok`), renumbered as one set in pass
    order: pairs (S,2), the arguments ``kept`` and ``dead`` of `FaceLists.contract_touched`, and the
    apexes (S,2) and the rows of E at the endpoints (None outside manifold mode)."""
    pairs, ws, fs, cs, ds, xs, rs = [], [], [], [], [], [], []
    off = 0
    for idx, (w, f, c), (df, downer), at in found:
        t = take[idx]
        pos = np.cumsum(t) - 1 + off  # each taken pair's place in the combined set
        keep = np.take(t, w >> 1)
        wk = np.compress(keep, w)
        ws.append(2 * np.take(pos, wk >> 1) + (wk & 1))
        fs.append(np.compress(keep, f))
        cs.append(np.compress(keep, c))
        ds.append(np.compress(np.take(t, downer), df))
        pairs.append(_take(E, np.compress(t, idx)))
        if at is not None:
            apex, rows, owner = at
            xs.append(_keep(apex, t))
            rs.append(np.compress(np.take(t, owner), rows))
        off += int(t.sum())
    cat = np.concatenate
    return cat(pairs), (cat(ws), cat(fs), cat(cs)), cat(ds), (cat(xs), cat(rs)) if xs else (None, None)


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


def _touched_vertices(faces: FaceLists, P, n):
    """(n,) bool: endpoints of the pairs P and every vertex sharing a face with one."""
    t = np.zeros(n, bool)
    t[P.reshape(-1)] = True
    t[_take(faces.F, faces.around(P.reshape(-1))[1]).reshape(-1)] = True
    return t


def _drop_coincident(faces: FaceLists, kept):
    """Resolve faces that coincide after contractions into the vertices ``kept`` (all such faces touch
    one), lower face index first (`topo.coincident_removals`)."""
    f = np.unique(faces.around(kept)[1])
    faces.remove(f[topo.coincident_removals(_take(faces.F, f))])


def _history_arrays(rounds):
    """Per-round (kept, removed, positions, costs) -> pairs (k,2) int64, positions (k,3), costs (k,)."""
    if not rounds:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0)
    pairs = np.concatenate([np.stack([a, b], 1) for a, b, _, _ in rounds]).astype(np.int64)
    return pairs, np.concatenate([x for _, _, x, _ in rounds]), np.concatenate([c for _, _, _, c in rounds])


def run(V, Q, F, extra_pairs, target_faces, settings: Settings, progress=None, edges=None):
    """Simplify. V (n,3) float32 normalised positions, Q (n,10) quadrics, F (m,3) int64 faces,
    extra_pairs (k,2) non-edge pairs that may also contract (aggregation; k may be 0); ``edges``:
    `topo.edges` of F when the caller has it.
    Returns (V, Q, F, alive, history, info): F (m,3) rows are the input faces re-linked, alive (m,)
    marks the survivors, history = (pairs (k,2), positions (k,3), costs (k,)) in contraction order."""
    n, m = len(V), len(F)
    manifold = settings.preserve_topology
    n_cap = bucket(n + 1)
    VQ = np.zeros((n_cap, 13), DTYPE)  # rows [position, quadric]
    VQ[:n, :3], VQ[:n, 3:] = V, Q
    extra_pairs = np.asarray(extra_pairs, np.int32).reshape(-1, 2)
    VQd = jnp.asarray(VQ)  # device copy, updated row by row
    first = None  # the first costing of the given edges runs while the host sets up the faces
    if edges is not None and len(extra_pairs) == 0:
        first = _place(VQd, edges[0], settings)
    # int32 rows (n < 2**31) keep their index: face i continues input face i; built on the worker
    # while this thread computes the input normals
    lists = _submit(FaceLists, F, n)
    N0 = face_normals(np.asarray(V, DTYPE), F)  # input normals
    N0d = jnp.asarray(pad_rows(N0, bucket(m)))  # padded: one compilation per size class
    faces = lists.result()
    timer = Timer()
    history = []
    branches = np.zeros(3, np.int64)
    rounds = rejected = 0
    max_cost_used = 0.0
    faces_per_round = []
    prev = None  # (targets, costs, branches, known invalid, moved vertices, keys) of the last round's edges
    # manifold mode: the edges are updated through each round's contractions instead of rebuilt
    incremental = manifold and len(extra_pairs) == 0
    updated = None  # (E, ecount, rows kept, degree, rows at moved vertices) after a round, when incremental
    while faces.count > target_faces:
        rounds += 1
        t0 = time.perf_counter()
        ekeys = same = None
        if updated is None:
            E, ecount = topo.edges(faces.live(), n) if edges is None else (edges[0].astype(np.int32), edges[1])
            edges = None
            E, ecount = _with_extra_pairs(E, ecount, extra_pairs, n)
            deg = topo.vertex_degree(E if incremental else _keep(E, ecount > 0), n)
            if not incremental:
                ekeys = topo.edge_keys(E[:, 0], E[:, 1], n)  # sorted, as E is
            if prev is not None:  # rebuilt: find each edge's predecessor by key
                src = np.minimum(np.searchsorted(prev[5], ekeys), len(prev[5]) - 1)
                same = prev[5][src] == ekeys
                follow = functools.partial(_take, indices=src)
        else:
            E, ecount, kept, deg, dirty = updated
            follow = functools.partial(_take, indices=np.flatnonzero(kept))  # several arrays: indices once
        # start re-costing the pairs at vertices the last round moved (the rest keep their cost and
        # target); the kernel runs while the host goes on
        if prev is None:
            d, pending = None, first or _place(VQd, E, settings)
            known_bad = np.zeros(len(E), bool)
        else:
            px, pcost, pbranch, pbad, changed, _ = prev
            if updated is None:
                dirty = any_at(changed, E)
            if same is not None:
                dirty |= ~same
            d = np.flatnonzero(dirty)
            pending = _place(VQd, _take(E, d), settings)
            known_bad = follow(pbad)  # found invalid, and their neighbourhood has not changed since
            if same is not None:
                known_bad &= same
        bvert = np.zeros(n, bool)
        bvert[_keep(E, ecount == 1).reshape(-1)] = True
        timer.add("topology_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        if d is None:
            x, cost, branch = pending()
        else:
            # separate arrays, each under 32 MB at 2 M edges: glibc maps larger ones afresh every time
            # (page faults on every round; one (E,5) array was slower to gather here)
            x, cost, branch = follow(px), follow(pcost), follow(pbranch)
            xd, cost[d], branch[d] = pending()
            put_rows(x, d, xd)
        timer.add("kernels_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        need = faces.count - target_faces
        n_alive = len(E)  # ~3× the live vertices; only the ratio matters for the gate
        valid = (cost <= settings.max_cost) & ~known_bad & (ecount <= need)
        if manifold:
            valid &= (ecount >= 1) & (ecount <= 2)
        if not valid.any():
            break
        k = min(max(need // (2 * TAIL), 1), int(valid.sum()), max(int(GATE_FRACTION * n_alive), 1))
        kth = np.partition(np.compress(valid, cost), k - 1)[k - 1]
        key_of = functools.partial(_sort_keys, cost, salt=rounds * 7919)
        cand = valid & (cost <= max(GATE * kth, FREE_COST))

        ctx = SimpleNamespace(VQd=VQd, N0d=N0d, faces=faces, x=x, ecount=ecount, bvert=bvert, deg=deg, n=n,
                              settings=settings, timer=timer, found=[])
        acc, bad, extra, locked = _select(E, key_of, cand, need, n, functools.partial(_validate, ctx=ctx))
        rejected += bad.size
        n_sel = acc.size
        acc = acc[np.argsort(key_of(acc), kind="stable")]
        acc = acc[_fits_target(ecount[acc] + extra[acc], need)]
        timer.add("select_s", time.perf_counter() - t0)
        known_bad[bad] = True
        if acc.size == 0:
            if bad.size:  # the invalid ones are out now: select again among the rest (same edges)
                prev = (x, cost, branch, known_bad, np.zeros(n, bool), ekeys)
                if incremental:
                    updated = (E, ecount, np.ones(len(E), bool), deg, np.zeros(len(E), bool))
                continue
            break

        t0 = time.perf_counter()
        P = _take(E, acc)
        a, b = P[:, 0], P[:, 1]
        xs = _take(x, acc)
        merged = _merged(VQd, P, xs)  # runs during the host's contraction below
        changed = np.zeros(n, bool)
        changed[a] = True
        branches += np.bincount(branch[acc], minlength=3)
        max_cost_used = max(max_cost_used, float(cost[acc].max()))
        history.append((a.copy(), b.copy(), xs, cost[acc].astype(np.float64)))
        r = np.flatnonzero(known_bad)
        if r.size:  # pairs whose faces change get another chance
            # the 1-rings that selection locked, unless the target cut the set short
            touched = locked if acc.size == n_sel else _touched_vertices(faces, P, n)
            known_bad[r[any_at(touched, _take(E, r))]] = False
        prev = (x, cost, branch, known_bad, changed, ekeys)
        taken = np.zeros(len(E), bool)
        taken[acc] = True
        pairs, kept, dead, (apex, erows) = _accepted(E, ctx.found, taken)  # in pass order, not acc's
        if incremental:  # the edge update runs on the worker while this thread relinks the faces
            edges_next = _submit(topo.contract_edges, E, ecount, pairs[:, 0], pairs[:, 1], apex, n, deg,
                                 rows=erows)
        faces.contract_touched(pairs, kept, dead)
        if not manifold:
            _drop_coincident(faces, a)
        if len(extra_pairs):
            rep = np.arange(n, dtype=np.int32)
            rep[b] = a
            extra_pairs = rep[extra_pairs]
            extra_pairs = extra_pairs[extra_pairs[:, 0] != extra_pairs[:, 1]]
        rows = np.concatenate([xs, merged()], 1)  # the kept vertices' new [position, quadric]
        put_rows(VQ, a, rows)
        VQd = set_rows(VQd, a, rows, size=MERGE_CHUNK)
        if incremental:
            updated = edges_next.result()
        faces_per_round.append(faces.count)
        timer.add("contract_s", time.perf_counter() - t0)
        if progress is not None:
            progress(faces.count)
    hist = _history_arrays(history)
    info = {"contractions": len(hist[0]), "rejected": rejected, "rounds": rounds, "max_cost": max_cost_used,
            "branches": branches, "faces_per_round": faces_per_round}
    info.update(timer.t)
    return VQ[:n, :3], VQ[:n, 3:], faces.F, faces.alive, hist, info
