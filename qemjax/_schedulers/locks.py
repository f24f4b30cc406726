"""The rules a scheduler applies to locked vertices and importance weights (`RunLocks`, in the run's
numbering, where the locked vertices come first: `qemjax._pipeline.locks` resolves the user's settings, and
says what locks and weights mean).

A pair of two locked vertices never contracts (`both_locked`, `outcome.LOCKED`), nor does a pair whose
contraction would leave a locked vertex in no face (`vanishing`, `strands`). A pair with one locked endpoint
has it first, as its kept vertex: it contracts onto it (`pin`) and is priced there (`adjust`,
``model.price_at_kept``, `_costs.at_kept`). Every cost is multiplied by the larger weight of the pair's
endpoints (`adjust`), and the kept vertex takes the larger of the two weights (`carry`).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np


class RunLocks(NamedTuple):
    """What a scheduler gets (in its own numbering): locked (n,) bool and the weights (n,) float64 or None.
    A scheduler copies the weights before carrying them through contractions."""

    locked: np.ndarray
    weights: Any = None


def both_locked(locks: RunLocks, E: np.ndarray) -> np.ndarray:
    """(P,) bool: pairs of E (P,2) whose endpoints are both locked (they never contract)."""
    return np.take(locks.locked, E[:, 0]) & np.take(locks.locked, E[:, 1])


def _kept_one(locks: RunLocks, P: np.ndarray) -> np.ndarray:
    """The rows of pairs P (K,2) with a locked kept vertex and an unlocked other one (priced at the kept)."""
    return np.flatnonzero(np.take(locks.locked, P[:, 0]) & ~np.take(locks.locked, P[:, 1]))


def at_kept_pairs(locks: RunLocks, P: np.ndarray) -> np.ndarray:
    """The pairs of P (K,2) that `adjust` prices at their kept vertex, in order."""
    return P[_kept_one(locks, P)]


def start_at_kept(locks: RunLocks, model, VQd, P: np.ndarray, params, faces=None, pad: int = 0):
    """The device price at their kept vertex of the pairs of P (K,2) that `adjust` prices there, started now
    on the device rows VQd (asynchronous), for `adjust`'s ``at``; None where `adjust` prices them on the
    host (a model with ``cost_at``) or none has a locked kept vertex."""
    from .device import start_price

    if getattr(model, "cost_at", None) is not None:
        return None
    one = _kept_one(locks, P)
    return start_price(model, VQd, P[one], params, faces, pad, at_kept=True) if one.size else None


def adjust(locks: RunLocks, weights, model, VQ, VQd, P: np.ndarray, priced, params, faces=None, pad: int = 0,
           at=None, held=None):
    """``priced`` (`common.Priced` of pairs P (K,2)) with the pairs that have a locked kept vertex priced
    there (``model.price_at_kept``; a model without it but with a host ``cost_at`` (attributes): on the
    host, with the kept vertex's attribute values held as the wedges keep them: ``held(a)``, the
    `_wedges.Tracker.held` of the vertex in row a) and every cost and part multiplied by the larger weight of the pair's endpoints (``weights``: the
    run's current weights, or None). The run's numbering puts a locked endpoint first in its pair.
    ``at``: that device price, started before on the same device rows (`start_at_kept` of P), or None."""
    from .device import start_price

    x, cost, branch, parts = priced.x, priced.cost, priced.branch, priced.parts
    one = _kept_one(locks, P)
    if one.size:
        x, cost, branch, parts = x.copy(), cost.copy(), branch.copy(), parts.copy()
        Q = P[one]
        if getattr(model, "cost_at", None) is not None:  # the attribute model: its host solve
            x[one] = VQ[Q[:, 0], :3]
            cost[one] = _cost_held(model, VQ, Q, held)
            branch[one] = 2
        else:
            at = (at or start_price(model, VQd, Q, params, faces, pad, at_kept=True))()
            x[one], cost[one], branch[one] = at.x, at.cost, at.branch
            if parts.shape[0]:
                parts[:, one] = at.parts
    if weights is not None:
        w = np.maximum(np.take(weights, P[:, 0]), np.take(weights, P[:, 1]))
        cost = (cost * w).astype(cost.dtype)
        if parts.shape[0]:
            parts = (parts * w).astype(parts.dtype)
    return type(priced)(x, cost, branch, parts)


def _cost_held(model, VQ, Q: np.ndarray, held) -> np.ndarray:
    """(K,) the attribute model's costs of contracting pairs Q (K,2) onto their locked first vertex where it
    stands: with its attribute values held (``held(a)``: its wedge keeps them), or at their optimum where
    it has several wedges (``held(a)`` None) or no ``held`` is given."""
    a, b = Q[:, 0], Q[:, 1]
    S = [None] * len(Q) if held is None else [held(v) for v in a.tolist()]
    out = np.empty(len(Q))
    kept = np.array([s is not None for s in S], bool)
    if kept.any():
        ka, kb = a[kept], b[kept]
        out[kept] = model.cost_held(VQ[ka], VQ[kb], VQ[ka, :3], np.stack([s for s in S if s is not None]))
    for i in np.flatnonzero(~kept).tolist():
        out[i] = max(model.cost_at(VQ[a[i]], VQ[b[i]], VQ[a[i], :3]), 0.0)
    return out


def pin(locks: RunLocks, VQ, P: np.ndarray, x: np.ndarray) -> None:
    """Put the pairs of P whose kept vertex is locked at that vertex (x (K,3) in place)."""
    one = np.flatnonzero(np.take(locks.locked, P[:, 0]))
    x[one] = VQ[P[one, 0], :3]


def vanishing(locks: RunLocks, P: np.ndarray, kept_faces: np.ndarray) -> np.ndarray:
    """(K,) bool: pairs P with a locked endpoint whose contraction keeps no face (``kept_faces`` (K,)): the
    locked vertex would leave the mesh."""
    return (kept_faces == 0) & (np.take(locks.locked, P[:, 0]) | np.take(locks.locked, P[:, 1]))


def drops(locks: RunLocks, G: np.ndarray, owner: np.ndarray, dropped: np.ndarray, K: int) -> np.ndarray:
    """(K,) bool: pairs that would drop a face with a locked corner as coincident (rows ``dropped`` of the
    faces after, G, whose pairs are ``owner``): `rules.drops_locked` for a round's pairs at once."""
    at = dropped[np.take(locks.locked, np.take(G, dropped, axis=0)).any(1)] if len(dropped) else dropped
    return np.bincount(np.take(owner, at), minlength=K) > 0


