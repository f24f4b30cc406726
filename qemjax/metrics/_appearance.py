"""Appearance metrics: texture-space (UV) and colour deviation, and seam (chart) integrity.

Meshes here carry per-corner attributes: a qemjax result (``uv`` / ``colors`` with ``wedge_faces``), a
`trimesh.Trimesh` whose visual holds UVs or vertex colours (its vertices split at seams, as trimesh loads
OBJ and glTF files), or a file path, read as `qemjax.simplify` reads it (``_io._read_trimesh`` and
``_wedges.from_trimesh``). `qemjax.load` meshes and ``(vertices, faces)`` arrays carry positions only.
"""
from __future__ import annotations

import numpy as np

from ._common import as_mesh, scaled
from ._distance import _check_samples
from .._mesh.arrays import whole_numbers
from .._mesh.nearest import nearest_triangles
from ._topology import _components

KINDS = ("uv", "color")


def corner_values(mesh, kind: str):
    """(vertices (n,3), faces (m,3), values (m,3,k)) of ``kind`` ('uv' or 'color', RGBA in [0, 1]) per face
    corner, or None when the mesh does not carry it."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    wf = getattr(mesh, "wedge_faces", None)
    if wf is not None:  # a qemjax result
        vals = mesh.uv if kind == "uv" else mesh.colors
        if vals is None:
            return None
        return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces), np.asarray(vals, np.float64)[wf]
    tm = _as_trimesh(mesh)
    if tm is None:
        return None
    from .._mesh.wedges import from_trimesh

    vals = from_trimesh(tm)[0].get(kind)  # as simplify reads them
    if vals is None:
        return None
    F = np.asarray(tm.faces, np.int64)
    return np.asarray(tm.vertices, np.float64), F, vals[F]


def _as_trimesh(mesh):
    """The `trimesh.Trimesh` of a path (read as `simplify` reads it) or of a trimesh mesh or scene; None
    for anything else (arrays, a `qemjax.Mesh`: positions only)."""
    import os

    from .._io import mesh as _io

    if isinstance(mesh, (str, os.PathLike)):
        return _io._read_trimesh(mesh)
    if type(mesh).__module__.startswith("trimesh"):
        return _io._as_trimesh(mesh)
    return None


def _missing(mesh, name: str, kind: str) -> str:
    import os

    if isinstance(mesh, (str, os.PathLike)) or hasattr(mesh, "visual") or hasattr(mesh, "wedge_faces"):
        return f"{name} carries no {kind}"
    return (f"{name} ({type(mesh).__name__}) carries no {kind}: qemjax.load meshes and (vertices, faces) "
            "arrays hold positions only; pass the file's path or a trimesh.Trimesh")


def closest_barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(q,3) barycentric coordinates of the point of each triangle (a, b, c: (q,3)) closest to p (q,3): the
    re-fit's (`qemjax._pipeline.fit_rules.closest_barycentric`; segments and slivers included)."""
    from .._pipeline.fit_rules import closest_barycentric as exact  # numba and scipy: imported when first used

    return exact(np.asarray(p, np.float64), np.asarray(a, np.float64), np.asarray(b, np.float64),
                 np.asarray(c, np.float64))


