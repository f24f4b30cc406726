"""The greedy scheduler's priority queue (`Queue`, lazy deletion), its tie-break (`tie`) and the stop
report from what is left in it (`stop_report`): shared by the one-at-a-time loop (`greedy`) and the verified
batches (`batches`)."""
from __future__ import annotations

import heapq
import itertools

import numpy as np

from ..._mesh.incidence import FaceLists
from .. import outcome
from ..._mesh.fixed_order import weighted_sum
from ..._options import Options
from ..outcome import BUDGET


def tie(a: int, b: int) -> int:
    """A fixed scramble of the pair (a, b): the last key of the queue, after the cost and the pair's
    length (see `Queue`)."""
    return ((a * 0x9E3779B1) ^ (b * 0x85EBCA77)) & 0xFFFFFFFF


def ties(P: np.ndarray) -> list:
    """`tie` of each pair P (k,2) of non-negative ids below 2³², as Python ints: the products taken modulo
    2⁶⁴ keep the low 32 bits that `tie` keeps."""
    P = np.asarray(P, np.uint64).reshape(-1, 2)
    return (((P[:, 0] * np.uint64(0x9E3779B1)) ^ (P[:, 1] * np.uint64(0x85EBCA77))) & np.uint64(0xFFFFFFFF)).tolist()


class Queue:
    """The priority queue of pairs with lazy deletion: an entry is current while its stamp is.

    Keys: (rank, squared length, `_tie`); the rank is the cost, or for a model with `rank_weights`
    cost + parts @ ``weights``. Flat regions tie exactly (cost 0); taking the shortest pair first
    decimates them evenly. Breaking those ties by a scramble (or by index) alone made vertices absorb their
    neighbours into fans whose slivers then refused contractions (on a flat grid, hundreds of times more
    refusals than by length: `experiments/probes/greedy_flat.py`)."""

    def __init__(self):
        self.heap, self.stamp, self.placed, self.blocked = [], {}, {}, {}
        self.weights = None
        # stamps from one counter, never reused: an entry whose stamp a rollback restored stays unique
        self.stamps = itertools.count(1)

    def _keys(self, cost: np.ndarray, parts: np.ndarray) -> list:
        """The ranks of entries with costs (k,) and parts (k, p), as Python floats: the cost, or with
        weights cost + parts @ weights (in float64, left to right) rounded to float32. One vectorised call
        per push: per entry, numpy's per-call overhead was most of a ring model's queue time, and each
        element's arithmetic is the same."""
        cost = np.asarray(cost, np.float64)
        if self.weights is None:
            return cost.tolist()
        if len(cost) == 0:
            return []
        return (cost + weighted_sum(parts, self.weights)).astype(np.float32).tolist()

    def push(self, pairs, priced, length2):
        """Enter pairs (a list of (a, b)) with their `Priced` rows and squared lengths (k,). Each entry holds
        its own row (x and parts as Python floats, with their dtypes: `entry` gives the arrays back): a view
        would keep the whole pushed block alive while one of its pairs stays current (a vertex of valence d
        re-prices d pairs per contraction: d² rows), and a copy per row cost a call each. A vertex of
        valence d pushes its d pairs after every contraction around it, so the per-pair work is done for
        all of them at once (`ties`, ``tolist``, the stamps): per pair only the entries are written."""
        k = len(pairs)
        if k == 0:
            return
        X, parts_t = np.asarray(priced.x), np.asarray(priced.parts).T
        keys = self._keys(priced.cost, parts_t)
        dtypes = (X.dtype, parts_t.dtype)
        first = next(self.stamps)
        if k > 1:  # the counter moves past the k stamps taken here
            self.stamps = itertools.count(first + k)
        stamp, placed, heap, heappush = self.stamp, self.placed, self.heap, heapq.heappush
        for pair in self.blocked.keys() & set(pairs):
            del self.blocked[pair]
        for (a, b), x, br, c, p, l2, key, t, s in zip(pairs, X.tolist(), np.asarray(priced.branch).tolist(),
                                                      np.asarray(priced.cost).tolist(), parts_t.tolist(),
                                                      length2.tolist(), keys, ties(pairs), range(first, first + k)):
            stamp[(a, b)] = s
            placed[(a, b)] = (x, br, c, p, l2, dtypes)
            heappush(heap, (key, l2, t, a, b, s))

    def entry(self, pair):
        """The placed pair's (x (3,), branch, cost, parts (p,)), x and parts as the arrays they were pushed
        as (their rows' dtypes)."""
        x, br, c, p, _, (xt, pt) = self.placed[pair]
        return np.array(x, xt), br, c, np.array(p, pt)

    def reweigh(self, weights):
        """New ranking weights: every current, unblocked entry is ranked again (the heap is rebuilt)."""
        self.weights = weights
        live = [(pair, e) for pair, e in self.placed.items() if pair not in self.blocked]
        cost = np.array([e[2] for _, e in live], np.float64)
        parts = np.array([e[3] for _, e in live]).reshape(len(live), -1) if live else np.zeros((0, 0))
        keys = self._keys(cost, parts)
        self.heap = [(key, e[4], tie(a, b), a, b, self.stamp[(a, b)]) for key, ((a, b), e) in zip(keys, live)]
        heapq.heapify(self.heap)

    def compact(self):
        """Drop the heap's old entries (stamp no longer current, or pair blocked: a blocked pair comes back
        only by a new push) once they outnumber the current ones, so that the heap stays as long as the
        queue, not as the run's pushes. Pops come in the same order (entries are distinct tuples)."""
        if len(self.heap) > 2 * len(self.stamp) + 1024:
            stamp, blocked = self.stamp, self.blocked
            self.heap = [e for e in self.heap if stamp.get((e[3], e[4])) == e[5] and (e[3], e[4]) not in blocked]
            heapq.heapify(self.heap)

    def forget(self, pair):
        self.stamp.pop(pair, None)
        self.placed.pop(pair, None)
        self.blocked.pop(pair, None)


def stop_report(faces: FaceLists, q: Queue, options: Options, target: int, stop):
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
