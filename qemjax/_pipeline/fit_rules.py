"""What the re-fit, its polish and the sliver moves share (`refit`, `polish`, `slivers`): the closest point
of a triangle as barycentric coordinates, and the rules a move of the output's vertices must keep (a face's
turn, its shape, what counts as a sliver)."""
from __future__ import annotations

import numpy as np

from .._mesh.compiled import njit
from .._mesh.grid_nearest import slivers
from .._mesh.pointtri import segment_closest
from .refit_system import regions

SLIVER_DEG = 10.0  # a face whose smallest angle is below this (degrees) is a sliver
COS_SLIVER = float(np.cos(np.radians(SLIVER_DEG)))


def closest_barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(q,3) barycentric coordinates of the point of triangle (a, b, c) nearest to p, row by row (Ericson,
    Real-Time Collision Detection 5.1.5: vertex, edge or interior region)."""
    q = len(p)
    X = np.concatenate([a, b, c]).astype(np.float64, copy=False)
    G = np.arange(3 * q).reshape(3, q).T
    return _barycentric_at(np.asarray(p, np.float64), X, G, np.arange(q), slivers(X, G))


def _barycentric_at(P, X, G, f, flat):
    """`closest_barycentric` of points P on faces f of (X, G): Ericson's regions (`refit_system.regions`),
    except on slivers (``flat``, per face of G: two corners at one point, three in a line, as
    `_mesh.pointtri` tells them), whose regions lose all precision: there the closest point of the three
    edges."""
    out = np.empty((len(f), 3))
    regions(P, X, G, f, out)
    sliver = np.flatnonzero(flat[f])
    if sliver.size:
        tri = G[f[sliver]]
        out[sliver] = _closest_on_edges(P[sliver], X[tri[:, 0]], X[tri[:, 1]], X[tri[:, 2]])
    return out


def _closest_on_edges(p, a, b, c):
    """(q,3) barycentric coordinates of the closest point of the three edges of triangles (a, b, c) to p."""
    best = np.full(len(p), np.inf)
    out = np.zeros((len(p), 3))
    corners = (a, b, c)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        t, d = segment_closest(p.T, corners[i].T, (corners[j] - corners[i]).T)
        closer = d < best
        best[closer] = d[closer]
        out[closer] = 0.0
        out[closer, i], out[closer, j] = 1 - t[closer], t[closer]
    return out


def shape(A: np.ndarray, B: np.ndarray, C: np.ndarray, n: np.ndarray) -> np.ndarray:
    """2·area / longest edge² of triangles with corners A, B, C (k,3) and normals n (k,3), |n| / longest²:
    the shape the contractions' quality guard bounds (`Topology.min_angle`), at most the sine of the
    smallest angle; 0 for a triangle whose corners are one point."""
    longest = np.max(np.stack([((c1 - c0) ** 2).sum(1) for c0, c1 in ((A, B), (B, C), (C, A))]), axis=0)
    return np.linalg.norm(n, axis=1) / np.where(longest > 0, longest, 1.0)


def _quality(P: np.ndarray, G: np.ndarray, n: np.ndarray) -> np.ndarray:
    """`shape` of each face (corners G at positions P, normals n)."""
    c = P[G]
    return shape(c[:, 0], c[:, 1], c[:, 2], n)


def _turned(n0: np.ndarray, n1: np.ndarray, cos_max: float) -> np.ndarray:
    """Faces whose normal turned by the flip angle or more (cos ≤ cos_max), or that lost all area."""
    l0, l1 = np.linalg.norm(n0, axis=1), np.linalg.norm(n1, axis=1)
    cos = np.einsum("ij,ij->i", n0, n1) / np.where(l0 * l1 > 0, l0 * l1, 1.0)
    return ((l1 == 0) & (l0 > 0)) | ((l0 > 0) & (cos <= cos_max))


@njit(cache=True, nogil=True)
def _min_cos(X, G, faces):
    """The largest cosine of each face's three angles (its smallest angle's); 2 for a face with a corner
    at another."""
    out = np.empty(len(faces))
    for t in range(len(faces)):
        g = faces[t]
        best = -2.0
        for k in range(3):
            a, b, c = G[g, k], G[g, (k + 1) % 3], G[g, (k + 2) % 3]
            ux, uy, uz = X[b, 0] - X[a, 0], X[b, 1] - X[a, 1], X[b, 2] - X[a, 2]
            vx, vy, vz = X[c, 0] - X[a, 0], X[c, 1] - X[a, 1], X[c, 2] - X[a, 2]
            nu = np.sqrt((ux * ux + uy * uy) + uz * uz)
            nv = np.sqrt((vx * vx + vy * vy) + vz * vz)
            if nu == 0.0 or nv == 0.0:
                best = 2.0
                break
            cs = ((ux * vx + uy * vy) + uz * vz) / (nu * nv)
            if cs > best:
                best = cs
        out[t] = best
    return out
