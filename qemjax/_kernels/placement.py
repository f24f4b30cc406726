"""Per-pair optimal placement (Garland & Heckbert §4) with fall-backs; two solves.

Around the pair's midpoint, the merged quadric is Q(u) = uᵀAu + 2bᵀu + c, A symmetric positive
semi-definite with eigenvalues λ1 ≥ λ2 ≥ λ3 ≥ 0 on n1, n2, n3.

- ``placement='optimal'`` (thresholded, the default): solve A·u = −b when det(A) > cond_eps·‖A‖_F³;
  otherwise fall back to the segment.
- ``placement='rank'`` (truncated): minimise Q over the directions whose λᵢ > rank_eps·λ1 and stay at
  the midpoint in the others, u = −Σ_kept nᵢ(nᵢ·b)/λᵢ (the truncated pseudo-inverse of Lindstrom's
  out-of-core simplification). A flat patch then keeps the midpoint's position along the plane and
  moves only across it, a crease keeps it along the crease, instead of both being confined to the edge.

Branches, reported per pair:
  0 SOLVE      A is well conditioned (every direction kept): the exact minimiser;
  3 TRUNCATED  ('rank' only) one or two directions kept: the truncated pseudo-inverse solution;
  1 SEGMENT    otherwise, or where the solution lies farther than max_shift·|v2 − v1| from the midpoint:
               the best point on the segment v1v2 (a 1-D quadratic, clamped to the segment);
  2 ENDPOINT   otherwise (or with ``placement='endpoints'``) the cheapest of v1, v2 and the midpoint.

The arithmetic is written on lists of component arrays (one array per coordinate or quadric entry).
On the CPU this matters: XLA then fuses the whole computation into one loop over contiguous rows, while
column slices of (K,10) arrays or several separate outputs make it recompute shared terms per output
(several times slower). `place_pairs` therefore returns a single stacked (5,K) array. The truncated
solve costs more arithmetic (docs/methods.md, "QEM and its presets"), so each mode is its own kernel (`place_pairs`,
`place_pairs_rank`): the default's compiled code is the one it always was.
"""
from __future__ import annotations

from .lazy import jax, jnp  # imported on first use (`_kernels.lazy`)

from . import kernel
from . import quadrics as qd

SOLVE, SEGMENT, ENDPOINT, TRUNCATED = 0, 1, 2, 3

# A spread of the eigenvalues below this (A scaled to unit Frobenius norm) counts as none (its cube is
# not formed): far under float32's resolution of a unit-norm matrix, far above its underflow.
_SMALL = 1e-12


def _merged(q1, q2, p1, p2):
    """Midpoint, half edge vector and Q1+Q2 expressed in the midpoint's frame (component lists)."""
    half = [0.5 * (p2[i] - p1[i]) for i in range(3)]
    mid = [0.5 * (p1[i] + p2[i]) for i in range(3)]
    t1, t2 = qd.translate_c(q1, half), qd.translate_c(q2, [-h for h in half])
    return mid, half, [t1[k] + t2[k] for k in range(10)]


def _fro(q):
    """‖A‖_F of a packed quadric (component list)."""
    return jnp.sqrt(q[0] * q[0] + q[3] * q[3] + q[5] * q[5] + 2.0 * (q[1] * q[1] + q[2] * q[2] + q[4] * q[4]))


def _column(m):
    """The column of the symmetric m (6 packed entries) with the largest diagonal entry: for a rank-one
    PSD m = μ·nnᵀ, μ·n_i·n (not normalised; zero where m is)."""
    pick1, pick2 = m[3] > m[0], m[5] > jnp.maximum(m[0], m[3])
    c1 = [jnp.where(pick1, m[1], m[0]), jnp.where(pick1, m[3], m[1]), jnp.where(pick1, m[4], m[2])]
    return [jnp.where(pick2, m[2], c1[0]), jnp.where(pick2, m[4], c1[1]), jnp.where(pick2, m[5], c1[2])]


def _largest_eigenvalue(m):
    """λ1 of the symmetric m (6 packed entries, Frobenius norm ≤ 1): the trigonometric solution of the
    characteristic cubic (accurate for λ1 whenever it is a simple eigenvalue)."""
    mean = (m[0] + m[3] + m[5]) / 3.0
    k0, k3, k5 = m[0] - mean, m[3] - mean, m[5] - mean
    p = jnp.sqrt((k0 * k0 + k3 * k3 + k5 * k5 + 2.0 * (m[1] * m[1] + m[2] * m[2] + m[4] * m[4])) / 6.0)
    det_k = _cofactors([k0, m[1], m[2], k3, m[4], k5])[1]
    sp = jnp.where(p > _SMALL, p, 1.0)
    r = jnp.clip(0.5 * det_k / (sp * sp * sp), -1.0, 1.0)
    return mean + 2.0 * p * jnp.cos(jnp.arccos(r) / 3.0)


