"""Minimum surface-area difference (Qi et al., "3D model simplification algorithm based on minimum surface
area error") as a cost model (``method="area"``), and its area term for other models (``area_weight=λ``).

For a pair (O1, O2) the new point is C(s) = O1 + s·(O2 − O1), s ∈ [0, 1]. The faces around O1 and O2 that
survive are rebuilt with C; the faces holding both die. With A the area of all those faces before,

    ΔS(s) = A − Σ_f area_f(C(s)),

and the contraction goes to the s that minimises |ΔS(s)|; its cost is that minimum (an area: mesh units²
like QEM's squared distances, so ``max_error`` reads as "no contraction changes the surface area by more
than this"). Each rebuilt face moves one corner along a line, so twice its area is the norm of a vector
affine in s, u_f + s·w_f, and the rebuilt area G(s) = ½ Σ |u_f + s·w_f| is convex: ΔS is concave. So:

1. s* = the maximiser of ΔS on the allowed interval [lo, hi] (a root of G′, which is non-decreasing);
2. ΔS increases on [lo, s*] and decreases on [s*, hi]: one root on each side at most, found by bisection
   (`optimistix.Bisection`, batched by vmap) where the side's ends have opposite signs;
3. of the roots found, s*, lo and hi, the one with the smallest |ΔS| is taken (ΔS ≥ 0 at both ends: an
   end; ΔS < 0 everywhere: s*).

Boundaries: a vertex on a boundary or feature edge (``boundary_weight`` > 0) stays on it: a pair with one
such endpoint contracts to it ([lo, hi] = that end, branch "pinned"); two such endpoints may meet anywhere
between them. Rings come padded from `ring.gather_groups`, dead faces included (``ring_dead``); a ring
wider than RING_CAP is solved on the host in float64 by the same steps (`solve_host`, compiled loops in
`area_host`) instead of compiling and padding ever wider kernels.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

from .._kernels.lazy import jax, jnp, optx  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._mesh import topology as topo
from .._kernels.batching import DTYPE
from .._kernels import kernel
from .._kernels.fixed import cross3, tree_sum
from .base import MeshInput, Method, require_nonnegative

RING_CAP = 128  # wider rings (valence ~60 and up) take the host path
MAX_STEPS = 48  # bisection halvings at most (2⁻⁴⁸: float64 tests); TOL stops float32 runs near 20
TOL = 1e-6  # bisection tolerance on s (the pair's length is 1)


# -- one pair ------------------------------------------------------------------------------------------

def affine_areas(pa, pb, pos, moving):
    """Twice the rebuilt faces' area vectors as u + s·w: pos (R,3,3) corner positions, moving (R,3) bool
    (the corners at O1 or O2). Returns u, w (R,3). Exact: a face with one moving corner has a cross
    product affine in s, a face with two (a dead face) has zero area at every s."""
    def cross_at(c):
        p = jnp.where(moving[..., None], c, pos)
        return cross3(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    u = cross_at(pa)
    return u, cross_at(pb) - u


def _norm(v):
    """|v| over the first axis (components first: (3, R) vectorises over the ring on a CPU)."""
    return jnp.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _area(pos, mask):
    """The ring's area before: its faces' (R,3,3) corners, mask (R,) the live ones. Sums in a fixed order
    (`_kernels.fixed`), so that a pair's price is the same bits on any CPU and in any batch."""
    return 0.5 * tree_sum(jnp.where(mask, _norm(cross3(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]).T), 0.0))


def _delta(s, uw):
    u, w, mask, before = uw
    return before - 0.5 * tree_sum(jnp.where(mask, _norm(u + s * w), 0.0))


def _signed_delta(s, args):
    uw, sign = args
    return sign * _delta(s, uw)


def _slope(s, uw):
    """G′(s), the rebuilt area's derivative (non-decreasing: G is convex)."""
    u, w, mask, _ = uw
    v = u + s * w
    n = _norm(v)
    dot = v[0] * w[0] + v[1] * w[1] + v[2] * w[2]
    return 0.5 * tree_sum(jnp.where(mask & (n > 0), dot / jnp.where(n > 0, n, 1.0), 0.0))


def _bisect(fn, uw, lo, hi, tol):
    """Root of the non-decreasing fn(·, uw) in [lo, hi]; an end when it does not change sign there."""
    sol = optx.root_find(fn, optx.Bisection(rtol=0.0, atol=tol, flip=False), 0.5 * (lo + hi), uw,
                         options=dict(lower=lo, upper=hi), max_steps=MAX_STEPS, throw=False)
    return jnp.clip(sol.value, lo, hi)


