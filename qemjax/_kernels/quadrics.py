"""Quadric storage and algebra.

A quadric is the function Q(u) = uᵀAu + 2bᵀu + c of a point u given *relative to a frame origin p*
(x = p + u). It is stored packed as 10 numbers ``[a00 a01 a02 a11 a12 a22 b0 b1 b2 c]``.

Keeping each vertex's quadric in a frame centred on the vertex means a plane through that vertex
contributes only to A (b = c = 0), and sums of quadrics are formed after translating by short edge
vectors: no large terms cancel, which is what makes float32 costs trustworthy near zero.
"""
from __future__ import annotations

from .lazy import jax, jnp  # imported on first use (`_kernels.lazy`)

from . import kernel

QSIZE = 10


def pack(A, b, c):
    """(…,3,3), (…,3), (…) -> (…,10)."""
    return jnp.concatenate(
        [A[..., 0, 0:3], A[..., 1, 1:3], A[..., 2, 2:3], b, c[..., None]], axis=-1
    )


def unpack(q):
    """(…,10) -> A (…,3,3) symmetric, b (…,3), c (…)."""
    a00, a01, a02, a11, a12, a22 = (q[..., k] for k in range(6))
    A = jnp.stack(
        [jnp.stack([a00, a01, a02], -1), jnp.stack([a01, a11, a12], -1), jnp.stack([a02, a12, a22], -1)],
        -2,
    )
    return A, q[..., 6:9], q[..., 9]


def plane_quadric(n, w):
    """Quadric w·(n·u)² of a plane through the frame origin; n (…,3) unit normal, w (…) weight."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    zero = jnp.zeros_like(x)
    return w[..., None] * jnp.stack([x * x, x * y, x * z, y * y, y * z, z * z, zero, zero, zero, zero], -1)


def dot(u, v):
    """u·v for 3-vectors given as lists of component arrays."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def matvec_c(q, u):
    """A·u on component lists: q (10 arrays), u (3 arrays). Written out elementwise: XLA fuses it into
    one loop (a batched 3×3 dot or column slices of (…,10) arrays are several times slower on the CPU)."""
    a00, a01, a02, a11, a12, a22 = q[:6]
    return [a00 * u[0] + a01 * u[1] + a02 * u[2],
            a01 * u[0] + a11 * u[1] + a12 * u[2],
            a02 * u[0] + a12 * u[1] + a22 * u[2]]


def evaluate_c(q, u):
    """Q(u) on component lists."""
    Au = matvec_c(q, u)
    return dot(u, [Au[i] + 2.0 * q[6 + i] for i in range(3)]) + q[9]


def translate_c(q, d):
    """`translate` on component lists."""
    Ad = matvec_c(q, d)
    b = q[6:9]
    c = q[9] + dot(d, [Ad[i] + 2.0 * b[i] for i in range(3)])
    return q[:6] + [b[i] + Ad[i] for i in range(3)] + [c]


def cols(a, k):
    """The k components of (…,k) as a list of (…) arrays."""
    return [a[..., i] for i in range(k)]


def matvec(q, u):
    """A·u (…,3) for packed q (…,10)."""
    return jnp.stack(matvec_c(cols(q, 10), cols(u, 3)), -1)


def evaluate(q, u):
    """Q(u) for q (…,10) and u (…,3) given in q's frame. Returns (…)."""
    return evaluate_c(cols(q, 10), cols(u, 3))


def translate(q, delta):
    """Re-express q in a frame whose origin is shifted by ``delta`` (new origin = old origin + delta).

    With u = u' + delta: A' = A, b' = b + A·delta, c' = Q(delta).
    """
    return jnp.stack(translate_c(cols(q, 10), cols(delta, 3)), -1)


def face_normals(p0, p1, p2):
    """Unit normals (…,3), areas (…) of triangles; degenerate triangles get a zero normal."""
    cr = jnp.cross(p1 - p0, p2 - p0)
    nrm = jnp.linalg.norm(cr, axis=-1)
    safe = jnp.where(nrm > 0, nrm, 1.0)
    return cr / safe[..., None] * (nrm > 0)[..., None], 0.5 * nrm


def _power(r, p):
    """r^p for r ≥ 0, exactly r at p = 1 and exactly 1 at p = 0 (a general power rounds differently)."""
    return jnp.where(p == 1, r, jnp.where(p == 0, 1.0, jnp.power(jnp.maximum(r, jnp.finfo(r.dtype).tiny), p)))


@kernel
def vertex_quadrics(V, F, fmask, area_power, cedges, cnormals, cweight, cmask, mean_area, mean_e2):
    """Per-vertex quadrics, each in its own vertex's frame.

    V (N,3) float positions; F (M,3) int faces, ``fmask`` (M,) bool marks real faces (the rest is padding).
    ``area_power`` () float: weight each face plane by (area / mean area)^area_power (dimensionless):
    1 = area-weighted, 0 = unit weights (the paper's), 0.5 between.
    Constraint edges (boundary or feature) ``cedges`` (B,2) int with the normal ``cnormals`` (B,3) of a
    face containing them and a weight ``cweight`` (B,) (the boundary penalty; already relative), masked by
    ``cmask``: each adds the plane through the edge perpendicular to that face, weighted by
    cweight·(|e|²/mean|e|²)^area_power, to both endpoints.
    ``mean_area``, ``mean_e2`` (): the mean area and mean squared edge length of the real faces, computed
    by the caller (`qemjax._mesh.arrays.face_stats`): an XLA:CPU reduction's order depends on the number of threads, and these
    two scale every weight.
    Returns (N,10) packed quadrics. Errors are squared distances in the units of V.
    """
    dt = V.dtype
    p = V[F]
    n, area = face_normals(p[:, 0], p[:, 1], p[:, 2])
    fm = fmask.astype(dt)
    w = _power(area / jnp.maximum(mean_area, jnp.finfo(dt).tiny), area_power) * fm
    # a plane through the vertex has b = c = 0: scatter the six entries of A, one corner at a time
    # (faster than a segment sum of all ten over repeated rows; docs/benchmarks.md, "Measured choices inside a run")
    qf = plane_quadric(n, w)[:, :6]
    nv = V.shape[0]
    A = jnp.zeros((nv, 6), dt)
    for j in range(3):
        A = A.at[F[:, j]].add(qf)
    Q = jnp.concatenate([A, jnp.zeros((nv, 4), dt)], 1)

    e = V[cedges[:, 1]] - V[cedges[:, 0]]
    elen2 = jnp.sum(e * e, -1)
    m = jnp.cross(e, cnormals)
    mn = jnp.linalg.norm(m, axis=-1)
    m = m / jnp.where(mn > 0, mn, 1.0)[:, None]
    # relative to the mean squared edge length of the real faces: a dimensionless boundary weight
    scale = _power(elen2 / jnp.maximum(mean_e2, jnp.finfo(dt).tiny), area_power)
    cw = cweight * scale * cmask.astype(dt) * (mn > 0)
    qc = plane_quadric(m, cw)
    Q = Q + jax.ops.segment_sum(jnp.concatenate([qc, qc]), jnp.concatenate([cedges[:, 0], cedges[:, 1]]),
                                num_segments=nv)
    return Q