def _cofactors(m):
    """adj(m) packed (6 entries) and det(m) of the symmetric 3×3 m (6 packed entries)."""
    a, b, c, d, e, f = m
    adj = [d * f - e * e, c * e - b * f, b * e - c * d, a * f - c * c, b * c - a * e, a * d - b * b]
    return adj, a * adj[0] + b * adj[1] + c * adj[2]


def _truncated_solve(q, rank_eps):
    """Minimiser u of Q(u) = uᵀAu + 2bᵀu + c over the eigen-directions of A whose eigenvalue exceeds
    rank_eps·λ1 (the truncated pseudo-inverse: u = −Σ_kept nᵢ(nᵢ·b)/λᵢ), and how many were kept (0-3).

    No general eigen-solver (on the CPU the kernel's time grows with its operation count): with A scaled
    to unit Frobenius norm, λ1 comes from the trigonometric solution of the characteristic cubic, λ2 and
    λ3 are the roots of x² − (tr A − λ1)·x + det A/λ1, and the eigenvector of a simple eigenvalue λ is
    the longest column of adj(A − λ·I) (rank one). Rank 3 solves A·u = −b by cofactors; rank 2 the same
    with A + λ1·n3n3ᵀ and b without its n3 part (the solution then has none); rank 1 projects on n1.
    """
    fro = _fro(q)
    nonzero = fro > jnp.finfo(fro.dtype).tiny
    s = 1.0 / jnp.where(nonzero, fro, 1.0)
    m = [v * s for v in q[:6]]
    bv = q[6:9]
    det = _cofactors(m)[1]
    lam1 = _largest_eigenvalue(m)
    tol = rank_eps * lam1
    # λ2 ≥ λ3: the roots of x² − (tr A − λ1)·x + det A/λ1
    rest = m[0] + m[3] + m[5] - lam1
    prod = jnp.maximum(det, 0.0) / jnp.where(lam1 > 0, lam1, 1.0)
    lam2 = 0.5 * rest + jnp.sqrt(jnp.maximum(0.25 * rest * rest - prod, 0.0))
    lam3 = prod / jnp.where(lam2 > 0, lam2, 1.0)
    keep2 = nonzero & (lam2 > tol)
    keep3 = keep2 & (lam3 > tol)
    # rank 2 or 3: (A + λ1·n3n3ᵀ)·u = −(b − n3(n3·b)), with n3 = 0 for rank 3; n3 spans adj(A − λ3·I)
    w = _column(_cofactors([m[0] - lam3, m[1], m[2], m[3] - lam3, m[4], m[5] - lam3])[0])
    ww = qd.dot(w, w)
    iww = jnp.where(keep3 | (ww <= 0), 0.0, 1.0 / jnp.where(ww > 0, ww, 1.0))
    wb = qd.dot(w, bv) * iww
    rhs = [bv[i] - w[i] * wb for i in range(3)]
    k = lam1 * iww
    shifted = [m[0] + k * w[0] * w[0], m[1] + k * w[0] * w[1], m[2] + k * w[0] * w[2],
               m[3] + k * w[1] * w[1], m[4] + k * w[1] * w[2], m[5] + k * w[2] * w[2]]
    adj2, det2 = _cofactors(shifted)
    # rank 1: along n1, which spans adj(A − λ1·I) = (λ1 − λ2)(λ1 − λ3)·n1n1ᵀ; one division for both
    v1 = _column(_cofactors([m[0] - lam1, m[1], m[2], m[3] - lam1, m[4], m[5] - lam1])[0])
    num = -s * jnp.where(keep2, 1.0, qd.dot(v1, bv))
    den = jnp.where(keep2, det2, qd.dot(v1, v1) * lam1)
    f = num / jnp.where(den != 0, den, 1.0)
    u2 = qd.matvec_c(adj2, rhs)
    u = [jnp.where(keep2, u2[i], v1[i]) * f for i in range(3)]
    rank = jnp.where(keep3, 3, jnp.where(keep2, 2, jnp.where(nonzero & (lam1 > 0), 1, 0)))
    return u, rank


def _place(q1, q2, p1, p2, endpoints_only, cond_eps, max_shift):
    """``placement='optimal'`` on component lists: q1, q2 (10 arrays), p1, p2 (3 arrays). Returns
    (x, cost, branch, q, u) with x and u component lists, q the merged quadric in the midpoint's frame."""
    mid, half, q = _merged(q1, q2, p1, p2)
    return place_merged(mid, half, q, endpoints_only, cond_eps, max_shift)


