"""ESQEM (Zhang 2022): the quadric error plus a Gaussian-curvature term, as a cost model.

State: each vertex's quadric (10 floats, as QEM) then its Gaussian curvature K(v) and the area A(v) of
its faces (2 floats). K is the angle deficit over a third of that area:

    interior vertex: K(v) = (2π − Σθᵢ) / (⅓ ΣSᵢ),    boundary vertex: K(v) = (π − Σθᵢ) / (⅓ ΣSᵢ)

(θᵢ the corner angles at v, Sᵢ the areas of its faces; 0 for a vertex without area). A pair's curvature is
the area-weighted mean of its endpoints' absolute curvatures, K(e) = |K₁|·ω₁ + |K₂|·ω₂ with
ωᵢ = Aᵢ / (A₁ + A₂). The contraction is ranked by

    Q(e) + w·K(e),    w = a·Q̄ / K̄    (a: ``curvature_weight``; means over the candidate pairs)

so that the mean curvature term is a times the mean quadric error: the paper sets the term about two
orders of magnitude below the quadric error, hence a = 0.01 by default.

What is priced and what is reported. `price` returns Q(e) as the cost (row 3, the squared distance that
``max_error`` and ``history.costs`` mean) and the parts ("quadric" Q, "curvature" K) in rows 5-6; the
schedulers add w·K only when ranking (`rank_weights`), so a sweep over a shares one costing pass and
reported errors keep their units.

When the means are taken (`rank_weights`, called by the schedulers): at the start and again whenever the
live face count has fallen by ``reweight_step`` (5 %) since the last time. Q̄ grows by orders of
magnitude as the mesh coarsens (a quadric error scales like the fourth power of the edge length) while
K̄ changes little (Gaussian curvature is intrinsic), so a w fixed at the start would make the curvature
term vanish after the first few rounds; recomputing keeps the ratio at a throughout. Every 5 % of faces
(not every contraction) because in the greedy scheduler a new w reorders the whole queue (a rebuild); the
parallel scheduler checks at every round, and its early rounds remove more than 5 % each.

Support: ring. A contraction changes the angles and areas of every vertex around the new one, so
`refresh` recomputes K and A there (once per round in the parallel scheduler, batched, for those
vertices only), and every pair at them is priced again. `merge` merges the quadrics and leaves K, A to
`refresh`. Curvature and area are computed from the faces around each vertex with one batched kernel
(`vertex_curvature`), the same at the start and after each round.

Edge splitting after simplification (``split_factor``) is ESQEM's second half; see `qemjax._pipeline.split`.
"""
from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

from .._kernels.lazy import jax, jnp  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._kernels.batching import DTYPE, chunks
from .._mesh.incidence import FaceLists
from .._kernels import kernel, placement
from .._kernels.fixed import cross3, dot3, norm3, tree_sum
from . import at_kept, ring
from .base import MeshInput, require_nonnegative
from .qem import QEM

CURVATURE_WEIGHT = 0.01  # a: the mean curvature term is 1 % of the mean quadric error (the paper's "two
# orders of magnitude below")
SPLIT_FACTOR = 4.0 / 3.0  # b: split edges longer than b × the mean edge length (the paper's 4/3)
REWEIGHT_STEP = 0.05  # recompute Q̄, K̄ when the face count has fallen by this fraction since the last time
KCOL, ACOL = 13, 14  # columns of K(v) and A(v) in a vertex row [position (3), quadric (10), K, A]
FEW = 16  # a ring group of at most this many vertices goes in one piece of this shape, not the smallest of
# `batching.CHUNKS`: a greedy contraction refreshes a few vertices, and at a vertex of valence in the hundreds
# a piece padded to hundreds of vertices was mostly padding rings of that width, every contraction


def vertex_curvature(pos, mask, boundary):
    """One vertex: pos (R,3,3) positions of ``[v, c1, c2]`` per face around v, mask (R,) bool (which rows
    are faces), boundary: whether v is on a boundary. Returns (K(v), A(v)): the angle-deficit Gaussian
    curvature (0 without area) and the area of its faces."""
    u, w = pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]
    cr = norm3(cross3(u, w))  # sums in a fixed order (`_kernels.fixed`): the same bits on any CPU
    theta = jnp.arctan2(cr, dot3(u, w))  # the corner angle at v, in [0, π]
    angles = tree_sum(jnp.where(mask, theta, 0.0))
    area = 0.5 * tree_sum(jnp.where(mask, cr, 0.0))
    deficit = jnp.where(boundary, math.pi, 2.0 * math.pi) - angles
    tiny = jnp.finfo(area.dtype).tiny
    return jnp.where(area > tiny, 3.0 * deficit / jnp.maximum(area, tiny), 0.0), area