def _seam_tolerant(Vo, Fo, Co, pts, dist, fo, val_s, d, tol, cs, face):
    """For samples with a deviation above ``tol``: the smallest deviation over the input faces that share a
    (welded) vertex with the nearest one and lie within twice its distance, or, for those across a seam from
    it (sharing none of its wedges, a wedge being a welded vertex with one value), within twice its distance
    plus a tenth of the longest edge of the sample's own face (``face``, of the output's corners ``cs``);
    both +1e-9 of the extent. Near a seam the nearest input point may sit in the chart across it, whose UVs
    are elsewhere in the texture; a point about as near on the sample's own side is the fair comparison.
    Twice the distance alone fails where the output lies within a hair of the input (a re-fitted one): the
    output's seam is a chord of the input's and passes beside it by a part of the output's edge, however
    near the surfaces are; on the nearest face's side the window stays relative, so a real deviation is not
    read away. Returns the new deviations."""
    bad = np.flatnonzero(d > tol)
    if bad.size == 0:
        return d
    _, wid = np.unique(Vo, axis=0, return_inverse=True)
    wid = wid.reshape(-1)
    Fw = wid[Fo]
    order = np.argsort(Fw.reshape(-1), kind="stable")
    vf = order // 3  # faces by welded vertex
    starts = np.searchsorted(Fw.reshape(-1)[order], np.arange(wid.max() + 2))
    corner = np.c_[Fw.reshape(-1, 1).astype(np.float64), Co.reshape(len(Fo) * 3, -1)]
    wedge = np.unique(corner, axis=0, return_inverse=True)[1].reshape(-1, 3)  # each corner's wedge
    ext = float(np.max(np.ptp(Vo, axis=0)))
    out = d.copy()
    for i in bad:
        cand = np.unique(np.concatenate([vf[starts[v]:starts[v + 1]] for v in Fw[fo[i]]]))
        c = Vo[Fo[cand]]
        p = np.repeat(pts[i][None], len(cand), 0)
        wb = closest_barycentric(p, c[:, 0], c[:, 1], c[:, 2])
        q = np.einsum("qk,qkj->qj", wb, c)
        dd = np.linalg.norm(q - p, axis=1)
        near = 2 * dist[i] + 1e-9 * ext
        across = ~np.isin(wedge[cand], wedge[fo[i]]).any(axis=1)
        own = cs[face[i]]
        size = np.linalg.norm(own - np.roll(own, 1, axis=0), axis=1).max()
        ok = (dd <= near) | (across & (dd <= near + 0.1 * size))
        if ok.any():
            vals = np.einsum("qk,qkj->qj", wb[ok], Co[cand[ok]])
            out[i] = min(d[i], float(np.min(np.linalg.norm(vals - val_s[i], axis=1))))
    return out


def attribute_deviation(original, simplified, *, kind: str = "uv", n_samples: int = 20_000,
                        seed: int = 0, seam_tolerant: bool = True) -> dict:
    """Texture-space (or colour) deviation of a simplification: sample points uniformly (by area) on the
    simplified surface, interpolate its ``kind`` there, and compare with the original's value
    interpolated at the nearest point of the original surface. Returns ``{kind}_dev_rms``, ``_mean``,
    ``_p95`` and ``_max`` (UV units, where the texture is the unit square; colours: Euclidean RGBA
    distance with channels in [0, 1]). ``seam_tolerant``: a sample whose nearest input point lies across
    a seam is compared with the nearest point on its own side when that is within twice the distance plus
    a tenth of the sample's face (`_seam_tolerant`; without it a sample a hair across a UV seam reads a
    deviation of up to the texture's width). Each mesh is what `qemjax.simplify` accepts and keeps
    attributes of: a path (read as simplify reads it), a `trimesh.Trimesh`, or a result (`SimplifyResult`).
    ``n_samples``: the points sampled on the simplified surface; ``seed``: their seed (equal inputs and seed
    give equal numbers). ValueError when either lacks ``kind``."""
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples must be a positive integer (points sampled on the simplified surface), "
                         f"got {n_samples!r}")
    o, s = corner_values(original, kind), corner_values(simplified, kind)
    for mesh, vals, name in ((original, o, "original"), (simplified, s, "simplified")):
        if vals is None:
            raise ValueError(f"both meshes must carry {kind}: the {_missing(mesh, name, kind)}")
    Vs, Fs, Cs = s
    Vo, Fo, Co = o
    # both in the original's frame (`_common.in_frame`): areas and squared distances in float64's range at any
    # scale; the deviations are in the attributes' units, whatever the frame
    _, (Vs, Vo) = scaled(np.asarray(Vo, np.float64), np.asarray(Vs, np.float64), np.asarray(Vo, np.float64))
    rng = np.random.default_rng(_check_samples(seed, "seed"))
    cs = Vs[Fs]  # (m,3,3)
    area = np.linalg.norm(np.cross(cs[:, 1] - cs[:, 0], cs[:, 2] - cs[:, 0]), axis=1)
    cum = np.cumsum(area)
    face = np.minimum(np.searchsorted(cum, rng.random(n_samples) * cum[-1], side="right"), len(cum) - 1)
    u, v = rng.random((2, n_samples))
    fold = u + v > 1
    u[fold], v[fold] = 1 - u[fold], 1 - v[fold]
    w = np.stack([1 - u - v, u, v], 1)
    pts = np.einsum("qk,qkj->qj", w, cs[face])
    val_s = np.einsum("qk,qkj->qj", w, Cs[face])
    mo = as_mesh((Vo, Fo), "original")
    dist, fo = nearest_triangles(mo.corners, pts)
    co = Vo[Fo[fo]]
    wo = closest_barycentric(pts, co[:, 0], co[:, 1], co[:, 2])
    val_o = np.einsum("qk,qkj->qj", wo, Co[fo])
    d = np.linalg.norm(val_s - val_o, axis=1)
    if seam_tolerant:
        d = _seam_tolerant(Vo, Fo, Co, pts, dist, fo, val_s, d, 0.05 if kind == "uv" else 0.1, cs, face)
    return {f"{kind}_dev_rms": float(np.sqrt(np.mean(d * d))), f"{kind}_dev_mean": float(d.mean()),
            f"{kind}_dev_p95": float(np.quantile(d, 0.95)), f"{kind}_dev_max": float(d.max())}