def strands(locks: RunLocks, faces, P: np.ndarray, dead) -> np.ndarray:
    """(K,) bool: pairs P whose dying faces (``dead``: (faces, owner pair), `FaceLists.touched_with_dead`)
    are all the faces a locked third vertex has (an "ear" vertex of a boundary: it would leave the mesh)."""
    out = np.zeros(len(P), bool)
    df, owner = dead
    if len(df) == 0:
        return out
    G = np.take(faces.F, df, axis=0)
    rows, cols = np.nonzero(np.take(locks.locked, G))
    if rows.size == 0:
        return out
    c, own = G[rows, cols].astype(np.int64), np.take(owner, rows)
    third = (c != np.take(P[:, 0], own)) & (c != np.take(P[:, 1], own))
    c, own = c[third], own[third]
    if c.size == 0:
        return out
    cu, inv, cnt = np.unique(c, return_inverse=True, return_counts=True)
    total = np.bincount(faces.around(cu)[0], minlength=len(cu))
    out[own[(cnt >= total)[inv]]] = True
    return out


def carry(weights, a: np.ndarray, b: np.ndarray) -> None:
    """The kept vertices ``a`` take the larger weight of theirs and the removed ``b``'s (in place)."""
    if weights is not None:
        weights[a] = np.maximum(np.take(weights, a), np.take(weights, b))