def place_merged(mid, half, q, endpoints_only, cond_eps, max_shift):
    """`_place` for a quadric q already merged in the midpoint's frame (component lists; mid, half: the
    midpoint and half the edge vector). The attribute model (`_costs.attributes`) places with it."""
    a, b_, c, d, e, f = q[:6]
    bv, cc = q[6:9], q[9]
    # det(A) and adj(A)·b by cofactors
    c00, c01, c02 = d * f - e * e, c * e - b_ * f, b_ * e - c * d
    c11, c12, c22 = a * f - c * c, b_ * c - a * e, a * d - b_ * b_
    det = a * c00 + b_ * c01 + c * c02
    adjb = [c00 * bv[0] + c01 * bv[1] + c02 * bv[2],
            c01 * bv[0] + c11 * bv[1] + c12 * bv[2],
            c02 * bv[0] + c12 * bv[1] + c22 * bv[2]]
    fro = jnp.sqrt(a * a + d * d + f * f + 2.0 * (b_ * b_ + c * c + e * e))
    tiny = jnp.finfo(a.dtype).tiny
    solvable = (det > cond_eps * fro * fro * fro) & (fro > tiny)
    inv = -1.0 / jnp.where(solvable, det, 1.0)
    u_opt = [adjb[i] * inv for i in range(3)]
    hh = qd.dot(half, half)
    # |u_opt| <= max_shift·|p2 − p1| = 2·max_shift·|half|
    solvable = solvable & (qd.dot(u_opt, u_opt) <= 4.0 * max_shift * max_shift * hh)

    # best point on the segment: u = s·half, s ∈ [-1, 1]
    hAh = qd.dot(half, qd.matvec_c(q, half))
    bh = qd.dot(bv, half)
    seg_ok = hAh > cond_eps * fro * hh
    s_seg = jnp.clip(-bh / jnp.where(seg_ok, hAh, 1.0), -1.0, 1.0)
    # endpoints and midpoint: Q(s·half) = s²·hAh + 2s·bh + c; ties prefer the midpoint, then v1
    c_1, c_2 = hAh - 2.0 * bh + cc, hAh + 2.0 * bh + cc
    s_end = jnp.where((c_1 < cc) & (c_1 <= c_2), -1.0, jnp.where(c_2 < cc, 1.0, 0.0))

    use_solve = solvable & ~endpoints_only
    use_seg = ~use_solve & seg_ok & ~endpoints_only
    branch = jnp.where(use_solve, SOLVE, jnp.where(use_seg, SEGMENT, ENDPOINT)).astype(jnp.int32)
    s = jnp.where(use_seg, s_seg, s_end)
    u = [jnp.where(use_solve, u_opt[i], s * half[i]) for i in range(3)]
    cost = jnp.maximum(qd.evaluate_c(q, u), 0.0)
    return [mid[i] + u[i] for i in range(3)], cost, branch, q, u


def _place_rank(q1, q2, p1, p2, endpoints_only, rank_eps, max_shift):
    """``placement='rank'``: as `_place`, with the truncated solve."""
    mid, half, q = _merged(q1, q2, p1, p2)
    return place_rank_merged(mid, half, q, endpoints_only, rank_eps, max_shift)


def place_rank_merged(mid, half, q, endpoints_only, rank_eps, max_shift):
    """`_place_rank` for a quadric q already merged in the midpoint's frame (as `place_merged`)."""
    bv, cc = q[6:9], q[9]
    u_opt, rank = _truncated_solve(q, rank_eps)
    full = rank == 3
    nonzero = rank > 0
    hh = qd.dot(half, half)
    # |u_opt| <= max_shift·|p2 − p1| = 2·max_shift·|half|
    solvable = nonzero & (qd.dot(u_opt, u_opt) <= 4.0 * max_shift * max_shift * hh)

    # best point on the segment: u = s·half, s ∈ [-1, 1]
    hAh = qd.dot(half, qd.matvec_c(q, half))
    bh = qd.dot(bv, half)
    seg_ok = hAh > rank_eps * _fro(q) * hh
    s_seg = jnp.clip(-bh / jnp.where(seg_ok, hAh, 1.0), -1.0, 1.0)
    # endpoints and midpoint: Q(s·half) = s²·hAh + 2s·bh + c; ties prefer the midpoint, then v1
    c_1, c_2 = hAh - 2.0 * bh + cc, hAh + 2.0 * bh + cc
    s_end = jnp.where((c_1 < cc) & (c_1 <= c_2), -1.0, jnp.where(c_2 < cc, 1.0, 0.0))

    use_solve = solvable & ~endpoints_only
    use_seg = ~use_solve & seg_ok & ~endpoints_only
    branch = jnp.where(use_solve, jnp.where(full, SOLVE, TRUNCATED),
                       jnp.where(use_seg, SEGMENT, ENDPOINT)).astype(jnp.int32)
    s = jnp.where(use_seg, s_seg, s_end)
    u = [jnp.where(use_solve, u_opt[i], s * half[i]) for i in range(3)]
    cost = jnp.maximum(qd.evaluate_c(q, u), 0.0)
    return [mid[i] + u[i] for i in range(3)], cost, branch, q, u


