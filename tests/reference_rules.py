"""Numpy twins of the validity rules (`qemjax._schedulers.rules`), kept only as references the tests compare
the compiled rules and the device kernel with: written independently of them (numpy blocks, Python sets),
with the float32 operations of the device kernel (`qemjax._kernels.flips`) in its order."""
from __future__ import annotations

import numpy as np

from qemjax._kernels import flips
from qemjax._mesh.incidence import FaceLists


def flips_host(V: np.ndarray, N0: np.ndarray, faces: np.ndarray, fids: np.ndarray, k: np.ndarray,
               x: np.ndarray, cos_max, min_quality=0.0) -> bool:
    """`flips.face_flips_at` on the host, in numpy, for the few faces of one contraction: does moving
    corner k (K,) of faces (K,3) (rows of V (N,≥3)) to x (3,) flip any of them against its own normal or
    its reference N0[fids]? The kernel's float32 operations (`flips._flips`), each rounded alike, on (K,3)
    blocks rather than component lists."""
    return bool(flips_host_faces(V, N0, faces, fids, k, x, cos_max, min_quality).any())


def flips_host_faces(V: np.ndarray, N0: np.ndarray, faces: np.ndarray, fids: np.ndarray, k: np.ndarray,
                     x: np.ndarray, cos_max, min_quality=0.0) -> np.ndarray:
    """`flips_host` per face: (K,) bool. x: (3,), or (K,3) where each face's corner goes (the faces of
    several contractions tested in one pass). ``min_quality``: the quality guard (0: off)."""
    g = V[faces, :3].astype(np.float32)  # (K,3,3)
    cos_max = np.float32(cos_max)
    q = g.copy()
    q[np.arange(len(g)), k] = np.asarray(x, np.float32)
    # rows: the two edges from corner 0 before and after, then the edges after the move, each (K,3)
    u = np.stack([g[:, 1] - g[:, 0], q[:, 1] - q[:, 0]])
    v = np.stack([g[:, 2] - g[:, 0], q[:, 2] - q[:, 0]])
    n0, n1 = _cross3(u, v)
    e0, e1, e2 = u[1], q[:, 2] - q[:, 1], q[:, 0] - q[:, 2]
    ref = N0[fids].astype(np.float32)
    # the eight dot products at once, each summed x + y, then + z, as `quadrics.dot`
    m = np.stack([n1, n0, n0, e0, e1, e2, ref, ref]) * np.stack([n1, n1, n0, e0, e1, e2, n1, ref])
    d11, d01, d00, de0, de1, de2, dr1, drr = m[..., 0] + m[..., 1] + m[..., 2]
    l1 = np.sqrt(d11)
    bad = d01 <= cos_max * np.sqrt(d00) * l1
    longest2 = np.maximum(np.maximum(de0, de1), de2)
    bad |= (l1 <= flips.SLIVER * longest2) & (cos_max > -1.0)
    bad |= dr1 <= cos_max * np.sqrt(drr) * l1
    # the quality guard: the edges before the move, their squared lengths summed as `quadrics.dot`
    o = np.stack([g[:, 1] - g[:, 0], g[:, 2] - g[:, 1], g[:, 0] - g[:, 2]])
    o = o * o
    do0, do1, do2 = o[..., 0] + o[..., 1] + o[..., 2]
    before2 = np.maximum(np.maximum(do0, do1), do2)
    worse = l1 * before2 < np.sqrt(d00) * longest2
    bad |= (l1 < np.float32(min_quality) * longest2) & worse
    return bad


def _cross3(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """`_cross` of (…,3) rows: each component u_i v_j - u_j v_i in the same order."""
    uu, vv = np.concatenate([u, u], -1), np.concatenate([v, v], -1)  # [x y z x y z]: rotations as views
    return uu[..., 1:4] * vv[..., 2:5] - uu[..., 2:5] * vv[..., 1:4]


def flips_host_reference(V, N0, faces, fids, k, x, cos_max) -> bool:
    """`flips_host` through `_flips` itself, on component lists (what tests compare it with)."""
    g = V[faces, :3].astype(np.float32)  # (K,3,3)
    p = [[g[:, j, i] for i in range(3)] for j in range(3)]
    ref = N0[fids].astype(np.float32)
    x = np.asarray(x, np.float32)
    return bool(np.any(flips._flips(p, k, [x[i] for i in range(3)], np.float32(cos_max),
                              [ref[:, i] for i in range(3)], np)))


def link_ok_sets(faces: FaceLists, a: int, b: int, nshared: int) -> bool:
    """The link condition (`topology.link_ok`) for the one pair (a, b) with ``nshared`` faces, on Python sets of its neighbourhood
    (a scalar check costs a few microseconds where the vectorised one costs hundreds): a manifold edge
    whose endpoints' common neighbours are exactly the apexes of its faces, that does not pinch two
    boundaries together through an interior edge, and no apex of an interior edge of degree 3."""
    if not 1 <= nshared <= 2:
        return False
    w, f = faces.around(np.array([a, b]))
    G = np.take(faces.F, f, axis=0)
    ring_a, ring_b = G[w == 0], G[w == 1]
    common = (set(ring_a.ravel().tolist()) & set(ring_b.ravel().tolist())) - {a, b}
    if len(common) != nshared:
        return False
    if nshared == 2:
        if _on_boundary(ring_a, a) and _on_boundary(ring_b, b):
            return False
        for c in common:
            if len(set(np.take(faces.F, faces.around(np.array([c]))[1], axis=0).ravel().tolist())) - 1 <= 3:
                return False
    return True


def _on_boundary(ring: np.ndarray, v: int) -> bool:
    """Whether v has an edge with one face, from its faces ``ring`` (k,3): a neighbour seen in one face."""
    others = ring.ravel()
    return bool(np.any(np.unique(others[others != v], return_counts=True)[1] == 1))
