"""Independent-set scheduler: many non-interacting contractions per round.

A round:
1. cost every current edge with the batched placement kernel (fixed-size chunks: one compilation);
2. select, in passes, pairs that are the cheapest among all candidate pairs touching their endpoints'
   closed 1-rings (ties broken by pair index through an int64 key), so no two selected pairs share a
   vertex, a face or a 1-ring neighbour; validate them (flip kernel, link test); invalid ones leave the
   candidate set, valid ones lock their 1-rings, and the next pass selects among what is still free;
3. contract the accepted set at once (vectorised remap, quadric sums, degenerate-face removal).
Because accepted contractions are two edges apart, the validity computed for each stays true when all
happen together. The last round takes only as many, in cost order, as the exact face target allows.
"""
from __future__ import annotations

import time

import jax.numpy as jnp
import numpy as np

from .. import _topology as topo
from .._kernels import flips, placement
from .common import DTYPE, Settings, Timer, bucket, chunk_size, pad_rows

MAX_PASSES = 8
GATE = 1.5  # take pairs up to GATE × the cost of the k-th cheapest, k = contractions still needed
NO_KEY = np.iinfo(np.int64).max


def _sort_keys(cost: np.ndarray) -> np.ndarray:
    """Unique, monotonic int64 keys: float32 cost bits (non-negative) in the high word and a fixed
    bijective scramble of the pair index in the low word. Ties (flat regions have many exact zeros)
    are broken deterministically but in a spatially incoherent order: breaking them by raw index would
    make neighbouring pairs form long descending chains with one local minimum each."""
    bits = np.ascontiguousarray(cost, dtype=np.float32).view(np.int32).astype(np.int64)
    h = (np.arange(len(cost), dtype=np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFFFF)
    h ^= h >> np.uint64(16)  # xorshift: still a bijection on 32 bits
    return (bits << 32) | h.astype(np.int64)


def _chunks(arr: np.ndarray, fill=0):
    """Split rows into equal padded pieces of a bucketed size (see `chunk_size`)."""
    size = chunk_size(len(arr))
    for s in range(0, max(len(arr), 1), size):
        yield s, pad_rows(arr[s:s + size], size, fill)


def _place(Vd, Qd, P, settings, outputs=(0, 1)):
    """Placement outputs (x, cost, branch, qsum; those named in ``outputs``) for index pairs P (K,2)."""
    args = settings.kernel_args()
    outs = [placement.place_pairs(Vd, Qd, part, *args) for _, part in _chunks(P.astype(np.int32))]
    return [np.concatenate([np.asarray(o[k]) for o in outs])[: len(P)] for k in outputs]


def _flip_bad(Vd, F, N0, n_cap, pairs, x, settings):
    """(S,) bool: does contracting pairs (vertex-disjoint) to x flip any surviving face?"""
    S = len(pairs)
    moved = np.zeros(n_cap, bool)
    target = np.zeros((n_cap, 3), DTYPE)
    partner = np.full(n_cap, -1, np.int32)
    a, b = pairs[:, 0], pairs[:, 1]
    moved[a] = moved[b] = True
    target[a] = target[b] = x
    partner[a], partner[b] = b, a
    tf = np.flatnonzero(moved[F].any(1))
    touched, ref = F[tf], N0[tf]
    acc = jnp.zeros(n_cap, bool)
    md, td, pd = jnp.asarray(moved), jnp.asarray(target), jnp.asarray(partner)
    cos_max = np.asarray(settings.cos_max, DTYPE)
    for (s, part), (_, rpart) in zip(_chunks(touched.astype(np.int32)), _chunks(ref)):
        fmask = np.arange(len(part)) < len(touched) - s
        acc = flips.flip_votes(Vd, part, fmask, rpart, td, pd, md, cos_max, acc)
    acc = np.asarray(acc)
    return acc[a] | acc[b] if S else np.zeros(0, bool)


def run(V, Q, F, pairs_unused, target_faces, settings: Settings, progress=None):
    """Same contract as `greedy.run`."""
    n = len(V)
    n_cap = bucket(n + 1)
    V = pad_rows(V.astype(DTYPE), n_cap)
    Q = pad_rows(Q.astype(DTYPE), n_cap)
    F = F.copy()
    fid = np.arange(len(F))  # input face each current face continues
    p = V[F]
    N0 = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).astype(DTYPE)  # input normals, by fid
    timer = Timer()
    history = []
    branches = np.zeros(3, np.int64)
    rounds = rejected = 0
    max_cost_used = 0.0
    removed_per_round = []
    invalid_keys = np.zeros(0, np.int64)  # edges found invalid whose neighbourhood has not changed since
    while len(F) > target_faces:
        rounds += 1
        t0 = time.perf_counter()
        E, ecount = topo.edges(F, n)
        deg = topo.vertex_degree(E, n)
        bvert = np.zeros(n, bool)
        bvert[E[ecount == 1].reshape(-1)] = True
        timer.add("topology_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        Vd, Qd = jnp.asarray(V), jnp.asarray(Q)
        x, cost = _place(Vd, Qd, E, settings)
        timer.add("kernels_s", time.perf_counter() - t0)

        t0 = time.perf_counter()
        need = len(F) - target_faces
        ekeys = E[:, 0] * n + E[:, 1]
        known_bad = np.zeros(len(E), bool)
        if invalid_keys.size:
            pos = np.minimum(np.searchsorted(invalid_keys, ekeys), invalid_keys.size - 1)
            known_bad = invalid_keys[pos] == ekeys
        valid = (cost <= settings.max_cost) & ~known_bad & (ecount <= need)
        if settings.preserve_topology:
            valid &= (ecount >= 1) & (ecount <= 2)
        if not valid.any():
            break
        k = min(max(need // 2, 1), int(valid.sum()))
        kth = np.partition(cost[valid], k - 1)[k - 1]
        key = _sort_keys(cost)
        free = np.ones(n, bool)
        accepted = []
        rejected_now = []
        cand = valid & (cost <= max(GATE * kth, kth))
        for _ in range(MAX_PASSES):
            live = cand & free[E[:, 0]] & free[E[:, 1]]
            if not live.any():
                break
            kl = np.where(live, key, NO_KEY)
            m1 = np.full(n, NO_KEY)
            np.minimum.at(m1, E[:, 0], kl)
            np.minimum.at(m1, E[:, 1], kl)
            m2 = m1.copy()
            np.minimum.at(m2, E[:, 0], m1[E[:, 1]])
            np.minimum.at(m2, E[:, 1], m1[E[:, 0]])
            sel = np.flatnonzero(live & (kl == m2[E[:, 0]]) & (kl == m2[E[:, 1]]))
            if sel.size == 0:
                break
            tv = time.perf_counter()
            ok = ~_flip_bad(Vd, F, N0[fid], n_cap, E[sel], x[sel], settings)
            ok &= ~topo.creates_duplicates(F, E[sel], n)
            if settings.preserve_topology:
                ok &= topo.link_ok(E[sel], E, ecount, n, bvert, deg)
            timer.add("validity_s", time.perf_counter() - tv)
            rejected += int((~ok).sum())
            cand[sel[~ok]] = False
            valid[sel[~ok]] = False
            rejected_now.append(sel[~ok])
            good = sel[ok]
            accepted.append(good)
            # lock the closed 1-rings of accepted endpoints
            lock = np.zeros(n, bool)
            lock[E[good].reshape(-1)] = True
            ring = lock[E[:, 0]] | lock[E[:, 1]]
            free[E[ring].reshape(-1)] = False
            if good.size * 50 < need // 2 and _ > 2:
                break
            if not any(a.size for a in accepted) and not (cand & free[E[:, 0]] & free[E[:, 1]]).any():
                cand = valid.copy()  # everything under the gate was invalid: widen it
        acc = np.concatenate(accepted) if accepted else np.zeros(0, np.int64)
        acc = acc[np.argsort(key[acc], kind="stable")]
        # exact target: take in cost order only what keeps faces >= target
        fr = np.where(ecount[acc] >= 1, ecount[acc], 0)
        csum = np.cumsum(fr)
        if csum.size and csum[-1] > need:
            take = csum <= need
            rest = np.flatnonzero(~take)
            left = need - (csum[take][-1] if take.any() else 0)
            for i in rest:  # a few: fill the remainder with contractions that still fit
                if fr[i] <= left:
                    take[i] = True
                    left -= fr[i]
            acc = acc[take]
        timer.add("select_s", time.perf_counter() - t0)
        bad_now = np.concatenate(rejected_now) if rejected_now else np.zeros(0, np.int64)
        invalid_keys = np.union1d(invalid_keys, ekeys[bad_now]) if bad_now.size else invalid_keys
        if acc.size == 0:
            if bad_now.size:
                continue
            break

        t0 = time.perf_counter()
        P = E[acc]
        a, b = P[:, 0], P[:, 1]
        xs, br, qs = _place(Vd, Qd, P, settings, (0, 2, 3))
        V[a] = xs
        Q[a] = qs
        branches += np.bincount(br, minlength=3)
        max_cost_used = max(max_cost_used, float(cost[acc].max()))
        history.append((a.copy(), b.copy(), xs, cost[acc].astype(np.float64)))
        rep = np.arange(n)
        rep[b] = a
        touched = np.zeros(n, bool)
        touched[a] = touched[b] = True
        touched[F[touched[F].any(1)].reshape(-1)] = True  # every vertex whose faces change
        if invalid_keys.size:
            iu, iw = invalid_keys // n, invalid_keys % n
            invalid_keys = invalid_keys[~(touched[iu] | touched[iw])]
        F = rep[F]
        deg_f = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
        F, fid = F[~deg_f], fid[~deg_f]
        removed_per_round.append(acc.size)
        timer.add("contract_s", time.perf_counter() - t0)
        if progress is not None:
            progress(len(F))
    alive = np.zeros(len(fid) and fid.max() + 1 or 0, bool)
    Fout = np.zeros((len(alive), 3), F.dtype)
    Fout[fid] = F
    alive[fid] = True
    hist = []
    for a, b, xs, cs in history:
        hist.extend(zip(a.tolist(), b.tolist(), xs, cs.tolist()))
    info = {"contractions": len(hist), "rejected": rejected, "rounds": rounds, "max_cost": max_cost_used,
            "branches": branches, "removed_per_round": removed_per_round}
    info.update(timer.t)
    return V[:n], Q[:n], Fout, alive, hist, info