def charts(faces: np.ndarray, wedge_faces: np.ndarray) -> np.ndarray:
    """(m,) int64 chart id of each face: faces are in one chart when they share an edge whose two
    endpoints have the same wedges in both (so a UV seam or colour discontinuity separates charts).
    ``faces`` and ``wedge_faces``: (m, 3) integer arrays, corner for corner (a result's ``faces`` and
    ``wedge_faces``)."""
    F, W = _index_array("faces", faces), _index_array("wedge_faces", wedge_faces)
    # else a 4th column would be read past, and shapes that differ would give numpy's broadcast error
    if F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"faces must have shape (m, 3) (triangles: a result's faces), got {F.shape}")
    if W.shape != F.shape:
        raise ValueError(f"wedge_faces must have the shape of faces {F.shape} (a wedge per face corner), "
                         f"got {W.shape}")
    m = len(F)
    k0, k1 = [0, 1, 2], [1, 2, 0]
    u, v = F[:, k0].reshape(-1), F[:, k1].reshape(-1)
    wu, wv = W[:, k0].reshape(-1), W[:, k1].reshape(-1)
    swap = u > v
    lo, hi = np.where(swap, v, u), np.where(swap, u, v)
    wlo, whi = np.where(swap, wv, wu), np.where(swap, wu, wv)
    key = np.stack([lo, hi, wlo, whi], 1)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    fid = np.repeat(np.arange(m), 3)
    order = np.argsort(inv, kind="stable")
    same = inv[order][1:] == inv[order][:-1]
    i, j = fid[order][1:][same], fid[order][:-1][same]
    return _components(m, i, j)[1].astype(np.int64)


def _index_array(name: str, x) -> np.ndarray:
    """x as int64; ValueError naming ``name`` for what does not hold whole numbers."""
    try:
        a = np.asarray(x)
    except (ValueError, TypeError):
        raise ValueError(f"{name} must be a rectangular array of vertex indices, got a ragged list") from None
    if not whole_numbers(a):
        raise ValueError(f"{name} must hold integer indices, got dtype {a.dtype}")
    return a.astype(np.int64, copy=False)