def solve_pair(pa, pb, pos, moving, mask, lo, hi, tol):
    """One pair: positions pa, pb (3,) of O1, O2, its ring pos (R,3,3) with moving (R,3) and mask (R,),
    the allowed interval lo ≤ hi in [0, 1]. Returns (s, |ΔS(s)|, signed ΔS(s), branch): branch 0 root,
    1 peak (s*), 2 end, 3 pinned (lo == hi)."""
    u, w = affine_areas(pa, pb, pos, moving)
    uw = (u.T, w.T, mask, _area(pos, mask))  # (3, R): components first
    peak = _bisect(_slope, uw, lo, hi, tol)
    d_lo, d_hi, d_peak = _delta(lo, uw), _delta(hi, uw), _delta(peak, uw)
    # ΔS rises on [lo, s*] and falls on [s*, hi]: both roots in one batched bisection (±ΔS, increasing)
    sides = jax.vmap(lambda sign, a, b: _bisect(_signed_delta, (uw, sign), a, b, tol))(
        jnp.array([1.0, -1.0], lo.dtype), jnp.stack([lo, peak]), jnp.stack([peak, hi]))
    s = jnp.concatenate([sides, jnp.stack([peak, lo, hi])])
    d = jax.vmap(_delta, (0, None))(s, uw)
    has_root = jnp.stack([(d_lo <= 0) & (d_peak >= 0), (d_hi <= 0) & (d_peak >= 0)])
    score = jnp.where(jnp.concatenate([has_root, jnp.ones(3, bool)]), jnp.abs(d), jnp.inf)
    k = jnp.argmin(score)  # ties: the first (roots, then s*, then the ends)
    branch = jnp.where(lo == hi, 3, jnp.array([0, 0, 1, 2, 2])[k])
    return s[k], jnp.abs(d[k]), d[k], branch


def interval(flags_a, flags_b):
    """The allowed [lo, hi] of s from the endpoints' boundary flags (1: on a boundary or feature edge)."""
    pa, pb = flags_a > 0.5, flags_b > 0.5
    lo = jnp.where(pb & ~pa, 1.0, 0.0)
    hi = jnp.where(pa & ~pb, 0.0, 1.0)
    return lo.astype(flags_a.dtype), hi.astype(flags_a.dtype)


def ring_positions(VS, pairs, corners):
    """Corner positions (K,R,3,3) of the ring faces and which corners are a pair's endpoints (K,R,3)."""
    pos = jnp.take(VS[:, :3], corners.reshape(-1), axis=0, mode="clip").reshape(corners.shape + (3,))
    moving = (corners == pairs[:, 0, None, None]) | (corners == pairs[:, 1, None, None])
    return pos, moving


@kernel
def _price(VS, pairs, params, corners, mask):
    pos, moving = ring_positions(VS, pairs, corners)
    pa, pb = VS[pairs[:, 0], :3], VS[pairs[:, 1], :3]
    lo, hi = interval(VS[pairs[:, 0], 3], VS[pairs[:, 1], 3])
    s, cost, _, branch = jax.vmap(solve_pair, (0, 0, 0, 0, 0, 0, 0, None))(
        pa, pb, pos, moving, mask, lo, hi, params["tol"])
    x = pa + s[:, None] * (pb - pa)
    return jnp.concatenate([x.T, cost[None], branch[None].astype(cost.dtype)], 0)


# -- the host path (wide rings) ------------------------------------------------------------------------

def solve_host(pa, pb, pos, moving, mask, lo, hi):
    """`solve_pair` for K pairs in float64 on the host (the same steps; compiled loops, `area_host`):
    arrays with a leading K axis. Returns (s, |ΔS|, ΔS, branch) (K,)."""
    from . import area_host  # compiled loops, imported on first use (only wide rings take this path)

    K = len(lo)
    f64 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
    mask = np.ascontiguousarray(mask, np.bool_)
    u, w, before = area_host.affine(f64(pa), f64(pb), f64(pos), np.ascontiguousarray(moving, np.bool_), mask)
    out = np.empty(K), np.empty(K), np.empty(K), np.empty(K, np.int64)
    area_host.solve(u, w, mask, before, f64(lo), f64(hi), *out)
    return out


