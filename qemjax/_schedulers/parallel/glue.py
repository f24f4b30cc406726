"""The parallel round's glue, compiled: what a run's round does between its compiled loops (`selection`, `contraction`) and
its one device call, as four calls instead of dozens of numpy calls on small arrays.

On a small mesh a round's own work is a few tens of µs, and the numpy calls around it (each a few µs: take,
put, compress, bincount, ...) cost more than the work (docs/benchmarks.md; `experiments/figures/round_floor.py` measures it). These loops take the same values from the same arrays, so the golden outputs
stay the same bits; tests/test_round_glue.py compares each with the numpy code it replaces on random
inputs. They serve one run on the compiled path (`parallel.GlueRound`; `under_gate` and `order_fit` also a
`parallel.LoopRound`'s): a batch's gates and budgets are per copy (`batched`).

* `carry`: stages 1 and 2 and the candidate test (`parallel.Round.update`, `.cost`, `.candidates`): the pairs
  that stay take their last prices and rules, the stale ones the device's new prices (with locks: as
  `locks.adjust` leaves them), pairs of two locked vertices are refused, and the boundary vertices and the
  candidates are marked;
* `under_gate`: the round's gate (`parallel.Round.select`), the candidates at most gate × the k-th cheapest valid key
  (or the free cost);
* `order_fit`: the accepted pairs in key order, cut to the face target (`select.sort_keys`,
  `select.fits_target`);
* `contract`: the rejections cleared around the round, the faces and pairs contracted (`contraction`), the
  positions written, the stale pairs listed, and the device call's inputs padded to their shapes; it takes
  the round's arrays bundled (`PairArrays`, `FaceArrays`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..._mesh.compiled import njit
from ..outcome import LOCKED
from .contraction import clear_bad, contract_edges, contract_faces
from .selection import _key


def bound(limit, dtype) -> np.generic:
    """max_error's cost bound as numpy compares it with costs of ``dtype``: a Python float becomes one of
    that dtype (numpy's weak scalars), a numpy float keeps its own precision (overflow: infinity)."""
    with np.errstate(over="ignore"):
        return np.asarray(limit, np.result_type(dtype, limit))[()]


class Known(NamedTuple):
    """What the last round knew of its pairs, as `carry` takes it: x (P0,3), cost (P0,), branch (P0,) int8,
    parts (P0, p), bad (P0,) int8."""

    x: np.ndarray
    cost: np.ndarray
    branch: np.ndarray
    parts: np.ndarray
    bad: np.ndarray


@njit(cache=True, nogil=True)
def carry(kept, d, out, last, E, ecount, n, test, locked):
    """The new pairs' prices, rules, boundary vertices and candidates.

    kept (P0,) bool: which of the last round's pairs stay, in order (`contraction.contract_edges`); d (K,):
    the rows of the new pairs E (P,2) whose price is stale; out (5 + p, ≥ K): the device's price of them
    ([x (3), cost, branch, parts] per column, `device.start_step`; a run with locks: as `locks.adjust`
    leaves it); last: the last round's arrays (a `Known`, passed as a plain tuple); test: the candidate
    test's (max_error's cost bound (`bound`), the faces still to remove, manifold mode); locked (n,) bool
    (empty: no locks): a pair of two locked vertices is marked `outcome.LOCKED` (`locks.both_locked`, as
    `parallel.Round.cost` marks every pair each round). Returns x, cost, branch, parts, bad, the boundary
    vertices (n,) bool, the candidates (P,) bool (`parallel.Round.candidates`) and how many there are."""
    x0, cost0, branch0, parts0, bad0 = last
    limit, need, manifold = test
    P = len(E)
    p = parts0.shape[1]
    x = np.empty((P, 3), x0.dtype)
    cost = np.empty(P, cost0.dtype)
    branch = np.empty(P, np.int8)
    parts = np.empty((P, p), parts0.dtype)
    bad = np.empty(P, np.int8)
    j = 0
    for i in range(len(kept)):
        if kept[i]:
            x[j, 0], x[j, 1], x[j, 2] = x0[i, 0], x0[i, 1], x0[i, 2]
            cost[j], branch[j], bad[j] = cost0[i], branch0[i], bad0[i]
            for c in range(p):
                parts[j, c] = parts0[i, c]
            j += 1
    for t in range(len(d)):
        i = d[t]
        x[i, 0], x[i, 1], x[i, 2] = out[0, t], out[1, t], out[2, t]
        cost[i] = out[3, t]
        branch[i] = np.int8(out[4, t])
        for c in range(p):
            parts[i, c] = out[5 + c, t]
    bvert = np.zeros(n, np.bool_)
    valid = np.empty(P, np.bool_)
    nv = 0
    locks = len(locked) > 0
    for i in range(P):
        if locks and locked[E[i, 0]] and locked[E[i, 1]]:
            bad[i] = LOCKED
        c = ecount[i]
        if c == 1:
            bvert[E[i, 0]] = True
            bvert[E[i, 1]] = True
        ok = cost[i] <= limit and bad[i] == 0 and c <= need
        if manifold:
            ok = ok and c >= 1 and c <= 2
        valid[i] = ok
        if ok:
            nv += 1
    return x, cost, branch, parts, bad, bvert, valid, nv


@njit(cache=True, nogil=True)
def under_gate(key, valid, thr, E, free_v):
    """(P,) bool: the candidates whose key is at most the gate: ``thr`` (numpy's maximum of gate × k-th and
    the free cost), or with free_v (n,) (the free cost at each vertex's part scale; empty: none) the
    larger of thr and free_v at the pair's first vertex, in numpy's promotion of the two."""
    P = len(key)
    cand = np.empty(P, np.bool_)
    if len(free_v) == 0:
        for i in range(P):
            cand[i] = valid[i] and key[i] <= thr
    else:
        for i in range(P):
            f = free_v[E[i, 0]]
            t = thr if (thr >= f or thr != thr) else f  # np.maximum: the larger, NaN if either is
            cand[i] = valid[i] and key[i] <= t
    return cand


@njit(cache=True, nogil=True)
def order_fit(acc, apex, key, ecount, salt, need, cnt, E):
    """The accepted pairs ``acc`` (pass order) and their apexes (S,2) in the order of their sort keys
    (`select.sort_keys` of ``key`` with the round's salt), cut as `select.fits_target` cuts them to the
    faces still needed (ecount: the faces each removes). Returns (pairs, apexes, the pool room their
    contraction takes: Σ cnt at both endpoints)."""
    S = len(acc)
    keys = np.empty(S, np.int64)
    kbits = key.view(np.int32)
    for s in range(S):
        keys[s] = _key(kbits, acc[s], acc[s], salt)
    order = np.argsort(keys, kind="mergesort")
    take = np.zeros(S, np.bool_)
    left = need
    m = 0
    for s in range(S):  # in order: each that still fits (fits_target's prefix, then its fill, is this)
        r = ecount[acc[order[s]]]
        if r <= left:
            take[s] = True
            left -= r
            m += 1
    out = np.empty(m, acc.dtype)
    ap = np.empty((m, 2), apex.dtype)
    room = 0
    j = 0
    for s in range(S):
        if take[s]:
            i = order[s]
            out[j] = acc[i]
            ap[j, 0], ap[j, 1] = apex[i, 0], apex[i, 1]
            room += cnt[E[acc[i], 0]] + cnt[E[acc[i], 1]]
            j += 1
    return out, ap, room


class PairArrays(NamedTuple):
    """A round's pairs and what is known of them, as `contract` takes them (`RoundState`'s arrays): E (P,2),
    ecount (P,), deg (n,), bad (P,) int8, and the prices x (P,3), cost (P,), branch (P,) int8."""

    E: np.ndarray
    ecount: np.ndarray
    deg: np.ndarray
    bad: np.ndarray
    x: np.ndarray
    cost: np.ndarray
    branch: np.ndarray


class FaceArrays(NamedTuple):
    """The vertex->face lists' arrays (`FaceLists`: F, alive, cnt, off, pool), as `contract` takes them."""

    F: np.ndarray
    alive: np.ndarray
    cnt: np.ndarray
    off: np.ndarray
    pool: np.ndarray


@njit(cache=True, nogil=True)
def contract(pairs, faces, end, rows, taken, counts, label, shapes):
    """The round's contraction of the accepted pairs, in one call. ``pairs``: a `PairArrays`, ``faces`` a
    `FaceArrays` (each passed as a plain tuple: numba types it by its fields) and the pool's ``end`` (the
    pool must have room); ``rows``: the host's rows (V3 positions, VQ [position, state]); ``taken``: the
    vertices whose rejections are cleared (touched (n,) bool), the accepted pairs' rows (acc (S,)) and their
    apexes (S,2); ``counts``: the branch counts to add to; ``label``: `contraction.contract_edges`' scratch;
    ``shapes``: (the device rows, the merge piece, the smallest price shape).

    Known rejections are cleared where touched (`contraction.clear_bad`), the faces (`contraction.contract_faces`)
    and the pairs (`contraction.contract_edges`) contracted, the kept rows moved in V3 and in the first three
    columns of VQ (their states follow with the device call). Returns the kept and removed vertices, their
    positions, costs (float64) and the largest, the pool's new end, the dead faces, `contract_edges`' result,
    the stale rows d of the new pairs, and the device call's inputs when one piece holds them (`device.step_one`):
    kept rows padded with the device rows' count, pairs, positions, stale pairs (else empty)."""
    E, ecount, deg, bad, x, cost, branch = pairs
    F, alive, cnt, off, pool = faces
    V3, VQ = rows
    touched, acc, apex = taken
    n_rows, size, price_size = shapes
    clear_bad(E, bad, touched)
    S = len(acc)
    a = np.empty(S, E.dtype)
    b = np.empty(S, E.dtype)
    xs = np.empty((S, 3), x.dtype)
    c64 = np.empty(S, np.float64)
    top = -np.inf
    for s in range(S):
        i = acc[s]
        a[s], b[s] = E[i, 0], E[i, 1]
        xs[s, 0], xs[s, 1], xs[s, 2] = x[i, 0], x[i, 1], x[i, 2]
        c64[s] = cost[i]
        if cost[i] > top:
            top = cost[i]
        if branch[i] < 0 or branch[i] >= len(counts):
            raise ValueError("a price's branch is not one of the model's branches")
        counts[branch[i]] += 1
    end, dead = contract_faces(a, b, F, alive, cnt, off, pool, end)
    E3, c3, keep, d2, s3 = contract_edges(E, ecount, deg, a, b, apex, label)
    for s in range(S):
        V3[a[s], 0], V3[a[s], 1], V3[a[s], 2] = xs[s, 0], xs[s, 1], xs[s, 2]
        VQ[a[s], 0], VQ[a[s], 1], VQ[a[s], 2] = xs[s, 0], xs[s, 1], xs[s, 2]
    d = np.flatnonzero(s3)
    nd = len(d)
    one = S <= size and nd <= price_size
    rows = np.full(size if one else 0, n_rows, np.int32)
    pp = np.zeros((size if one else 0, 2), np.int32)
    xx = np.zeros((size if one else 0, 3), x.dtype)
    qq = np.zeros((price_size if one else 0, 2), np.int32)
    if one:
        for s in range(S):
            rows[s] = a[s]
            pp[s, 0], pp[s, 1] = a[s], b[s]
            xx[s, 0], xx[s, 1], xx[s, 2] = xs[s, 0], xs[s, 1], xs[s, 2]
        for t in range(nd):
            qq[t, 0], qq[t, 1] = E3[d[t], 0], E3[d[t], 1]
    return a, b, xs, c64, top, end, dead, (E3, c3, keep, d2, s3), d, (rows, pp, xx, qq)