def seam_report(result, input_wedge_faces: np.ndarray | None = None) -> dict:
    """Whether a qemjax result kept its UV / colour charts: each output face continues an input face
    (``source_faces``); an output chart whose faces come from two or more input charts has a face that
    spans a seam. Returns charts_in, charts_out, mixed_charts (output charts spanning input charts:
    0 means the seams held) and seam_faces_out (faces in those charts). ``input_wedge_faces``: the cleaned
    input's corner wedges, when ``result`` does not carry them (a qemjax result does)."""
    wf_in = getattr(result, "input_wedge_faces", None) if input_wedge_faces is None else input_wedge_faces
    if result.wedge_faces is None or wf_in is None:
        raise ValueError("seam_report needs a result with attributes (wedge_faces and input_wedge_faces)")
    cin = charts(result.input_faces, wf_in)
    cout = charts(result.faces, result.wedge_faces)
    src = cin[result.source_faces]
    pairs = np.unique(np.stack([cout, src], 1), axis=0)
    per_out = np.bincount(pairs[:, 0], minlength=int(cout.max()) + 1 if len(cout) else 0)
    mixed = np.flatnonzero(per_out > 1)
    return {"charts_in": int(len(np.unique(cin))), "charts_out": int(len(np.unique(cout))),
            "mixed_charts": int(len(mixed)), "seam_faces_out": int(np.isin(cout, mixed).sum())}


def _uv_charts_of_mesh(mesh):
    """(welded faces, per-face chart ids, corner UVs (m,3,2)) of a mesh carrying UVs (`corner_values`)."""
    V, F, C = corner_values(mesh, "uv")
    if getattr(mesh, "wedge_faces", None) is not None:
        return F, charts(F, mesh.wedge_faces), C
    _, wid = np.unique(V, axis=0, return_inverse=True)
    return wid.reshape(-1)[F], charts(wid.reshape(-1)[F], F), C


def uv_chart_integrity(original, simplified, *, eps: float = 1e-6, chunk: int = 256) -> dict:
    """Seam integrity of any simplifier's textured output, from UVs alone: each output face's three corner
    UVs and its UV centroid are located in the original's UV atlas (the input triangle containing each, with
    ``eps`` slack); a face whose four points share no input chart spans a seam (or left the atlas).
    Returns charts_in, charts_out (output faces joined across edges whose corners share UVs),
    faces_spanning (count) and spanning_fraction. ``original``, ``simplified``: meshes with UVs (as
    `attribute_deviation` takes them); ``chunk``: output points tested against the atlas at a time (memory)."""
    # a NaN eps would find no point in any triangle (every face "spanning"); a chunk below 1, range's errors
    if isinstance(eps, bool) or not isinstance(eps, (int, float, np.integer, np.floating)) \
            or not 0 <= eps < float("inf"):
        raise ValueError(f"eps must be a finite number >= 0 (UV units), got {eps!r}")
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk must be a whole number >= 1, got {chunk!r}")
    if corner_values(original, "uv") is None or corner_values(simplified, "uv") is None:
        raise ValueError("both meshes must carry UVs")
    _, cin, Cin = _uv_charts_of_mesh(original)
    Fs, cout, Cs = _uv_charts_of_mesh(simplified)
    q = np.concatenate([Cs, Cs.mean(axis=1, keepdims=True)], 1).reshape(-1, 2)  # (4m, 2)
    a, b, c = Cin[:, 0], Cin[:, 1], Cin[:, 2]
    v0, v1 = b - a, c - a
    den = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    ok = np.abs(den) > 1e-300
    sets = []
    for s in range(0, len(q), chunk):
        p = q[s:s + chunk, None, :] - a[None]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (p[..., 0] * v1[:, 1] - p[..., 1] * v1[:, 0]) / den
            v = (v0[:, 0] * p[..., 1] - v0[:, 1] * p[..., 0]) / den
        inside = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps)
        sets += [set(cin[np.flatnonzero(row)].tolist()) for row in inside]
    per_face = [sets[4 * i:4 * i + 4] for i in range(len(Fs))]
    spanning = sum(1 for pts in per_face if not set.intersection(*pts))
    return {"charts_in": int(len(np.unique(cin))), "charts_out": int(len(np.unique(cout))),
            "faces_spanning": int(spanning), "spanning_fraction": spanning / max(len(Fs), 1)}
