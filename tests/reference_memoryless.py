"""The numpy form of the memoryless quadrics' rebuild (`qemjax._costs.memoryless.current_quadrics`, compiled in
`qemjax._costs.current_sums`), kept as the reference the compiled one must equal bit for bit."""
from __future__ import annotations

import numpy as np

from qemjax._mesh import fixed_order
from qemjax._mesh.incidence import FaceLists  # noqa: F401 (the annotations)


def _power(r: np.ndarray, p: float) -> np.ndarray:
    """r^p for r ≥ 0, exactly r at p = 1 and 1 at p = 0 (as `quadrics._power`)."""
    if p == 1:
        return r
    if p == 0:
        return np.ones_like(r)
    return fixed_order.power(np.maximum(r, np.finfo(np.float64).tiny), p)  # not np.power: its bits vary by CPU


def _planes(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(k,6) upper triangle of w·n nᵀ for unit normals n (k,3), weights w (k,)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    return w[:, None] * np.stack([x * x, x * y, x * z, y * y, y * z, z * z], 1)


def current_quadrics_numpy(P: np.ndarray, faces: FaceLists, verts: np.ndarray, *, area_power: float,
                     boundary_weight: float, mean_area: float, mean_e2: float) -> np.ndarray:
    """(k,13) float64: the quadrics (10) of ``verts`` (k,), each in its vertex's frame (so b = c = 0), from
    the live faces around it (positions P (n,3)): the plane of each face weighted by
    (area / mean_area)^area_power, and for each boundary edge at the vertex (an edge in one live face only)
    the plane through it perpendicular to that face, weighted by boundary_weight·(|e|² / mean_e2)^area_power
    (none when boundary_weight is 0); then g(v) (3): the sum of ½(c1 − v)×(c2 − v) over those faces."""
    verts = np.asarray(verts, np.int64)
    k = len(verts)
    A = np.zeros((k, 6))
    g = np.zeros((k, 3))
    w, f = faces.around(verts)
    if len(f):
        G = np.take(faces.F, f, axis=0).astype(np.int64)
        me = np.take(verts, w)
        corner = np.where(G[:, 0] == me, 0, np.where(G[:, 1] == me, 1, 2))
        rows = np.arange(len(G))
        rot = np.stack([G[rows, corner], G[rows, (corner + 1) % 3], G[rows, (corner + 2) % 3]], 1)
        P = np.asarray(P, np.float64)
        p0, p1, p2 = P[rot[:, 0]], P[rot[:, 1]], P[rot[:, 2]]
        cr = np.cross(p1 - p0, p2 - p0)
        nrm = np.linalg.norm(cr, axis=1)
        n = cr / np.where(nrm > 0, nrm, 1.0)[:, None]
        wf = _power(0.5 * nrm / max(mean_area, np.finfo(np.float64).tiny), area_power)
        contrib = [(w, _planes(n, wf))]
        for i in range(3):
            g[:, i] = np.bincount(w, weights=0.5 * cr[:, i], minlength=k)
        if boundary_weight > 0:
            # the edge (v, c) is a boundary edge when c is the other end of one live face edge at v only
            m = len(P) + 1
            key = np.concatenate([w * m + rot[:, 1], w * m + rot[:, 2]])
            _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
            once = (cnt[inv] == 1).reshape(2, -1)
            for j, c in ((0, rot[:, 1]), (1, rot[:, 2])):
                s = np.flatnonzero(once[j])
                e = P[c[s]] - p0[s]
                mm = np.cross(e, n[s])
                mn = np.linalg.norm(mm, axis=1)
                mm = mm / np.where(mn > 0, mn, 1.0)[:, None]
                wb = boundary_weight * _power(np.sum(e * e, 1) / max(mean_e2, np.finfo(np.float64).tiny),
                                              area_power) * (mn > 0)
                contrib.append((w[s], _planes(mm, wb)))
        for owner, q in contrib:
            for i in range(6):
                A[:, i] += np.bincount(owner, weights=q[:, i], minlength=k)
    return np.concatenate([A, np.zeros((k, 4)), g], 1)
