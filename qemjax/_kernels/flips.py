"""Normal-flip test for contractions, evaluated per face corner.

A contraction moves its endpoints to x. Every surviving face around them (one that does not contain both
endpoints) has one corner moved; the contraction is forbidden if any such face's normal turns past the
threshold: n_before·n_after ≤ cos_max·|n_before||n_after| (default cos_max = 0: any sign flip, and a
face collapsing to zero area or to a sliver, are forbidden).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

SLIVER = 1e-6  # |n|/longest² (≈ sine of the smallest angle) under which a moved face counts as collapsed


def moved_corner_flips(p, k, x, cos_max, ref=None):
    """Does moving corner k (…) int of triangles p (…,3,3) to x (…,3) turn its normal past the
    threshold? Returns (…) bool; a face collapsing to zero area counts as flipped when cos_max ≥ 0.
    With ``ref`` (…,3), the new normal must also stay within the threshold of ``ref`` (the normal of the
    input face this face continues), so that small turns cannot add up to a flip over many rounds."""
    n0 = jnp.cross(p[..., 1, :] - p[..., 0, :], p[..., 2, :] - p[..., 0, :])
    sel = (jnp.arange(3) == k[..., None])[..., None]
    q = jnp.where(sel, x[..., None, :], p)
    n1 = jnp.cross(q[..., 1, :] - q[..., 0, :], q[..., 2, :] - q[..., 0, :])
    d = jnp.sum(n0 * n1, -1)
    l1 = jnp.linalg.norm(n1, axis=-1)
    bad = d <= cos_max * jnp.linalg.norm(n0, axis=-1) * l1
    # sliver guard: float32 rounding can leave a "collinear" result a tiny positive normal
    e = jnp.stack([q[..., 1, :] - q[..., 0, :], q[..., 2, :] - q[..., 1, :], q[..., 0, :] - q[..., 2, :]], -2)
    longest2 = jnp.max(jnp.sum(e * e, -1), -1)
    bad |= (l1 <= SLIVER * longest2) & (cos_max > -1.0)
    if ref is not None:
        bad |= jnp.sum(ref * n1, -1) <= cos_max * jnp.linalg.norm(ref, axis=-1) * l1
    return bad


@jax.jit
def face_flips(p, k, x, mask, ref, cos_max):
    """Per face: does moving corner k (K,) of triangle p (K,3,3) to x (K,3) flip it? (K,) bool."""
    return moved_corner_flips(p, k, x, cos_max, ref) & mask


@jax.jit
def local_flips(p, k, x, mask, ref, cos_max):
    """Any flip among the faces p (K,3,3) (reference normals ref (K,3)) whose corner k (K,) moves to
    x (3,), masked by mask (K,)."""
    xs = jnp.broadcast_to(x, p.shape[:-2] + (3,))
    return jnp.any(moved_corner_flips(p, k, xs, cos_max, ref) & mask)
