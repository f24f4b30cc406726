"""Per-pair optimal placement (Garland & Heckbert §4): minimise v̄ᵀ(Q1+Q2)v̄ with fall-backs.

Branches, reported per pair:
  0 SOLVE     the 3×3 system is well conditioned and its solution is near the pair: solve it;
  1 SEGMENT   otherwise the best point on the segment v1v2 (a 1-D quadratic, clamped to the segment);
  2 ENDPOINT  otherwise (or with ``placement='endpoints'``) the cheapest of v1, v2 and the midpoint.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from . import quadrics as qd

SOLVE, SEGMENT, ENDPOINT = 0, 1, 2


def _cofactor_solve(q, b):
    """det(A) and adj(A)·b for the symmetric 3×3 A of packed quadrics q (…,10)."""
    a, b_, c, d, e, f = (q[..., k] for k in range(6))
    c00 = d * f - e * e
    c01 = c * e - b_ * f
    c02 = b_ * e - c * d
    c11 = a * f - c * c
    c12 = b_ * c - a * e
    c22 = a * d - b_ * b_
    det = a * c00 + b_ * c01 + c * c02
    x = jnp.stack(
        [
            c00 * b[..., 0] + c01 * b[..., 1] + c02 * b[..., 2],
            c01 * b[..., 0] + c11 * b[..., 1] + c12 * b[..., 2],
            c02 * b[..., 0] + c12 * b[..., 1] + c22 * b[..., 2],
        ],
        -1,
    )
    return det, x


def place(q1, q2, p1, p2, endpoints_only, cond_eps, max_shift):
    """Optimal contraction target of pairs.

    q1, q2 (…,10) quadrics in the frames of p1, p2 (…,3). endpoints_only (…) bool: the paper's fixed
    placement. cond_eps (…): the solve is used when det(A) > cond_eps·‖A‖_F³ (a lower bound on
    λmin/λmax). max_shift (…): and when the solution lies within max_shift·|p2−p1| of the midpoint.
    Returns x (…,3) absolute position, cost (…) ≥ 0 (squared distance, units of p), branch (…) int32,
    qsum (…,10) the summed quadric in the frame of x.
    """
    dt = p1.dtype
    mid = 0.5 * (p1 + p2)
    half = 0.5 * (p2 - p1)
    q = qd.translate(q1, half) + qd.translate(q2, -half)  # both now in the midpoint's frame
    b, c = q[..., 6:9], q[..., 9]

    det, adjb = _cofactor_solve(q, b)
    diag, off = q[..., jnp.array([0, 3, 5])], q[..., jnp.array([1, 2, 4])]
    fro = jnp.sqrt(jnp.sum(diag * diag, -1) + 2.0 * jnp.sum(off * off, -1))
    tiny = jnp.finfo(dt).tiny
    solvable = (det > cond_eps * fro**3) & (fro > tiny)
    u_opt = -adjb / jnp.where(solvable, det, 1.0)[..., None]
    elen = 2.0 * jnp.linalg.norm(half, axis=-1)
    solvable = solvable & (jnp.linalg.norm(u_opt, axis=-1) <= max_shift * elen)

    # best point on the segment: u = s·half, s ∈ [-1, 1]
    Ah = qd.matvec(q, half)
    hAh = jnp.sum(half * Ah, -1)
    bh = jnp.sum(b * half, -1)
    seg_ok = hAh > cond_eps * fro * jnp.sum(half * half, -1)
    s = jnp.clip(-bh / jnp.where(seg_ok, hAh, 1.0), -1.0, 1.0)
    u_seg = s[..., None] * half

    # endpoints and midpoint: Q(s·half) = s²·hAh + 2s·bh + c; ties prefer the midpoint, then v1
    c_m, c_1, c_2 = c, hAh - 2.0 * bh + c, hAh + 2.0 * bh + c
    s_end = jnp.where((c_1 < c_m) & (c_1 <= c_2), -1.0, jnp.where(c_2 < c_m, 1.0, 0.0))
    u_end = s_end[..., None] * half

    use_solve = solvable & ~endpoints_only
    use_seg = ~use_solve & seg_ok & ~endpoints_only
    branch = jnp.where(use_solve, SOLVE, jnp.where(use_seg, SEGMENT, ENDPOINT)).astype(jnp.int32)
    u = jnp.where(use_solve[..., None], u_opt, jnp.where(use_seg[..., None], u_seg, u_end))
    cost = jnp.maximum(qd.evaluate(q, u), 0.0)
    return mid + u, cost, branch, qd.translate(q, u)


@jax.jit
def place_pairs(V, Q, pairs, endpoints_only, cond_eps, max_shift):
    """Batched `place` for index pairs (K,2) into vertex arrays V (N,3), Q (N,10).

    ``endpoints_only`` may be a scalar or per pair (K,); the tunables are arrays, never static.
    Returns x (K,3), cost (K,), branch (K,) int32, qsum (K,10) (the merged quadric in x's frame).
    """
    i, j = pairs[:, 0], pairs[:, 1]
    return place(Q[i], Q[j], V[i], V[j], endpoints_only, cond_eps, max_shift)
