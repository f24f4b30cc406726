"""Per-pair optimal placement (Garland & Heckbert §4): minimise v̄ᵀ(Q1+Q2)v̄ with fall-backs.

Branches, reported per pair:
  0 SOLVE     the 3×3 system is well conditioned and its solution is near the pair: solve it;
  1 SEGMENT   otherwise the best point on the segment v1v2 (a 1-D quadratic, clamped to the segment);
  2 ENDPOINT  otherwise (or with ``placement='endpoints'``) the cheapest of v1, v2 and the midpoint.

The arithmetic is written on lists of component arrays (one array per coordinate or quadric entry).
On the CPU this matters: XLA then fuses the whole computation into one loop over contiguous rows, while
column slices of (K,10) arrays or several separate outputs make it recompute shared terms per output
(measured 4-8× slower). `place_pairs` therefore returns a single stacked (5,K) array.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from . import kernel
from . import quadrics as qd

SOLVE, SEGMENT, ENDPOINT = 0, 1, 2


def _merged(q1, q2, p1, p2):
    """Midpoint, half edge vector and Q1+Q2 expressed in the midpoint's frame (component lists)."""
    half = [0.5 * (p2[i] - p1[i]) for i in range(3)]
    mid = [0.5 * (p1[i] + p2[i]) for i in range(3)]
    t1, t2 = qd.translate_c(q1, half), qd.translate_c(q2, [-h for h in half])
    return mid, half, [t1[k] + t2[k] for k in range(10)]


def _place(q1, q2, p1, p2, endpoints_only, cond_eps, max_shift):
    """Core on component lists: q1, q2 (10 arrays), p1, p2 (3 arrays). Returns (x, cost, branch, q, u)
    with x and u component lists, q the merged quadric in the midpoint's frame."""
    mid, half, q = _merged(q1, q2, p1, p2)
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
def merged_quadrics(VQ, pairs, x):
    """(K,10): Q1+Q2 of index pairs (K,2) expressed in the frame of their new positions x (K,3)."""
    q1, q2, p1, p2 = _gather_rows(VQ, pairs)
    mid, _, q = _merged(q1, q2, p1, p2)
    return jnp.stack(qd.translate_c(q, [x[:, i] - mid[i] for i in range(3)]), -1)
