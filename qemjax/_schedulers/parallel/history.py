"""A run's record from its per-round arrays: each contraction's round, pair, position and cost in record
order, and which contraction removed each face."""
from __future__ import annotations

import numpy as np

from ..._mesh.face_passes import first_step


def history_columns(history):
    """A run's per-round [(round, (kept, removed, positions, costs))] -> each contraction's round, kept
    and removed vertex (k,) int64, position (k,3) and cost (k,), in record order."""
    if not history:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                np.zeros(0))
    rounds = np.repeat([r for r, _ in history], [len(h[0]) for _, h in history]).astype(np.int64)
    cols = [np.concatenate([h[i] for _, h in history]) for i in range(4)]
    return rounds, cols[0].astype(np.int64), cols[1].astype(np.int64), cols[2], cols[3]


def history_arrays(a, b, x, cost):
    """The record's history: pairs (k,2) int64, positions (k,3), costs (k,) (float64 empties when k = 0)."""
    if not len(a):
        return np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0)
    return np.stack([a, b], 1), x, cost


def removal_steps(F, rounds, a, b, dead, dropped):
    """Which contraction removed each face, from a run's per-round arrays (no per-contraction work):
    F (m,3) the faces at the end (a removed face keeps the row it had when it went), rounds, a, b the
    round, kept and removed vertex of each contraction in record order (`history_columns`), dead /
    dropped the faces each round's contractions removed / its coincident faces dropped. Returns the
    record's ``removed_at`` (m,) int64 (-1: survives), ``coincident`` (m,) bool and ``rounds`` (k,) int64
    (see `_record.Record`).

    A face that dies in a contraction holds its removed vertex and vertices removed later or never: its
    step is the smallest removal step of its corners. A dropped face holds the kept vertex of the one
    contraction of its round that made it coincide (contractions of a round are two edges apart)."""
    m = len(F)
    removed_at, coincident = np.full(m, -1, np.int64), np.zeros(m, bool)
    if not len(a):
        return removed_at, coincident, rounds
    n = int(max(a.max(), b.max(), F.max() if m else 0)) + 1
    step_of = np.full(n, np.iinfo(np.int64).max)
    step_of[b] = np.arange(len(b))
    for di in dead:  # each dying face's smallest corner step (compiled: no (k,3) temporaries)
        first_step(F, step_of, di, removed_at)
    if dropped:
        f = np.concatenate([x for _, x in dropped]).astype(np.int64)
        r = np.repeat([r for r, _ in dropped], [len(x) for _, x in dropped]).astype(np.int64)
        key = rounds * n + a  # (round, kept vertex) -> step; unique, sorted by round
        order = np.argsort(key, kind="stable")
        ck = (r[:, None] * n + F[f]).reshape(-1)
        at = np.minimum(np.searchsorted(key[order], ck), len(key) - 1)
        hit = np.where(key[order][at] == ck, order[at], -1).reshape(-1, 3)
        removed_at[f] = hit.max(axis=1)
        coincident[f] = True
    return removed_at, coincident, rounds
