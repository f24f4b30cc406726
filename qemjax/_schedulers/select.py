"""Choosing a round's contractions: unique sort keys, the independent-set passes, the exact face target.

Selection works on int64 keys (float32 cost bits over a scramble of the pair index), so per-vertex minima
need no sort and ties are broken the same way on every machine.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from .._mesh.arrays import any_at, keep_rows as _keep, take_rows as _take
from .._options import Schedule

NO_KEY = np.iinfo(np.int64).max
SPLIT_ROWS = 1 << 18  # array passes at least this long are shared with the worker thread
# work on fewer rows than this runs on the calling thread: waking the worker on another core costs more
# than the little it would overlap (experiments/probes/inline_rows.py)
INLINE_ROWS = 1 << 15
_worker = None  # one host thread beside the caller's: numpy releases the GIL in its large array passes


def submit(fn, *args, size: int | None = None, **kw):
    """Run fn on the host worker thread; returns its future. Only read-only inputs are shared.
    ``size``: the rows the work passes over; under `INLINE_ROWS` it runs here and now (the future is done)."""
    global _worker
    if size is not None and size < INLINE_ROWS:
        done = Future()
        try:
            done.set_result(fn(*args, **kw))
        except Exception as exc:  # raised by result(), as from the worker
            done.set_exception(exc)
        return done
    if _worker is None:
        _worker = ThreadPoolExecutor(1, thread_name_prefix="qemjax-host")
    return _worker.submit(fn, *args, **kw)


def sort_keys(cost: np.ndarray, idx: np.ndarray, salt: int = 0, offset: np.ndarray | None = None) -> np.ndarray:
    """Unique, monotonic int64 keys of pairs idx: float32 cost bits (non-negative) in the high word and a
    fixed bijective scramble of the pair index in the low word (a multiplication by an odd constant
    modulo 2³²). Ties (flat regions have many exact zeros) are broken deterministically but in a
    spatially incoherent order: breaking them by raw index would make neighbouring pairs form long
    descending chains with one local minimum each. Only the pairs asked for are keyed (a round looks
    at a small part of them). ``offset`` (P,): scramble ``idx - offset[idx]`` instead, each pair's index
    within its copy in a batched run (`batched`), so a copy breaks ties as it does alone."""
    bits = cost.take(idx).astype(np.float32, copy=False).view(np.int32).astype(np.int64)
    local = idx if offset is None else idx - offset.take(idx)
    h = local.astype(np.uint32) * np.uint32(0x9E3779B1) + np.uint32(salt & 0xFFFFFFFF)
    bits <<= 32
    bits |= h
    return bits


def independent_sets(E, key_of, cand, need, n, validate, schedule: Schedule, groups=None):
    """Passes of independent-set selection with validation. Returns (accepted, rejected) pair indices,
    the reason code of each rejected one (from ``validate``), the extra faces (coincident ones) each
    accepted pair removes, (len(E),) int, and the vertices the accepted pairs lock (their endpoints'
    closed 1-rings through E), (n,) bool.

    E (P,2) are all candidate pairs (mesh edges and, with aggregation, close vertex pairs): the conflict
    graph. ``key_of(idx)`` gives the (unique) int64 keys of pairs idx (`sort_keys`).
    ``validate(pairs, idx, pairs_at_free)`` (pairs_at_free: every pair of E at a free vertex) returns
    (reason code per pair, 0 = valid; extra faces removed).

    Each pass takes the candidates that hold the smallest key among all candidates touching their
    endpoints' closed 1-rings, validates them (flips, duplicate faces, link condition), and locks the
    1-rings of the accepted ones. Later passes only look at what is still free, so they cost little.
    """
    def narrow(avail, ws, split=True, first=0):
        """Working sets, narrowed to what touches ``avail`` vertices: pairs with an available endpoint
        (locking, link test) and their rows, and which of those have both endpoints available
        (selection). Large sets are split between this thread and the worker (idle here). ``ws`` rows
        None: its pairs are rows first, first + 1, ... of E (the first narrowing, without an arange)."""
        one, Eo, _ = ws
        if split and len(Eo) >= SPLIT_ROWS:
            h = len(Eo) // 2
            lo, hi = (None, None) if one is None else (one[:h], one[h:])
            half = submit(narrow, avail, (lo, Eo[:h], None), split=False, first=first)
            rest = narrow(avail, (hi, Eo[h:], None), split=False, first=first + h)
            return tuple(np.concatenate(pair) for pair in zip(half.result(), rest))
        ae = avail.take(Eo).view(np.uint16).reshape(-1)  # two bools per edge: 0x0101 = both
        k1 = ae != 0
        rows = np.flatnonzero(k1) + first if one is None else one.compress(k1)
        return rows, _keep(Eo, k1), ae.compress(k1) == 0x0101

    def endpoints(mask):
        from .._mesh.edge_lists import endpoints as marked  # numba: imported when first used

        return marked(E, mask, n)

    free = np.ones(n, bool)
    if groups is not None:
        # + accepted so far per copy, and which copies have left the passes (none yet)
        groups = (*groups, np.zeros(len(groups[1]), np.int64), np.zeros(len(groups[1]), bool))
    # only vertices with a candidate pair matter: the rest never select and never conflict
    active = endpoints(cand)
    ws = narrow(active, (None, E, None))
    accepted, rejected, reasons = [], [], []
    extra = np.zeros(len(E), np.int64)
    n_acc = 0
    for p in range(schedule.max_passes):
        one, Eo, bmask = ws
        both, Eb = one.compress(bmask), _keep(Eo, bmask)
        live = cand[both]
        if not live.any():
            break
        kl = np.where(live, key_of(both), NO_KEY)
        m1 = np.full(n, NO_KEY)
        np.minimum.at(m1, Eb[:, 0], kl)
        np.minimum.at(m1, Eb[:, 1], kl)
        m2 = m1.copy()
        np.minimum.at(m2, Eb[:, 0], m1.take(Eb[:, 1]))
        np.minimum.at(m2, Eb[:, 1], m1.take(Eb[:, 0]))
        sel = both.compress(live & (kl == m2.take(Eb[:, 0])) & (kl == m2.take(Eb[:, 1])))
        if sel.size == 0:
            break
        why, extra_sel = validate(_take(E, sel), sel, Eo)
        ok = why == 0
        extra[sel] = extra_sel
        cand[sel[~ok]] = False
        rejected.append(sel[~ok])
        reasons.append(why[~ok])
        good = sel[ok]
        accepted.append(good)
        # lock the closed 1-rings of accepted endpoints; shrink the working sets to what is free
        lock = np.zeros(n, bool)
        lock[_take(E, good).reshape(-1)] = True
        free[_keep(Eo, any_at(lock, Eo)).reshape(-1)] = False
        if groups is None:
            n_acc += good.size
            if good.size < schedule.pass_yield * n_acc or (good.size * 50 < need // 2 and p > 2):
                break  # later passes would add little: leave the rest to the next round
        else:
            stay = _copies_staying(groups, sel, good, p, schedule)
            if stay is None:
                break
            active &= stay
        if p + 1 < schedule.max_passes:
            ws = narrow(active & free, ws)
    cat = lambda xs, dt=np.int64: np.concatenate(xs) if xs else np.zeros(0, dt)  # noqa: E731
    return cat(accepted), cat(rejected), cat(reasons, np.int8), extra, ~free


def _copies_staying(groups, sel, good, p, schedule):
    """A batched run's pass rule (see `independent_sets`): (n,) bool, the vertices of the copies that go on
    to the next pass (a copy that selected nothing this pass is done), True when they are the same as
    after the last pass, or None when none goes on. Updates the per-copy accepted counts and the copies
    that have left in ``groups``."""
    vcopy, need, cp, n_acc, out = groups
    C = len(need)
    g = np.bincount(cp.take(good), minlength=C)
    tried = np.bincount(cp.take(sel), minlength=C) > 0
    n_acc += g
    done = ~tried | (g < schedule.pass_yield * n_acc) | ((g * 50 < need // 2) & (p > 2))
    if done.all():
        return None
    if not (done & ~out).any():  # no copy left the passes now: the vertex mask stays as it is
        return True
    out |= done
    return (~done).take(vcopy)


def gate_rank(need: int, n_valid: int, n_pairs: int, schedule: Schedule) -> int:
    """k of a round's gate (`Schedule.gate`): the candidates cost at most gate × the k-th cheapest valid
    pair's cost, k = min(what is still needed / (2·tail), the valid pairs, gate_fraction × the pairs),
    at least 1."""
    return min(max(need // (2 * schedule.tail), 1), n_valid, max(int(schedule.gate_fraction * n_pairs), 1))


def fits_target(removes: np.ndarray, need: int) -> np.ndarray:
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
