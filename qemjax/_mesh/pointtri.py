"""Exact Euclidean distance from points to triangles (Ericson, Real-Time Collision Detection, 5.1.5).

The region test picks which feature of the triangle (a vertex, an edge or the interior) is closest and gives
the barycentric coordinates of the closest point; the distance is the length of the residual vector from it.
"""

from __future__ import annotations

import math

import numpy as np

# A triangle whose twice-area is below this fraction of its longest edge squared (width below ~1e-8 of its
# length) is measured as the polyline of its three edges: there the barycentric solve loses more (~eps * L /
# width) than treating the sliver as its edges does (at most its width).
_FLAT_REL = 1e-8
_BLOCK = 32_768  # pairs per kernel call


def point_triangle_distance(points, a, b, c, *, squared: bool = False) -> np.ndarray:
    """Exact distance from points to (filled) triangles, computed in float64.

    Args:
      points: (..., 3) points.
      a, b, c: (..., 3) triangle corners; all four arrays broadcast against each other, so one triangle can be
        measured against many points or each point against its own triangle.
      squared: return squared distances instead.

    Returns:
      (...,) float64 distances (same length units as the inputs; squared units when ``squared``), with ``...``
      the broadcast shape. Degenerate triangles (collinear or repeated corners, or thinner than 1e-8 of their
      length) are measured as the union of their three edges.

    Raises:
      ValueError: when a last axis is not 3, the shapes do not broadcast, or a value is not finite.
    """
    arrays = [np.asarray(x, dtype=np.float64) for x in (points, a, b, c)]
    for name, x in zip(("points", "a", "b", "c"), arrays):
        if x.ndim == 0 or x.shape[-1] != 3:
            raise ValueError(f"point_triangle_distance: {name} must have shape (..., 3), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError(f"point_triangle_distance: {name} contains NaN or infinite values")
    # measured where the largest coordinate is about 1, as the metrics measure (`metrics._common.in_frame`): a
    # power of two scales exactly, where squared lengths of 1e160 overflowed (NaN) and of 1e-160 underflowed
    top = max(float(np.abs(x).max(initial=0.0)) for x in arrays)
    k = math.frexp(top)[1] if top > 0 else 0
    if k:
        arrays = [np.ldexp(x, -k) for x in arrays]
    try:
        arrays = np.broadcast_arrays(*arrays)
    except ValueError as err:
        raise ValueError(f"point_triangle_distance: shapes do not broadcast: {err}") from None
    shape = arrays[0].shape[:-1]
    p, a_, b_, c_ = (np.ascontiguousarray(x.reshape(-1, 3).T) for x in arrays)
    ab, ac = b_ - a_, c_ - a_
    d2 = np.empty(p.shape[1])
    for s in range(0, len(d2), _BLOCK):  # blocks keep the temporaries in cache
        blk = slice(s, s + _BLOCK)
        d2[blk] = squared_distance_cf(p[:, blk], a_[:, blk], ab[:, blk], ac[:, blk])
    out = d2 if squared else np.sqrt(d2)
    if k:  # back in the inputs' units: inf or 0 where float64 cannot hold the value
        with np.errstate(over="ignore", under="ignore"):
            out = np.ldexp(out, 2 * k if squared else k)
    return out.reshape(shape)


def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


def flat_triangles(ab: np.ndarray, ac: np.ndarray) -> np.ndarray:
    """(n,) bool: triangles (edge vectors ab, ac as (3, n)) too thin to have a reliable normal."""
    n = np.cross(ab, ac, axis=0)
    bc = ac - ab
    longest = np.maximum(np.maximum(_dot(ab, ab), _dot(ac, ac)), _dot(bc, bc))
    return _dot(n, n) <= (_FLAT_REL * longest) ** 2


def segment_closest(p, o, e):
    """(t, squared distance) of the point o + t e of the segment, t in [0, 1], closest to p; arrays are (3, n)."""
    ee = _dot(e, e)
    po = p - o
    t = np.clip(np.divide(_dot(po, e), ee, out=np.zeros_like(ee), where=ee > 0), 0.0, 1.0)
    r = po - t * e
    return t, _dot(r, r)


def _segment_sq(p, o, e):
    """Squared distance from p to the segment o + t e, t in [0, 1]; arrays are (3, n)."""
    return segment_closest(p, o, e)[1]


def edge_products(ab: np.ndarray, ac: np.ndarray) -> np.ndarray:
    """(3, n) float64: ab.ab, ac.ac and ab.ac of edge vectors ab, ac (3, n), as `squared_distance_cf` uses them."""
    return np.stack([_dot(ab, ab), _dot(ac, ac), _dot(ab, ac)])


def squared_distance_cf(p, a, ab, ac, flat=None, products=None) -> np.ndarray:
    """Squared point-triangle distances, the internal workhorse of `point_triangle_distance`.

    Args are component-first float64 arrays: p, a (3, n) points and first corners, ab = b - a, ac = c - a
    (3, n) edge vectors; flat (n,) bool from `flat_triangles` (computed when None); products (3, n) from
    `edge_products` (computed when None; the same values either way). Returns (n,) float64.
    No checks, no broadcasting; fastest on blocks of ~10^4-10^5 pairs (cache-resident temporaries).
    """
    ap = p - a
    d1 = _dot(ab, ap)
    d2 = _dot(ac, ap)
    ab2, ac2, abac = edge_products(ab, ac) if products is None else products
    # Ericson's d3..d6 = ab.(p - b), ac.(p - b), ab.(p - c), ac.(p - c), from d1, d2 and the edge products.
    d3 = d1 - ab2
    d4 = d2 - abac
    d5 = d1 - abac
    d6 = d2 - ac2
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    bc_p = d4 - d3  # (c - b).(p - b)
    cb_p = d5 - d6  # (b - c).(p - c)
    with np.errstate(divide="ignore", invalid="ignore"):  # only flat triangles divide by zero; fixed below
        # Barycentrics (v, w) of the closest point a + v ab + w ac: the interior answer, then each Voronoi
        # region overrides it in reverse order of Ericson's tests, so the first region that holds wins.
        den = va + vb + vc
        v = vb / den
        w = vc / den
        m = (va <= 0) & (bc_p >= 0) & (cb_p >= 0)  # edge BC
        t = bc_p / (bc_p + cb_p)
        v = np.where(m, 1.0 - t, v)
        w = np.where(m, t, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)  # edge AC
        v = np.where(m, 0.0, v)
        w = np.where(m, d2 / ac2, w)
        m = (d6 >= 0) & (d5 <= d6)  # vertex C
        v = np.where(m, 0.0, v)
        w = np.where(m, 1.0, w)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)  # edge AB
        v = np.where(m, d1 / ab2, v)
        w = np.where(m, 0.0, w)
        m = (d3 >= 0) & (d4 <= d3)  # vertex B
        v = np.where(m, 1.0, v)
        w = np.where(m, 0.0, w)
        m = (d1 <= 0) & (d2 <= 0)  # vertex A
        v = np.where(m, 0.0, v)
        w = np.where(m, 0.0, w)
    # The residual vector, not |ap|^2 - |projection|^2: no cancellation for points close to the triangle.
    r = ap - v * ab - w * ac
    out = _dot(r, r)

    if flat is None:
        flat = flat_triangles(ab, ac)
    if flat.any():
        pf, af, abf, acf = p[:, flat], a[:, flat], ab[:, flat], ac[:, flat]
        out[flat] = np.minimum(
            np.minimum(_segment_sq(pf, af, abf), _segment_sq(pf, af, acf)), _segment_sq(pf, af + abf, acf - abf)
        )
    return out