@kernel
def curvature_rows(pos, mask, boundary):
    """Batched `vertex_curvature`: pos (K,R,3,3), mask (K,R), boundary (K,) -> (2,K) [K(v); A(v)]."""
    k, a = jax.vmap(vertex_curvature)(pos, mask, boundary)
    return jnp.stack([k, a], 0)


def edge_curvature(k1, a1, k2, a2):
    """K(e) = |K1|·ω1 + |K2|·ω2, ωi = Ai / (A1 + A2) (the plain mean of |K| when both areas are 0)."""
    s = a1 + a2
    tiny = jnp.finfo(s.dtype).tiny
    w1 = jnp.where(s > tiny, a1 / jnp.maximum(s, tiny), 0.5)
    return jnp.abs(k1) * w1 + jnp.abs(k2) * (1.0 - w1)


@kernel
def _price(VS, pairs, endpoints_only, cond_eps, max_shift):
    out = placement.place_pairs(VS, pairs, endpoints_only, cond_eps, max_shift)  # (5,K), inlined
    a = jnp.take(VS, pairs[:, 0], axis=0, mode="clip")
    b = jnp.take(VS, pairs[:, 1], axis=0, mode="clip")
    ke = edge_curvature(a[:, KCOL], a[:, ACOL], b[:, KCOL], b[:, ACOL])
    return jnp.concatenate([out, out[3:4], ke[None]], 0)


@kernel
def _price_at_kept(VS, pairs):
    """`_price`'s rows with each pair at its kept vertex (`at_kept`): parts [Q, K] as `_price` gives them."""
    out = at_kept.qem(VS, pairs, None)
    a = jnp.take(VS, pairs[:, 0], axis=0, mode="clip")
    b = jnp.take(VS, pairs[:, 1], axis=0, mode="clip")
    ke = edge_curvature(a[:, KCOL], a[:, ACOL], b[:, KCOL], b[:, ACOL])
    return jnp.concatenate([out, out[3:4], ke[None]], 0)


@kernel
def _with_curvature_columns(q):
    """Merged quadrics q (K,10) with the K, A columns appended as zeros: one compiled call, where two
    eager operations per contraction were a large share of the greedy queue's device calls."""
    return jnp.concatenate([q, jnp.zeros((q.shape[0], 2), q.dtype)], 1)


