"""QEM with appearance attributes: Hoppe's memory-efficient generalised quadric (Hoppe 1999, "New quadric
metric for simplifying meshes with appearance attributes").

Each face has a plane (unit normal n) and, for each attribute channel j (u, v; r, g, b, a; nx, ny, nz,
scaled by its weight), a linear field s_j(p) = g_jᵀp + d_j over the face's plane (g_j ⊥ n, fitted through
the face's three corner values). A point p with attribute values s costs, per face of weight w,

    w · [ (nᵀp + d)² + Σ_j (g_jᵀp + d_j − s_j)² ],

the squared distance to the face in (3 + m)-dimensional position × attribute space, like Garland &
Heckbert 1998's generalised quadric, which would store a full (3+m)×(3+m) matrix. Summed over faces this
is the quadric over (u, s), u in the vertex's frame:

    Q(u, s) = uᵀAu + 2bᵀu + c + α·|s|² − 2 Σ_j s_j (G_jᵀu + D_j),

whose s-block is α·I, so it is stored as 11 + 4m floats: the ten of a position quadric (A, b, c), α and
(G_j, D_j) per channel. A full (3+m)-dimensional quadric takes (3+m)(4+m)/2 + (3+m) + 1 floats: 21
against 19 here for UVs (m = 2), 36 against 27 for RGBA (m = 4), 91 against 47 for UV + RGBA + normal
(m = 9), and its per-pair solve is a (3+m)² system instead of a 3×3 one. Minimising over s in closed form,
s_j = (G_jᵀu + D_j)/α, leaves a position quadric

    A − Σ G_j G_jᵀ/α,   b − Σ D_j G_j/α,   c − Σ D_j²/α,

which the QEM placement (`_kernels.placement`: solve, segment, endpoints) minimises unchanged; the
optimal attributes follow from the placement. The state width is 11 + 4m (``width``); weights scale the
channels before the fit, so they never recompile.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

from .._kernels.lazy import jax, jnp  # imported on first use (`_kernels.lazy`)
import numpy as np

from .._kernels.batching import DTYPE
from .._kernels import kernel, placement
from .._kernels import quadrics as qd
from .base import MeshInput
from .qem import QEM


def _translate(st, d, m):
    """Component list of a state (11 + 4m entries) re-expressed in a frame moved by d (3 arrays)."""
    q = qd.translate_c(st[:10], d)
    out = q + [st[10]]
    for j in range(m):
        g = st[11 + 4 * j: 14 + 4 * j]
        out += g + [st[14 + 4 * j] + qd.dot(g, d)]
    return out


def reduce_c(st, m):
    """The position quadric (10 entries) of a state, the attributes minimised out."""
    alpha = st[10]
    inv = 1.0 / jnp.where(alpha > 0, alpha, 1.0)
    q = list(st[:10])
    for j in range(m):
        g, dj = st[11 + 4 * j: 14 + 4 * j], st[14 + 4 * j]
        gi = [x * inv for x in g]
        q[0] = q[0] - g[0] * gi[0]
        q[1] = q[1] - g[0] * gi[1]
        q[2] = q[2] - g[0] * gi[2]
        q[3] = q[3] - g[1] * gi[1]
        q[4] = q[4] - g[1] * gi[2]
        q[5] = q[5] - g[2] * gi[2]
        for i in range(3):
            q[6 + i] = q[6 + i] - dj * gi[i]
        q[9] = q[9] - dj * dj * inv
    return q


def _gather(VS, pairs, width):
    a = jnp.take(VS, pairs[:, 0], axis=0, mode="clip").T
    b = jnp.take(VS, pairs[:, 1], axis=0, mode="clip").T
    a, b = jax.lax.optimization_barrier((a, b))
    return [a[3 + k] for k in range(width)], [b[3 + k] for k in range(width)], [a[k] for k in range(3)], \
        [b[k] for k in range(3)]


def _merged(VS, pairs, m):
    s1, s2, p1, p2 = _gather(VS, pairs, 11 + 4 * m)
    half = [0.5 * (p2[i] - p1[i]) for i in range(3)]
    mid = [0.5 * (p1[i] + p2[i]) for i in range(3)]
    t1, t2 = _translate(s1, half, m), _translate(s2, [-h for h in half], m)
    return mid, half, [x + y for x, y in zip(t1, t2)]


@kernel(static_argnums=(0, 1))
def price_pairs(m, rank, VS, pairs, endpoints_only, eps, max_shift):
    """(5,K) [x, cost, branch] of pairs with attribute states (width 11 + 4m): QEM's placement on the
    reduced quadric of the summed states (module docstring); ``rank``: the truncated solve
    (``placement='rank'``, eps = rank_eps), else the thresholded one (eps = cond_eps)."""
    mid, half, st = _merged(VS, pairs, m)
    place = placement.place_rank_merged if rank else placement.place_merged
    x, cost, branch, _, _ = place(mid, half, reduce_c(st, m), endpoints_only, eps, max_shift)
    return jnp.stack(x + [cost, branch.astype(cost.dtype)], 0)


_PRICE_FNS = {}


def price_function(m: int, rank: bool):
    """The price as a static function of (VS, pairs, params), one object per (m, rank): terms
    (`regularize`, `area_weight`) pass it to their jit as a static argument, so it must not be new on each
    call."""
    key = (int(m), bool(rank))
    if key not in _PRICE_FNS:
        def fn(VS, pairs, params):
            return price_pairs(key[0], key[1], VS, pairs, params["endpoints_only"],
                               params["rank_eps"] if key[1] else params["cond_eps"], params["max_shift"])
        _PRICE_FNS[key] = fn
    return _PRICE_FNS[key]


_MERGE_FNS = {}


def merge_function(m: int):
    """The merge as a static function of (VS, pairs, x, params), one object per m (as `price_function`)."""
    if m not in _MERGE_FNS:
        def fn(VS, pairs, x, params):
            return merge_pairs(m, VS, pairs, x)
        _MERGE_FNS[m] = fn
    return _MERGE_FNS[m]


@kernel(static_argnums=0)
def merge_pairs(m, VS, pairs, x):
    """(K, 11 + 4m) summed states in the frames of the new positions x (K,3)."""
    mid, _, st = _merged(VS, pairs, m)
    return jnp.stack(_translate(st, [x[:, i] - mid[i] for i in range(3)], m), -1)


def face_fields(P: np.ndarray, S: np.ndarray):
    """Per face, the linear attribute fields through its corners: P (f,3,3) corner positions, S (f,3,m)
    corner values -> g (f,m,3) gradients in the face's plane and d (f,m) with s(p) = g·p + d (float64).
    Faces too thin to fit get g = 0, d = the mean of their corners."""
    from .._mesh import fixed_order_solve  # here: importing the cost models does not need numba
    from . import attribute_sums

    M, rhs, nn = attribute_sums.face_systems(np.ascontiguousarray(P, np.float64), np.ascontiguousarray(S, np.float64))
    X, det = fixed_order_solve.solve(M, rhs)  # not np.linalg: LAPACK's bits differ by CPU
    ok = np.abs(det) > 1e-12 * np.maximum(nn, 1e-300) ** 1.5
    sol = np.zeros_like(rhs)
    sol[ok] = X[ok]
    sol[~ok, 3] = S[~ok].mean(1)
    return np.transpose(sol[:, :3], (0, 2, 1)), sol[:, 3]


def attribute_state(V: np.ndarray, F: np.ndarray, S: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(n, 1 + 4m) float64 [α, (G_j, D_j)…] per vertex, in its own frame, and the (n,10) attribute part of
    its position quadric: V (n,3), F (f,3), corner values S (f,3,m), face weights w (f,)."""
    n, m = len(V), S.shape[2]
    g, d = face_fields(V[F], S)
    from . import attribute_sums  # here: importing the cost models does not need numba

    if 1 <= m <= attribute_sums.MAX_CHANNELS and len(F):  # the same sums, compiled
        return attribute_sums.corner_sums(np.ascontiguousarray(F, np.int64), np.ascontiguousarray(g, np.float64),
                                          np.ascontiguousarray(S, np.float64), np.ascontiguousarray(w, np.float64), n)
    gg = np.einsum("fji,fjk->fik", g, g)  # Σ_j g gᵀ per face
    packed = gg[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    cols = []  # per corner k (k-major, as the faces' corners are summed): the columns to scatter
    for k in range(3):
        s = S[:, k]  # the field's value at the corner: D in the corner's frame
        c = [w[:, None] * packed, w[:, None] * np.einsum("fj,fji->fi", s, g), (w * np.sum(s * s, 1))[:, None],
             w[:, None]]
        for j in range(m):
            c += [w[:, None] * g[:, j], (w * s[:, j])[:, None]]
        cols.append(np.concatenate(c, 1))
    X = np.concatenate(cols)  # (3f, 10 + 1 + 4m)
    idx = F.T.reshape(-1)
    # bincount adds in index order, so each sum is the corners' in k-major order, as a loop would
    return np.stack([np.bincount(idx, X[:, c], minlength=n) for c in range(X.shape[1])], 1)


def _np_translate(st: np.ndarray, d: np.ndarray, m: int) -> np.ndarray:
    """A state (11 + 4m,) re-expressed in a frame moved by d (3,), float64 numpy."""
    # Python floats, in a fixed order (not BLAS, whose bits vary by CPU; and a pair at a time, numpy's
    # per-call overhead would dominate)
    a0, a1, a2, a3, a4, a5, b0, b1, b2 = st[:9].tolist()
    d0, d1, d2 = d.tolist()
    ad = (a0 * d0 + a1 * d1 + a2 * d2, a1 * d0 + a3 * d1 + a4 * d2, a2 * d0 + a4 * d1 + a5 * d2)
    out = st.copy()
    out[6:9] += ad
    out[9] += d0 * (ad[0] + 2 * b0) + d1 * (ad[1] + 2 * b1) + d2 * (ad[2] + 2 * b2)
    g = st[11:].tolist()
    out[14::4] += [g[4 * j] * d0 + g[4 * j + 1] * d1 + g[4 * j + 2] * d2 for j in range(m)]
    return out


def optimal_attributes(rows_a: np.ndarray, rows_b: np.ndarray, X: np.ndarray, m: int) -> np.ndarray:
    """(K,m) the optimal (weighted) attribute values at X (K,3) of K pairs' summed states, rows (K, 3 + 11
    + 4m) [position, state] each in its vertex's frame: s_j = Σ (D_j + G_j·(x − p)) / Σ α, float64 on
    the host (0 where α is 0)."""
    num = np.zeros((len(X), m))
    alpha = np.zeros(len(X))
    for rows in (rows_a, rows_b):
        r = np.asarray(rows, np.float64)
        d = np.asarray(X, np.float64) - r[:, :3]
        G = r[:, 14:].reshape(len(r), m, 4)
        num += G[:, :, 3] + (G[:, :, 0] * d[:, None, 0] + G[:, :, 1] * d[:, None, 1] + G[:, :, 2] * d[:, None, 2])
        alpha += r[:, 13]
    return np.where(alpha[:, None] > 0, num / np.where(alpha > 0, alpha, 1.0)[:, None], 0.0)


def solve_host(row_a: np.ndarray, row_b: np.ndarray, x: np.ndarray, m: int):
    """float64 on the host, for a pair's rows [position, state]: (reduced cost at x, optimal attributes at
    x (m,))."""
    ra, rb = row_a.astype(np.float64), row_b.astype(np.float64)
    x = np.asarray(x, np.float64)
    st = _np_translate(ra[3:], x - ra[:3], m) + _np_translate(rb[3:], x - rb[:3], m)
    alpha = st[10]
    G = st[11:].reshape(m, 4)
    s = G[:, 3] / alpha if alpha > 0 else np.zeros(m)
    cost = st[9] - (np.sum(G[:, 3] ** 2) / alpha if alpha > 0 else 0.0)
    return max(float(cost), 0.0), s


def _translate_many(st: np.ndarray, d: np.ndarray, m: int) -> np.ndarray:
    """`_np_translate` of K states (K, 11 + 4m) by d (K,3) at once: the same operations in the same order,
    elementwise (so the same bits)."""
    a0, a1, a2, a3, a4, a5, b0, b1, b2 = (st[:, k] for k in range(9))
    d0, d1, d2 = d[:, 0], d[:, 1], d[:, 2]
    ad = (a0 * d0 + a1 * d1 + a2 * d2, a1 * d0 + a3 * d1 + a4 * d2, a2 * d0 + a4 * d1 + a5 * d2)
    out = st.copy()
    for k in range(3):
        out[:, 6 + k] += ad[k]
    out[:, 9] += d0 * (ad[0] + 2 * b0) + d1 * (ad[1] + 2 * b1) + d2 * (ad[2] + 2 * b2)
    g = st[:, 11:]
    out[:, 14::4] += g[:, 0::4] * d0[:, None] + g[:, 1::4] * d1[:, None] + g[:, 2::4] * d2[:, None]
    return out


def cost_held_many(rows_a: np.ndarray, rows_b: np.ndarray, X: np.ndarray, S: np.ndarray, m: int) -> np.ndarray:
    """(K,) float64 on the host, for K pairs' rows [position, state]: the cost at X (K,3) with the (weighted)
    attribute values held at S (K,m) instead of their optimum: Q(x, s) = c + α·|s|² − 2 Σ s_j D_j (module
    docstring; a locked vertex's price, its values kept)."""
    ra, rb = np.asarray(rows_a, np.float64), np.asarray(rows_b, np.float64)
    X, S = np.asarray(X, np.float64), np.asarray(S, np.float64)
    st = _translate_many(ra[:, 3:], X - ra[:, :3], m) + _translate_many(rb[:, 3:], X - rb[:, :3], m)
    ss = sd = np.zeros(len(X))
    for j in range(m):  # left to right, as `fixed_order.dot`
        ss = ss + S[:, j] * S[:, j]
        sd = sd + S[:, j] * st[:, 14 + 4 * j]
    return np.maximum(st[:, 9] + st[:, 10] * ss - 2.0 * sd, 0.0)


@dataclasses.dataclass(frozen=True)
class AttributeQEM(QEM):
    """QEM over position × attributes (module docstring): QEM's settings, plus ``channels`` m (the number
    of attribute scalars, in `_wedges.KINDS` order) and ``weights`` (m,) each channel's weight."""

    name: ClassVar[str] = "qem"  # `simplify(method='qem')` with attributes kept
    error_measure: ClassVar[str] = "quadric error (a sum of squared distances to planes) plus weighted attribute deviation"
    channels: int = 0
    weights: tuple = ()

    width = property(lambda self: 11 + 4 * self.channels)
    at_kept_kernel = None  # locked vertices are priced on the host by `cost_at` (`qemjax._schedulers.locks`)

    def __post_init__(self):
        super().__post_init__()
        if self.channels < 1 or len(self.weights) != self.channels:
            raise ValueError(f"need one weight per channel, got {len(self.weights)} for {self.channels}")

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        return self.with_attributes(mesh, super().init_state(mesh))

    def with_attributes(self, mesh: MeshInput, q: np.ndarray) -> np.ndarray:
        """The state of position quadrics ``q`` (n,10) (QEM's, or quadrics carried from elsewhere) with the
        attribute quadrics of ``mesh``'s faces added."""
        q = np.asarray(q).astype(np.float64)
        V = np.asarray(mesh.V, np.float64)
        F = np.asarray(mesh.F, np.int64)
        S = np.asarray(mesh.attributes, np.float64) * np.asarray(self.weights, np.float64)
        P = V[F]
        area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
        if self.area_weighted:
            mean_area = mesh.means[0] if mesh.means is not None else area.mean()
            w = (area / max(mean_area, np.finfo(DTYPE).tiny)) ** self.area_power
        else:
            w = np.ones(len(F))
        st = attribute_state(V, F, S, w)
        st[:, :10] += q
        return st.astype(DTYPE)

    @property
    def price_kernel(self):
        return price_function(self.channels, self.placement == "rank")

    @property
    def merge_kernel(self):  # (`QEM.price` and `QEM.merge` call these two kernels)
        return merge_function(int(self.channels))

    def vertex_error(self, state: np.ndarray) -> np.ndarray:
        """The position-and-attribute error at each vertex (attributes at their optimum)."""
        s = state.astype(np.float64)
        alpha = s[:, 10]
        D = s[:, 14::4]
        with np.errstate(divide="ignore", invalid="ignore"):
            red = np.where(alpha > 0, np.sum(D * D, 1) / np.where(alpha > 0, alpha, 1.0), 0.0)
        return np.maximum(s[:, 9] - red, 0.0)

    def cost_at(self, row_a, row_b, x) -> float:
        return solve_host(row_a, row_b, x, self.channels)[0]

    def cost_held(self, rows_a, rows_b, X, S) -> np.ndarray:
        """(K,) the costs at X (K,3) with the attributes held at S (K,m), weighted (locked kept vertices'
        values): `cost_held_many`."""
        return cost_held_many(rows_a, rows_b, X, S, self.channels)

    def attributes_at(self, row_a, row_b, x) -> np.ndarray:
        """(m,) the optimal attribute values at x, unweighted."""
        return solve_host(row_a, row_b, x, self.channels)[1] / np.asarray(self.weights, np.float64)

    def attributes_at_many(self, rows_a, rows_b, X) -> np.ndarray:
        """(K,m) `attributes_at` for K pairs at once: rows (K, 3 + width), X (K,3)."""
        return optimal_attributes(rows_a, rows_b, X, self.channels) / np.asarray(self.weights, np.float64)
