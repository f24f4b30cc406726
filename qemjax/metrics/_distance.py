"""Two-way sampled surface distance between an original and a simplified mesh."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ._common import MeshArrays, as_mesh, in_frame, to_mesh_units
from .._mesh.nearest import nearest_triangles
from .._mesh.quantiles import quantiles

DEFAULT_SAMPLES = 100_000


def sample_points(mesh: MeshArrays, n_samples: int, rng: np.random.Generator) -> np.ndarray:
    """Points on the surface: every referenced vertex, then n_samples area-weighted uniform samples.

    Returns (V_referenced + n_samples, 3) float64 (only the vertices when the area is zero).
    """
    verts = mesh.vertices[mesh.referenced]
    cum = np.cumsum(mesh.double_areas)
    if n_samples == 0 or not cum[-1] > 0:
        return verts
    face = np.minimum(np.searchsorted(cum, rng.random(n_samples) * cum[-1], side="right"), len(cum) - 1)
    u, v = rng.random((2, n_samples))
    fold = u + v > 1.0  # reflect into the triangle: uniform over its area
    u[fold], v[fold] = 1.0 - u[fold], 1.0 - v[fold]
    c = mesh.corners[:, :, face]  # (3 corners, 3 axes, n)
    pts = c[0] + u * (c[1] - c[0]) + v * (c[2] - c[0])
    return np.concatenate([verts, pts.T])


def nearest_faces(mesh: MeshArrays, points: np.ndarray) -> np.ndarray:
    """(q,) int64: for each point (q, 3), a face of mesh at the smallest exact distance."""
    return nearest_triangles(mesh.corners, points)[1]


PERCENTILES = (50, 95, 99)


def _summary(fwd: np.ndarray, bwd: np.ndarray, diag: float, k: int = 0) -> dict:
    """The distances' summary, measured in the frame of `_common.in_frame` with exponent ``k``: lengths
    reported in mesh units, relative values as measured."""
    both = np.concatenate([fwd, bwd])
    e_gh = float(np.mean(both * both))
    out = {
        "hausdorff": float(both.max()),
        "mean": float(both.mean()),
        "rms": float(np.sqrt(e_gh)),
        **{f"p{p}": v for p, v in zip(PERCENTILES, quantiles(both, [p / 100 for p in PERCENTILES]))},
        "e_gh": e_gh,
        "hausdorff_fwd": float(fwd.max()),
        "hausdorff_bwd": float(bwd.max()),
        "mean_fwd": float(fwd.mean()),
        "mean_bwd": float(bwd.mean()),
    }
    rel = {}
    for key, value in out.items():
        scale = diag * diag if key == "e_gh" else diag
        rel[key + "_rel"] = value / scale if scale > 0 else float("nan")
    return {
        **{key: to_mesh_units(value, 2 if key == "e_gh" else 1, k) for key, value in out.items()},
        **rel,
        "n_points_fwd": len(fwd),
        "n_points_bwd": len(bwd),
        "bbox_diagonal": to_mesh_units(diag, 1, k),
    }


def _check_samples(n_samples, name: str = "n_samples") -> int:
    """``n_samples`` (or the argument ``name``: a seed) as an int; ValueError naming it unless it is a whole
    number >= 0."""
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {n_samples!r}")
    return int(n_samples)


def two_way(o: MeshArrays, s: MeshArrays, n_samples: int, seed: int, extra_bwd=None, also=None):
    """Distances of original samples to the simplified surface (fwd) and of simplified samples (plus
    extra_bwd (k, 3) points, answered separately with their nearest original faces) to the original (bwd).

    also: an optional callable run meanwhile (its result is returned last). numpy and scipy release the GIL
    in their loops, so the two directions and ``also`` overlap on several cores.
    """
    seed = _check_samples(seed, "seed")
    rng_o, rng_s = (np.random.default_rng(ss) for ss in np.random.SeedSequence(seed).spawn(2))
    pts_o = sample_points(o, n_samples, rng_o)
    pts_s = sample_points(s, n_samples, rng_s)
    n_bwd = len(pts_s)
    if extra_bwd is not None:
        pts_s = np.concatenate([pts_s, extra_bwd])
    with ThreadPoolExecutor(max_workers=2) as pool:
        fwd = pool.submit(nearest_triangles, s.corners, pts_o)
        bwd = pool.submit(nearest_triangles, o.corners, pts_s)
        extra = also() if also is not None else None
        d_fwd, _ = fwd.result()
        d_bwd, f_bwd = bwd.result()
    return d_fwd, d_bwd[:n_bwd], f_bwd[n_bwd:], extra


def surface_distance(original, simplified, *, n_samples: int = DEFAULT_SAMPLES, seed: int = 0) -> dict:
    """Two-way sampled surface distance, with exact point-to-triangle distances.

    Each mesh is sampled (seeded): all its referenced vertices plus ``n_samples`` area-weighted uniform
    points. fwd = distances from the original's samples to the simplified surface; bwd = from the
    simplified's samples to the original surface. Distances are exact to the nearest point of the other
    surface (not to its vertices).

    Args:
      original, simplified: `trimesh.Trimesh`, ``(vertices, faces)``, objects with ``.vertices`` /
        ``.faces``, or a file's path.
      n_samples: area-weighted samples per mesh, on top of the vertices.
      seed: seeds the sampling; equal seeds give equal results.

    Returns a flat dict of floats; lengths in mesh units, ``*_rel`` keys divided by the original's
    bounding-box diagonal (``e_gh_rel`` by its square):
      hausdorff: max over both sample sets. mean: mean over both sets pooled. rms: sqrt(e_gh).
      p50, p95, p99: the median, 95th and 99th percentile of both sets pooled (observed values, `quantiles`).
      e_gh: Garland-Heckbert's E_i = (sum fwd^2 + sum bwd^2) / (n_fwd + n_bwd), squared units.
      hausdorff_fwd / _bwd, mean_fwd / _bwd: one-sided values.
      n_points_fwd, n_points_bwd (ints), bbox_diagonal.
    """
    k, (o, s) = in_frame(as_mesh(original, "original"), as_mesh(simplified, "simplified"))
    fwd, bwd, _, _ = two_way(o, s, _check_samples(n_samples), seed)
    return _summary(fwd, bwd, o.bbox_diagonal, k)
