"""Normal-flip test for contractions, evaluated per face corner.

A contraction moves its endpoints to x. Every surviving face around them (one that does not contain both
endpoints) has one corner moved; the contraction is forbidden if any such face's normal turns past the
threshold: n_before·n_after ≤ cos_max·|n_before||n_after| (default cos_max = 0: any sign flip, and a
face collapsing to zero area or to a sliver, are forbidden).

As in `placement`, the arithmetic runs on lists of component arrays so XLA fuses it into one loop.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import kernel
from . import quadrics as qd

SLIVER = 1e-6  # |n|/longest² (≈ sine of the smallest angle) under which a moved face counts as collapsed


def host_limits(cos_max: float, min_quality: float) -> tuple:
    """The flip test's limits as the host rule (`_schedulers.rules.flips`) takes them: float32 cos_max, and
    its ``shape``, float32 (`SLIVER`, min_quality)."""
    return np.float32(cos_max), (np.float32(SLIVER), np.float32(min_quality))


def _sub(u, v):
    return [u[i] - v[i] for i in range(3)]


def _cross(u, v):
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _normal(p0, p1, p2):
    return _cross(_sub(p1, p0), _sub(p2, p0))


def _flips(p, k, x, cos_max, ref, xp=jnp, min_quality=None):
    """Core on component lists: p = [p0, p1, p2] corners, each [x, y, z]; k corner index array;
    x [x, y, z]; ref [x, y, z] or None. Returns a bool array. ``xp``: jax.numpy, or numpy (the tests'
    host reference). ``min_quality``: the quality guard (`Topology.min_angle`; None or 0: off): a face
    whose 2·area / longest edge² ends below it and below what it was counts as flipped. The host form of
    this test, with the same float32 operations in the same order, is `_schedulers.rules.flips`."""
    n0 = _normal(*p)
    q = [[xp.where(k == c, x[i], p[c][i]) for i in range(3)] for c in range(3)]
    n1 = _normal(*q)
    l1 = xp.sqrt(qd.dot(n1, n1))
    bad = qd.dot(n0, n1) <= cos_max * xp.sqrt(qd.dot(n0, n0)) * l1
    # sliver guard: float32 rounding can leave a "collinear" result a tiny positive normal
    e = [_sub(q[1], q[0]), _sub(q[2], q[1]), _sub(q[0], q[2])]
    longest2 = xp.maximum(xp.maximum(qd.dot(e[0], e[0]), qd.dot(e[1], e[1])), qd.dot(e[2], e[2]))
    bad = bad | ((l1 <= SLIVER * longest2) & (cos_max > -1.0))
    if min_quality is not None:
        o = [_sub(p[1], p[0]), _sub(p[2], p[1]), _sub(p[0], p[2])]
        before2 = xp.maximum(xp.maximum(qd.dot(o[0], o[0]), qd.dot(o[1], o[1])), qd.dot(o[2], o[2]))
        worse = l1 * before2 < xp.sqrt(qd.dot(n0, n0)) * longest2
        bad = bad | ((l1 < min_quality * longest2) & worse)
    if ref is not None:
        bad = bad | (qd.dot(ref, n1) <= cos_max * xp.sqrt(qd.dot(ref, ref)) * l1)
    return bad


def moved_corner_flips(p, k, x, cos_max, ref=None):
    """Does moving corner k (…) int of triangles p (…,3,3) to x (…,3) turn its normal past the
    threshold? Returns (…) bool; a face collapsing to zero area counts as flipped when cos_max ≥ 0.
    With ``ref`` (…,3), the new normal must also stay within the threshold of ``ref`` (the normal of the
    input face this face continues), so that small turns cannot add up to a flip over many rounds."""
    pc = [qd.cols(p[..., c, :], 3) for c in range(3)]
    rc = None if ref is None else qd.cols(ref, 3)
    return _flips(pc, k, qd.cols(x, 3), cos_max, rc)


@kernel
def face_flips(p, k, x, mask, ref, cos_max):
    """Per face: does moving corner k (K,) of triangle p (K,3,3) to x (K,3) flip it? (K,) bool."""
    return moved_corner_flips(p, k, x, cos_max, ref) & mask


@jax.jit  # not `kernel`: the older emitter runs this several times slower (docs/benchmarks.md); see below
def face_flips_at(V, N0, faces, fids, k, x, cos_max, min_quality=None):
    """`face_flips` with the inputs gathered here: faces (K,3) index rows of V (N,≥3) (columns 0-2 are
    positions); k (K,) the moving corner, x (K,3) where it goes; the reference normal of face i is
    N0[fids[i]]. Indices are clipped, not checked: padding rows give meaningless results to slice off.
    ``min_quality``: the quality guard's bound (`_flips`), or None: off, and then not computed (a separate
    trace, so that runs without the guard do not pay for its arithmetic). Returns (K,) bool.

    Everything gathered is packed into one (15,K) array and materialised before the arithmetic: with the
    gathers left apart (one per corner, as separate arrays), XLA's CPU fusion recomputes them and takes
    more than twice the CPU time (same results bit for bit; docs/benchmarks.md, "Measured choices inside a
    run").

    Its output is a sign test, so a core-count-dependent FMA contraction could change it only for a face
    within a rounding step of the threshold; the golden cases agree on 1 and 2 cores
    (experiments/golden.py --check under taskset -c 0)."""
    K = faces.shape[0]
    g = jnp.take(V, faces.reshape(-1), axis=0, mode="clip")[:, :3].reshape(K, 9)
    ref = jnp.take(N0, fids, axis=0, mode="clip")
    c = jax.lax.optimization_barrier(jnp.concatenate([g, ref.astype(g.dtype), x.astype(g.dtype)], 1).T)
    p = [[c[3 * j + i] for i in range(3)] for j in range(3)]
    return _flips(p, k, [c[12 + i] for i in range(3)], cos_max, [c[9 + i] for i in range(3)],
                  min_quality=min_quality)
