"""Locked vertices and importance weights on the pipeline's side (``simplify(locked=..., vertex_weights=...)``):
the one module that turns the user's settings into what a scheduler reads, and the scheduler's outcome back
into what the user sees. The stages call it at four points: `pop_settings` (the settings), `resolve` and
`Locks.geometry` (`stages.job`), `Locks.run` (`stages.run`), `back` and `keep_exact` (`stages.finish`).

**Locks.** A locked vertex is in the output exactly where the input has it (the same float64 values the
cleaned input holds, which are the values the user passed), and at every level of the record. A pair with
one locked endpoint may only contract onto it, and is priced there; a pair of two locked vertices never
contracts, nor does a pair whose contraction would leave a locked vertex in no face (the rules the
schedulers apply: `qemjax._schedulers.locks`).

The schedulers always keep a pair's lower-numbered vertex. So that the locked endpoint is always the kept
one, a run with locks numbers the locked vertices first (`Locks.perm`: locked ones in input order, then the
others in input order), runs on that numbering (`Locks.geometry`) and maps the scheduler's outcome back
(`back`) before the result is built, so everything the user sees is numbered as the cleaned input. (Ties
between equal costs are broken by pair index, so a run with locks can order ties differently from one
without, even where no lock is near.)

**Weights.** Each pair's cost (and its cost parts, so the ranking of models with weighted parts scales
alike) is multiplied by the larger weight of its endpoints: weight 0 makes a vertex's pairs free, a large
weight keeps detail near it. The weighted cost is what ranks the pairs, what ``max_error`` limits and what
the history records. Through a contraction the kept vertex takes the larger of the two weights, so a heavy
vertex's weight spreads to what absorbs it and never dilutes.
"""
from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from .._mesh import topology as topo
from .._mesh.arrays import row_index
from .._mesh.units import Frame
from .._schedulers.locks import RunLocks

KEYS = ("locked", "vertex_weights")  # the per-vertex settings `simplify` takes through its **settings
# the largest weight taken: the schedulers multiply the pairs' single-precision costs by the weights, and
# a weight near float32's range would overflow them to infinity, where every such pair ties
MAX_WEIGHT = 1e30


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
        """What the scheduler gets, in the run's numbering."""
        return RunLocks(self.locked[self.perm], None if self.weights is None else self.weights[self.perm])

    def geometry(self):
        """The cleaned `Geometry` in the run's numbering: the same mesh, vertices renumbered, faces in order."""
        geo, perm, inv = self.geo, self.perm, self.inv
        F = inv[geo.F]
        extra = np.sort(inv[geo.extra], axis=1) if len(geo.extra) else geo.extra
        fr = geo.frame
        frame = Frame(fr.centers, fr.scale, None if fr.part is None else fr.part[perm], fr.sizes)
        parts = (geo.parts[0], geo.parts[1][perm])
        return geo._replace(V=geo.V[perm], F=F, extra=extra, parts=parts, Vn=geo.Vn[perm], frame=frame,
                            edges=topo.edge_table(F, len(geo.V)), vertex_map=None)

    def feature_edges(self, edges: np.ndarray) -> np.ndarray:
        """The user's feature edges (checked, cleaned numbering) in the run's numbering; an error in them
        is raised here, naming the user's indices rather than the run's."""
        if len(edges):
            topo.feature_edges_with_faces(self.geo.F, len(self.geo.V), edges)
        return self.inv[edges]

    def outcome_back(self, out):
        """A scheduler's `Outcome` of the run, numbered as the cleaned input."""
        perm, inv = self.perm, self.inv
        h = out.history
        return dataclasses.replace(out, positions=out.positions[inv], states=out.states[inv],
                                   faces=perm[out.faces], history=h._replace(pairs=perm[h.pairs]))


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
            raise ValueError(f"vertex_weights must be finite and >= 0; vertex {i} has {float(w[i])!r} "
                             f"({int(bad.sum())} such)")
        big = w > MAX_WEIGHT
        if big.any():
            i = int(np.flatnonzero(big)[0])
            raise ValueError(f"vertex_weights must be at most {MAX_WEIGHT:g} (they multiply costs held in single "
                             "precision, which would overflow; only their ratios rank the pairs: divide them all by "
                             f"one number); vertex {i} has {float(w[i])!r} ({int(big.sum())} such)")
    return idx, w


def given_map(geo) -> np.ndarray:
    """Each given vertex's index in the cleaned mesh (-1: dropped), the vertices numbered as the user gave
    them: a mesh's as passed; an OBJ file's as its ``v`` lines (trimesh reads an OBJ's vertices in another
    order: unused ones dropped, those at a UV seam split), matched to the cleaned vertices by position (with
    ``weld=False``, the first of the copies at a position). An OBJ's is found once per geometry (kept in
    ``geo.given``): every run of a batch on it would read the file again."""
    vmap = geo.vertex_map
    if geo.source is None or not str(geo.source).lower().endswith(".obj"):
        return vmap
    if geo.given is not None and "map" in geo.given:
        return geo.given["map"]
    from .._io.text import obj_vertices

    with open(geo.source, "rb") as f:
        P = obj_vertices(f.read()) + 0.0  # + 0.0: -0.0 as 0.0, as below
    V = geo.V + 0.0
    if len(P) == len(vmap) and np.all(vmap >= 0) and np.array_equal(V[vmap], P):
        found = vmap  # read in the file's numbering
    else:
        found = row_index(V, P)
    if geo.given is not None:
        geo.given["map"] = found
    return found


def resolve(locked, vertex_weights, geo, stacklevel: int, stats: dict | None = None) -> Locks | None:
    """The run's `Locks` on the cleaned `Geometry` ``geo`` (its ``vertex_map`` maps the given vertices),
    or None when nothing is locked and no weight differs from 1 (the run is then the run without them).
    Warns when locked vertices are in no face (they cannot be kept). ``stats``: a dict that gets the lock
    stats (`Locks.stats`) whenever locks or weights were given, also when none is left to keep (all
    unreferenced: the warning points the user to them)."""
    if locked is None and vertex_weights is None:
        return None
    vmap = given_map(geo)
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
    given = {"locked_in": int(len(idx)), "locked": int(mask.sum()), "locked_unreferenced": gone,
             "vertex_weights": weights is not None}
    if stats is not None:
        stats.update(given)
    if not mask.any() and weights is None:
        return None
    perm = np.concatenate([np.flatnonzero(mask), np.flatnonzero(~mask)])
    inv = np.empty(n, np.int64)
    inv[perm] = np.arange(n)
    return Locks(mask, weights, perm, inv, geo, given)


def scheduler_settings(locks: Locks | None) -> dict:
    """The scheduler's keyword for the run's locks: {"locks": `RunLocks`}, or nothing without locks."""
    return {} if locks is None else {"locks": locks.run()}


def back(locks: Locks | None, out, geo) -> tuple:
    """(the scheduler's outcome, the geometry, the locked mask (n,) or None), numbered as the cleaned input:
    a run with locks ran on its own numbering (`Locks.geometry`, ``geo``)."""
    if locks is None:
        return out, geo, None
    return locks.outcome_back(out), locks.geo, locks.locked


def keep_exact(locked: np.ndarray | None, X: np.ndarray, vertices: np.ndarray, V: np.ndarray):
    """Rows of X (k,3) in mesh units whose vertex (``vertices`` (k,), cleaned numbering) is locked: set to
    its input position V exactly (in place; contractions onto a locked vertex too). Returns which rows
    (k,) bool, or None without locks."""
    if locked is None:
        return None
    held = locked[vertices]
    X[held] = V[vertices[held]]
    return held