def ring_corners(faces: FaceLists, verts: np.ndarray):
    """The live faces around each of ``verts`` (k,) rotated so that the vertex comes first: (owner
    position in verts (r,) non-decreasing, corners (r,3) int32 ``[v, c1, c2]``), and (k,) bool: which of
    the vertices are on a boundary (some edge at it lies in only one of its faces)."""
    w, f = faces.around(verts)
    G = np.take(faces.F, f, axis=0)
    me = np.take(verts, w)
    corner = np.where(G[:, 0] == me, 0, np.where(G[:, 1] == me, 1, 2))
    rows = np.arange(len(G))
    rot = np.stack([G[rows, corner], G[rows, (corner + 1) % 3], G[rows, (corner + 2) % 3]], 1)
    # an edge (v, c) is a boundary edge when it lies in one face at v: c appears once among c1, c2
    n = len(faces.cnt)
    key = np.concatenate([w, w]).astype(np.int64) * n + np.concatenate([rot[:, 1], rot[:, 2]])
    uk, cnt = np.unique(key, return_counts=True)
    boundary = np.zeros(len(verts), bool)
    boundary[uk[cnt == 1] // n] = True
    return w, rot.astype(np.int32), boundary


def curvature_at(faces: FaceLists, P: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """(k,2) float32 [K(v), A(v)] at ``verts`` (k,) from the live faces and positions P (n,3): the faces
    are gathered on the host into padded rings (grouped by size, `ring.group_rings`) and one batched
    kernel computes the angles and areas (fixed chunk shapes, `FEW` for a group of few vertices: a handful
    of compilations per run)."""
    verts = np.asarray(verts, np.int64)
    out = np.zeros((len(verts), 2), DTYPE)
    if len(verts) == 0:
        return out
    owner, rot, boundary = ring_corners(faces, verts)
    P = np.asarray(P, DTYPE)
    pending = []
    for idx, rg in ring.group_rings(owner, rot, len(verts), 0):
        pos = np.take(P, rg.corners.reshape(-1), axis=0).reshape(rg.corners.shape + (3,))
        size = FEW if len(idx) <= FEW else None  # (one vertex's K, A do not depend on the piece's shape)
        for (s, pp), (_, mm), (_, bb) in zip(chunks(pos, size=size), chunks(rg.mask, size=size),
                                             chunks(boundary[idx], size=size)):
            pending.append((idx[s:s + len(pp)], curvature_rows(pp, mm, bb)))
    for sel, o in pending:
        out[sel] = np.asarray(o).T[: len(sel)]
    return out


@dataclasses.dataclass(frozen=True)
class ESQEM(QEM):
    """ESQEM (Zhang 2022): QEM's placement and error, ranked with a Gaussian-curvature term (module
    docstring), then long edges split (`qemjax._pipeline.split`). QEM's settings, plus:

    curvature_weight: a ≥ 0; the curvature term's weight is w = a·Q̄/K̄ (0: rank by Q alone).
    split_factor: b > 0; after simplifying, split edges longer than b × the mean edge length (None: no
        splitting).
    reweight_step: recompute Q̄ and K̄ whenever the face count has fallen by this fraction.
    """

    name: ClassVar[str] = "esqem"
    width: ClassVar[int] = 12
    support: ClassVar[str] = "ring"
    parts: ClassVar[tuple[str, ...]] = ("quadric", "curvature")
    part_units: ClassVar[tuple[int, ...]] = (2, -2)  # powers of length: squared distance, 1/length²

    memoryless_refused: ClassVar[str] = "ESQEM's refresh keeps its own state"

    curvature_weight: float = CURVATURE_WEIGHT
    split_factor: float | None = SPLIT_FACTOR
    reweight_step: float = REWEIGHT_STEP

    def __post_init__(self):
        super().__post_init__()
        if self.placement == "rank":
            raise ValueError("method='esqem' places with 'optimal' or 'endpoints'; placement='rank' is QEM's only")
        require_nonnegative(self, "curvature_weight")
        if self.split_factor is not None and not (self.split_factor > 0 and math.isfinite(self.split_factor)):
            raise ValueError(f"split_factor must be a finite number > 0 or None, got {self.split_factor}")
        if not 0 < self.reweight_step <= 1:
            raise ValueError(f"reweight_step must be in (0, 1], got {self.reweight_step}")

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        q = super().init_state(mesh)
        ka = curvature_at(FaceLists(mesh.F, len(mesh.V)), mesh.V, np.arange(len(mesh.V)))
        return np.concatenate([q, ka], 1).astype(DTYPE)

    def price(self, VS, pairs, params, rings=None):
        return _price(VS, pairs, params["endpoints_only"], params["cond_eps"], params["max_shift"])

    def price_at_kept(self, VS, pairs, params, rings=None):
        return _price_at_kept(VS, pairs)

    def merge(self, VS, pairs, x, params):
        return _with_curvature_columns(super().merge(VS, pairs, x, params))  # K, A: `refresh` writes them

    def refresh(self, view, verts):
        verts = np.asarray(verts, np.int64)
        ka = curvature_at(view.faces, view.rows[:, :3], verts)
        return np.concatenate([view.rows[verts, 3:KCOL], ka], 1)

    def rank_weights(self, parts: np.ndarray) -> np.ndarray:
        """(2,) float64 weights of the parts (P,2) [Q, K] of the candidate pairs in the ranking key
        cost + parts @ weights: [0, w], w = a·Q̄/K̄ (0 when K̄ is 0: a flat mesh has no curvature)."""
        p = np.asarray(parts, np.float64)
        if len(p) == 0:
            return np.zeros(2)
        qbar, kbar = np.mean(np.maximum(p[:, 0], 0.0)), np.mean(p[:, 1])
        w = self.curvature_weight * qbar / kbar if kbar > 0 else 0.0
        return np.array([0.0, w])
