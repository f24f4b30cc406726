"""Locked vertices and importance weights (``simplify(locked=..., vertex_weights=...)``).

**Locks.** A locked vertex is in the output exactly where the input has it (the same float64 values the
cleaned input holds, which are the values the user passed), and at every level of the record. A pair with
one locked endpoint may only contract onto it, and is priced there (``model.price_at_kept``, `_costs.at_kept`);
a pair of two locked vertices never contracts (`outcome.LOCKED`), nor does a pair whose contraction would
leave a locked vertex in no face (a small part vanishing under ``prune=True``).

The schedulers always keep a pair's lower-numbered vertex. So that the locked endpoint is always the kept
one, a run with locks numbers the locked vertices first (`permutation`: locked ones in input order, then
the others in input order), runs on that numbering (`permuted_geometry`) and maps the scheduler's outcome
back (`outcome_back`) before the result is built, so everything the user sees is numbered as the cleaned
input. (Ties between equal costs are broken by pair index, so a run with locks can order ties differently
from one without, even where no lock is near.)

**Weights.** Each pair's cost (and its cost parts, so the ranking of models with weighted parts scales
alike) is multiplied by the larger weight of its endpoints: weight 0 makes a vertex's pairs free, a large
weight keeps detail near it. The weighted cost is what ranks the pairs, what ``max_error`` limits and what
the history records. Through a contraction the kept vertex takes the larger of the two weights, so a heavy
vertex's weight spreads to what absorbs it and never dilutes.
"""
from __future__ import annotations

import dataclasses
import warnings
from typing import Any, NamedTuple

import numpy as np

from .._mesh.units import Frame

KEYS = ("locked", "vertex_weights")  # the per-vertex settings `simplify` takes through its **settings


class RunLocks(NamedTuple):
    """What a scheduler gets (in its own numbering): locked (n,) bool and the weights (n,) float64 or None.
    A scheduler copies the weights before carrying them through contractions."""

    locked: np.ndarray
    weights: Any = None


@dataclasses.dataclass(frozen=True)
class Locks:
    """A run's locks and weights, resolved on the cleaned mesh: locked (n,) bool and weights (n,) float64 or
    None in the cleaned input's numbering; perm (n,) the run's numbering (run vertex i is cleaned vertex
    perm[i]) and inv its inverse; geo: the cleaned `Geometry` (the result is built on it); stats."""

    locked: np.ndarray
    weights: Any
    perm: np.ndarray
    inv: np.ndarray
    geo: Any
    stats: dict

    def run(self) -> RunLocks:
        return RunLocks(self.locked[self.perm], None if self.weights is None else self.weights[self.perm])


def hold_back(blocked_by: dict) -> bool:
    """Whether a blocked run stopped because of its locks: they hold back at least as many of the pairs
    left as every other rule together (the stop reason is then ``"locked"``)."""
    n = blocked_by.get("locked", 0)
    return n > 0 and n >= sum(v for k, v in blocked_by.items() if k != "locked")


def pop_settings(settings: dict) -> tuple:
    """(locked, vertex_weights) taken out of ``simplify``'s settings (None when not given)."""
    return tuple(settings.pop(k, None) for k in KEYS)


def _vector(name: str, x) -> np.ndarray:
    try:
        a = np.asarray(x)
    except (ValueError, TypeError):
        a = None
    if a is None or a.dtype == object:
        raise ValueError(f"{name} must be a flat array, got {type(x).__name__}")
    if a.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {a.shape}")
    return a


def check(locked, vertex_weights, n: int) -> tuple:
    """(indices (k,) int64 of the locked given vertices, weights (n,) float64 or None), ValueError in the
    user's terms. n: the number of vertices the user passed."""
    idx = np.zeros(0, np.int64)
    if locked is not None:
        a = _vector("locked", locked)
        if a.dtype == np.bool_:
            if len(a) != n:
                raise ValueError(f"locked: a boolean mask needs one entry per input vertex ({n}), got {len(a)}")
            idx = np.flatnonzero(a)
        elif a.size == 0:
            pass
        elif np.issubdtype(a.dtype, np.integer):
            lo, hi = int(a.min()), int(a.max())
            if lo < 0 or hi >= n:
                raise ValueError(f"locked: vertex indices out of range: found [{lo}, {hi}] for {n} input "
                                 "vertices (indices refer to the vertices as passed)")
            idx = np.unique(a.astype(np.int64))
        else:
            raise ValueError(f"locked must be a boolean mask or integer vertex indices, got dtype {a.dtype}")
    w = None
    if vertex_weights is not None:
        w = _vector("vertex_weights", vertex_weights)
        if not (np.issubdtype(w.dtype, np.number) and not np.iscomplexobj(w)) or w.dtype == np.bool_:
            raise ValueError(f"vertex_weights must be numbers, got dtype {w.dtype}")
        if len(w) != n:
            raise ValueError(f"vertex_weights needs one weight per input vertex ({n}), got {len(w)}")
        w = w.astype(np.float64)
        bad = ~(np.isfinite(w) & (w >= 0))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"vertex_weights must be finite and >= 0; vertex {i} has {w[i]!r} "
                             f"({int(bad.sum())} such)")
    return idx, w


