"""The measured distance of a result from its input (``simplify(measure=...)``; ``res.stats["distance_*"]``).

The contraction costs are quadric errors: each a sum of squared distances to many planes, which can be
tens or hundreds of times the squared distance the output actually lies from the input. What a user can
report as an error is measured here instead, in mesh units: the distance from the input's surface to the
output's, at deterministic samples of the input (every vertex and every face centroid, the re-fit's
samples, `refit.samples`), each to its exact nearest point of the output (`_mesh.grid_nearest`).

* ``distance_max``: the largest sample's distance (a one-sided Hausdorff distance, input → output, at
  those samples: a lower bound of the continuous one, which points between samples can exceed);
* ``distance_rms``: the root mean square over the samples, each weighted by the area it stands for (a
  vertex a third of its faces' area, a centroid its face's), an estimate of the surface's rms distance;
* ``distance_p50``, ``distance_p95``, ``distance_p99``: the median, 95th and 99th percentile of the
  samples' distances, each sample weighted by the area it stands for (as for the rms: the distance within
  which that share of the input's surface lies, at the samples); observed values, never interpolated;
* ``distance_max_rel``, ``distance_rms_rel``, ``distance_p50_rel``, ...: the same divided by the input's
  bounding-box diagonal;
* ``distance_samples`` and ``distance_s`` (the seconds it took).

`qemjax.metrics.surface_distance` measures both ways with random samples too, for evaluations.
"""
from __future__ import annotations

import time

import numpy as np

PERCENTILES = (50, 95, 99)
KEYS = ("distance_max", "distance_rms", *(f"distance_p{p}" for p in PERCENTILES), "distance_max_rel",
        "distance_rms_rel", *(f"distance_p{p}_rel" for p in PERCENTILES), "distance_samples", "distance_s")


def not_measured() -> dict:
    """The stats of a run that did not measure (``measure=False``): every key None."""
    return dict.fromkeys(KEYS)


def distance(V: np.ndarray, F: np.ndarray, X: np.ndarray, G: np.ndarray, sampled: tuple | None = None,
             seeds: np.ndarray | None = None) -> dict:
    """The stats of the module docstring for the input (V, F) and the output (X, G), float64, mesh units.
    ``sampled``: the input's samples as the re-fit of the same run made them (its ``sampled``: points in
    the input's unit frame, weights), the same arrays as made here; ``seeds``: a face of G near each
    sample (the re-fit's last attachment), where each search starts (the same distances, found sooner:
    `grid_nearest.nearest`)."""
    from .._mesh.arrays import box_diagonal
    from .._mesh.box_bounds import row_bounds  # numba, lazily
    from .._mesh.grid_nearest import nearest
    from .._mesh.quantiles import quantiles
    from .refit import samples, unit_frame

    t = time.perf_counter()
    V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
    X, G = np.asarray(X, np.float64), np.asarray(G, np.int64)
    box = row_bounds(V) if len(V) else None  # (lo, hi), for the frame and the diagonal
    centre, unit = unit_frame(V, box)  # as the re-fit: squared distances stay finite at any scale
    diag = box_diagonal(box[0], box[1]) if len(V) else 0.0
    if not (unit > 0 and np.isfinite(unit)) or len(V) == 0 or len(G) == 0:
        return not_measured() | dict(distance_samples=0, distance_s=time.perf_counter() - t)
    if sampled is None:
        P, w, _ = samples((V - centre) / unit, F, np.zeros(len(V), np.int64))  # areas too: no underflow
    else:
        P, w = sampled
    if len(P) == 0:
        return not_measured() | dict(distance_samples=0, distance_s=time.perf_counter() - t)
    if len(X) == len(V) and np.array_equal(G, F) and np.array_equal(X, V):
        # the input itself (nothing removed, nothing moved): every sample lies on it, exactly; the search,
        # in the unit frame, would round that to 1e-16 or so
        d = np.zeros(len(P))
    else:
        _, d = nearest((X - centre) / unit, G, P, seeds)
    d_max = float(d.max()) * unit
    d_rms = float(np.sqrt(np.sum(w * d * d) / np.sum(w))) * unit
    pq = {f"distance_p{p}": v * unit for p, v in zip(PERCENTILES, quantiles(d, [p / 100 for p in PERCENTILES], w))}
    out = dict(distance_max=d_max, distance_rms=d_rms, **pq)
    out.update({f"{k}_rel": (v / diag if diag > 0 else None) for k, v in list(out.items())})
    return out | dict(distance_samples=int(len(P)), distance_s=time.perf_counter() - t)