def _price_host(VS, pairs, corners, mask):
    """The kernel's output for pairs with rings wider than RING_CAP, computed on the host in float64: the
    rings' corners are read from VS by the compiled loop (`area_host.affine_rings`), not gathered into
    (pairs, ring, 3, 3) arrays first."""
    from . import area_host  # compiled loops, imported on first use (only wide rings take this path)

    VS = np.asarray(VS)
    P = np.ascontiguousarray(VS[:, :3], np.float64)
    pairs = np.ascontiguousarray(pairs, np.int64)
    corners = np.ascontiguousarray(corners, np.int32)
    mask = np.ascontiguousarray(mask, np.bool_)
    cols = np.flatnonzero(mask.any(0))  # drop the columns no pair uses
    # a pair with no faces (a batch's padding) has ΔS = 0 at every s whatever its ring holds: it is solved
    # with an empty ring, the same steps on the same values, without reading a ring or passing over it
    live = mask.any(1)
    fa, fb = VS[pairs[:, 0], 3] > 0.5, VS[pairs[:, 1], 3] > 0.5
    lo, hi = np.where(fb & ~fa, 1.0, 0.0), np.where(fa & ~fb, 0.0, 1.0)
    s, cost, branch = np.empty(len(pairs)), np.empty(len(pairs)), np.empty(len(pairs), np.int64)
    for rows, used in ((np.flatnonzero(live), cols), (np.flatnonzero(~live), cols[:0])):
        u, w, before, sub = area_host.affine_rings(P, pairs, corners, mask, rows, used)
        out = np.empty(len(rows)), np.empty(len(rows)), np.empty(len(rows)), np.empty(len(rows), np.int64)
        area_host.solve(u, w, sub, before, lo[rows], hi[rows], *out)
        s[rows], cost[rows], branch[rows] = out[0], out[1], out[3]
    pa, pb = P[pairs[:, 0]], P[pairs[:, 1]]
    x = pa + s[:, None] * (pb - pa)
    return np.concatenate([x.T, cost[None], branch[None]], 0).astype(DTYPE)


# -- the model -----------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class AreaDifference(Method):
    """Minimum surface-area difference (see the module). State: one flag per vertex, 1 on a boundary or
    feature edge (when ``boundary_weight`` > 0), else 0; merged by max. ``tol``: the bisection's
    tolerance on s in the compiled kernel; a pair of a wide ring (`RING_CAP`, the host path) bisects until
    its float64 interval stops shrinking, within any ``tol``, so ``tol`` does not change its answer (a
    stopping rule of its own there would move the default's bits). `vertex_error` is 0: the method measures
    areas, not distances to the input."""

    name: ClassVar[str] = "area"
    width: ClassVar[int] = 1
    support: ClassVar[str] = "ring"
    uses_ring: ClassVar[bool] = True
    ring_dead: ClassVar[bool] = True
    branches: ClassVar[tuple[str, ...]] = ("root", "peak", "end", "pinned")
    error_measure: ClassVar[str] = "surface-area change"

    boundary_weight: float = 100.0
    tol: float = TOL

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "boundary_weight")
        if not (0 < self.tol < 1):
            raise ValueError(f"tol must be in (0, 1), got {self.tol}")

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        flag = np.zeros((len(mesh.V), 1), DTYPE)
        if self.boundary_weight > 0:
            be = mesh.boundary[0] if mesh.boundary is not None else topo.boundary_edges(mesh.F, len(mesh.V))[0]
            flag[np.asarray(be).reshape(-1)] = 1
            if mesh.feature_edges is not None and len(mesh.feature_edges):
                flag[np.asarray(mesh.feature_edges, np.int64).reshape(-1)] = 1
        return flag

    def kernel_params(self) -> dict:
        return {"tol": np.asarray(self.tol, DTYPE)}

    def price(self, VS, pairs, params, rings=None):
        if rings.corners.shape[1] > RING_CAP:
            return _price_host(VS, pairs, rings.corners, rings.mask)
        return _price(VS, pairs, params, rings.corners, rings.mask)

    def price_at_kept(self, VS, pairs, params, rings=None):
        return price_at_kept_kernel(VS, pairs, params, rings.corners, rings.mask)

    def merge(self, VS, pairs, x, params):
        return _merge(VS, pairs)


@kernel
def _merge(VS, pairs):
    return jnp.maximum(VS[pairs[:, 0], 3:4], VS[pairs[:, 1], 3:4])


def delta_at_kept(pa, pb, pos, moving, mask):
    """One pair: |ΔS| when both endpoints go to pa (s = 0 of the pair's family; locked vertices)."""
    u, w = affine_areas(pa, pb, pos, moving)
    return jnp.abs(_delta(jnp.zeros((), pa.dtype), (u.T, w.T, mask, _area(pos, mask))))


@kernel
def price_at_kept_kernel(VS, pairs, params, corners, mask):
    """The price rows at the kept vertex (`at_kept`): |ΔS| there, +inf where the boundary rule pins the
    pair to the removed vertex; branch "end" (2)."""
    pos, moving = ring_positions(VS, pairs, corners)
    pa, pb = VS[pairs[:, 0], :3], VS[pairs[:, 1], :3]
    lo, _ = interval(VS[pairs[:, 0], 3], VS[pairs[:, 1], 3])
    d = jax.vmap(delta_at_kept)(pa, pb, pos, moving, mask)
    cost = jnp.where(lo > 0, jnp.inf, d)
    return jnp.concatenate([pa.T, cost[None], jnp.full_like(cost, 2.0)[None]], 0)