def resolve(locked, vertex_weights, geo, stacklevel: int) -> Locks | None:
    """The run's `Locks` on the cleaned `Geometry` ``geo`` (its ``vertex_map`` maps the given vertices),
    or None when nothing is locked and no weight differs from 1 (the run is then the run without them).
    Warns when locked vertices are in no face (they cannot be kept)."""
    if locked is None and vertex_weights is None:
        return None
    vmap = geo.vertex_map
    n_user, n = len(vmap), len(geo.V)
    idx, w = check(locked, vertex_weights, n_user)
    clean = vmap[idx]
    gone = int(np.count_nonzero(clean < 0))
    if gone:
        warnings.warn(f"{gone} locked vertices are used by no face of the cleaned mesh (unreferenced, or only "
                      "in degenerate faces): they cannot be kept (stats['locked_unreferenced'])",
                      stacklevel=stacklevel)
    mask = np.zeros(n, bool)
    mask[clean[clean >= 0]] = True
    weights = None
    if w is not None:
        keep = vmap >= 0
        weights = np.zeros(n)
        np.maximum.at(weights, vmap[keep], w[keep])  # welded copies: the largest of their weights
        if np.all(weights == 1.0):
            weights = None
    if not mask.any() and weights is None:
        return None
    perm = np.concatenate([np.flatnonzero(mask), np.flatnonzero(~mask)])
    inv = np.empty(n, np.int64)
    inv[perm] = np.arange(n)
    stats = {"locked_in": int(len(idx)), "locked": int(mask.sum()), "locked_unreferenced": gone,
             "vertex_weights": weights is not None}
    return Locks(mask, weights, perm, inv, geo, stats)


def permuted_geometry(geo, locks: Locks):
    """``geo`` in the run's numbering (`Locks.perm`): the same mesh, vertices renumbered, faces in order."""
    from .._mesh import topology as topo

    perm, inv = locks.perm, locks.inv
    F = inv[geo.F]
    extra = np.sort(inv[geo.extra], axis=1) if len(geo.extra) else geo.extra
    fr = geo.frame
    frame = Frame(fr.centers, fr.scale, None if fr.part is None else fr.part[perm], fr.sizes)
    parts = (geo.parts[0], geo.parts[1][perm])
    return geo._replace(V=geo.V[perm], F=F, extra=extra, parts=parts, Vn=geo.Vn[perm], frame=frame,
                        edges=topo.edge_table(F, len(geo.V)), vertex_map=None)


def outcome_back(out, locks: Locks):
    """A scheduler's `outcome.Outcome` of the permuted run, numbered as the cleaned input."""
    perm, inv = locks.perm, locks.inv
    h = out.history
    return dataclasses.replace(out, positions=out.positions[inv], states=out.states[inv], faces=perm[out.faces],
                               history=h._replace(pairs=perm[h.pairs]))


# -- in the schedulers -----------------------------------------------------------------------------------

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
    from .common import start_price

    if getattr(model, "cost_at", None) is not None:
        return None
    one = _kept_one(locks, P)
    return start_price(model, VQd, P[one], params, faces, pad, at_kept=True) if one.size else None


def adjust(locks: RunLocks, weights, model, VQ, VQd, P: np.ndarray, priced, params, faces=None, pad: int = 0,
           at=None):
    """``priced`` (`common.Priced` of pairs P (K,2)) with the pairs that have a locked kept vertex priced
    there (``model.price_at_kept``; a model without it but with a host ``cost_at`` (attributes): on the
    host) and every cost and part multiplied by the larger weight of the pair's endpoints (``weights``: the
    run's current weights, or None). The run's numbering puts a locked endpoint first in its pair.
    ``at``: that device price, started before on the same device rows (`start_at_kept` of P), or None."""
    from .common import start_price

    x, cost, branch, parts = priced.x, priced.cost, priced.branch, priced.parts
    one = _kept_one(locks, P)
    if one.size:
        x, cost, branch, parts = x.copy(), cost.copy(), branch.copy(), parts.copy()
        Q = P[one]
        if getattr(model, "cost_at", None) is not None:  # the attribute model: its host solve
            x[one] = VQ[Q[:, 0], :3]
            cost[one] = [max(model.cost_at(VQ[a], VQ[b], VQ[a, :3]), 0.0) for a, b in Q.tolist()]
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


def pin(locks: RunLocks, VQ, P: np.ndarray, x: np.ndarray) -> None:
    """Put the pairs of P whose kept vertex is locked at that vertex (x (K,3) in place)."""
    one = np.flatnonzero(np.take(locks.locked, P[:, 0]))
    x[one] = VQ[P[one, 0], :3]


def vanishing(locks: RunLocks, P: np.ndarray, kept_faces: np.ndarray) -> np.ndarray:
    """(K,) bool: pairs P with a locked endpoint whose contraction keeps no face (``kept_faces`` (K,)): the
    locked vertex would leave the mesh."""
    return (kept_faces == 0) & (np.take(locks.locked, P[:, 0]) | np.take(locks.locked, P[:, 1]))


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

