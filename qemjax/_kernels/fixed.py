"""Arithmetic in a fixed order, for kernels whose results must not depend on the batch they run in.

On the CPU, XLA compiles a reduction over a short axis (``jnp.sum(v, -1)`` over 3 coordinates, a sum over a
ring of R faces) into loops whose order of additions and use of fused multiply-adds depend on the shape of
the whole array, so the same pair priced among 37 pairs or among 128 can differ in the last bit
(`simplify_batch` would then stop equalling `simplify` alone). Written as element-wise operations on
slices, each result is computed by the same sequence of operations whatever the batch: coordinates added
left to right, a ring summed by halving (its width is a power of two: `ring.group_rings`).
"""
from __future__ import annotations

from .lazy import jnp  # imported on first use (`_kernels.lazy`)


def dot3(a, b):
    """(…,) a·b over the last axis of length 3, as a0·b0 + a1·b1 + a2·b2."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross3(a, b):
    """(…,3) a × b over the last axis."""
    return jnp.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                      a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)


def norm3(a):
    """(…,) |a| over the last axis of length 3."""
    return jnp.sqrt(dot3(a, a))


def tree_sum(v):
    """(…,) the sum over the last axis by pairwise halving (zero-padded to a power of two)."""
    w = v.shape[-1]
    if w == 0:
        return jnp.zeros(v.shape[:-1], v.dtype)
    p = 1 << (w - 1).bit_length()
    if p != w:
        v = jnp.concatenate([v, jnp.zeros(v.shape[:-1] + (p - w,), v.dtype)], -1)
    while p > 1:
        p //= 2
        v = v[..., :p] + v[..., p:2 * p]
    return v[..., 0]