def place(q1, q2, p1, p2, endpoints_only, cond_eps, max_shift):
    """Optimal contraction target of pairs.

    q1, q2 (…,10) quadrics in the frames of p1, p2 (…,3). endpoints_only (…) bool: the paper's fixed
    placement. cond_eps (…): the solve is used when det(A) > cond_eps·‖A‖_F³ (a lower bound on
    λmin/λmax). max_shift (…): and when the solution lies within max_shift·|p2−p1| of the midpoint.
    Returns x (…,3) absolute position, cost (…) ≥ 0 (squared distance, units of p), branch (…) int32,
    qsum (…,10) the summed quadric in the frame of x.
    """
    x, cost, branch, q, u = _place(qd.cols(q1, 10), qd.cols(q2, 10), qd.cols(p1, 3), qd.cols(p2, 3),
                                   endpoints_only, cond_eps, max_shift)
    return jnp.stack(x, -1), cost, branch, jnp.stack(qd.translate_c(q, u), -1)


def place_rank(q1, q2, p1, p2, endpoints_only, rank_eps, max_shift):
    """`place` with the truncated solve (``placement='rank'``): the eigenvalues of A at or below
    rank_eps·λmax (…) are dropped, those directions stay at the midpoint; the solution is used when it
    lies within max_shift·|p2−p1| of the midpoint, else the segment. Same returns as `place`."""
    x, cost, branch, q, u = _place_rank(qd.cols(q1, 10), qd.cols(q2, 10), qd.cols(p1, 3), qd.cols(p2, 3),
                                        endpoints_only, rank_eps, max_shift)
    return jnp.stack(x, -1), cost, branch, jnp.stack(qd.translate_c(q, u), -1)


def _gather_rows(VQ, pairs):
    """Component lists (q1, q2, p1, p2) of index pairs (K,2) into VQ (N,13) rows [x y z q0…q9].
    The gathered rows are transposed and materialised (the barrier) so the arithmetic reads contiguous
    rows; indices are clipped, not checked (callers pass valid or padding indices)."""
    a = jnp.take(VQ, pairs[:, 0], axis=0, mode="clip").T
    b = jnp.take(VQ, pairs[:, 1], axis=0, mode="clip").T
    a, b = jax.lax.optimization_barrier((a, b))
    return [a[3 + k] for k in range(10)], [b[3 + k] for k in range(10)], [a[k] for k in range(3)], \
        [b[k] for k in range(3)]


@kernel
def place_pairs(VQ, pairs, endpoints_only, cond_eps, max_shift):
    """Batched placement for index pairs (K,2) into vertex rows VQ (N,13) = [position (3), quadric (10)].

    The tunables are arrays, never static. Returns one (5,K) array: x (rows 0-2), cost (row 3) and the
    branch (row 4, as a float).
    """
    q1, q2, p1, p2 = _gather_rows(VQ, pairs)
    x, cost, branch, _, _ = _place(q1, q2, p1, p2, endpoints_only, cond_eps, max_shift)
    return jnp.stack(x + [cost, branch.astype(cost.dtype)], 0)


@kernel
def place_pairs_rank(VQ, pairs, endpoints_only, rank_eps, max_shift):
    """`place_pairs` with the truncated solve (``placement='rank'``). Same (5,K) output."""
    q1, q2, p1, p2 = _gather_rows(VQ, pairs)
    x, cost, branch, _, _ = _place_rank(q1, q2, p1, p2, endpoints_only, rank_eps, max_shift)
    return jnp.stack(x + [cost, branch.astype(cost.dtype)], 0)


@kernel
def merged_quadrics(VQ, pairs, x):
    """(K,10): Q1+Q2 of index pairs (K,2) expressed in the frame of their new positions x (K,3)."""
    q1, q2, p1, p2 = _gather_rows(VQ, pairs)
    mid, _, q = _merged(q1, q2, p1, p2)
    return jnp.stack(qd.translate_c(q, [x[:, i] - mid[i] for i in range(3)]), -1)
