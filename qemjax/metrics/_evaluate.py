"""One call that measures everything about a simplification: a flat dict, one row of a results table."""

from __future__ import annotations

import time

from ._appearance import KINDS, attribute_deviation, corner_values
from ._common import as_mesh, in_frame
from ._distance import DEFAULT_SAMPLES, _check_samples, _summary, two_way
from ._quality import _area_volume, triangle_quality
from ._topology import (
    face_centroids,
    flipped_faces_report,
    target_report,
    topology_report,
)

_TOPOLOGY_BEFORE = ("boundary_edges", "non_manifold_edges", "components", "euler", "closed", "genus")


def evaluate(original, simplified, *, target_faces: int | None = None, n_samples: int = DEFAULT_SAMPLES,
             seed: int = 0) -> dict:
    """Distances, area / volume, triangle quality and topology of a simplification, as one flat dict.

    Args:
      original, simplified: `trimesh.Trimesh`, ``(vertices, faces)`` tuples, any objects with
        ``.vertices`` (n, 3) and ``.faces`` (m, 3) (a qemjax result has them), or a file's path.
      target_faces: the face count that was asked for (optional).
      n_samples: area-weighted surface samples per mesh for the distances, on top of the vertices.
      seed: sampling seed; equal inputs and seed give equal numbers.

    Returns scalar values only (lengths in mesh units, angles in degrees, ``*_rel`` relative to the
    original's bounding-box diagonal), in this order:
      faces_before, faces_after, vertices_before, vertices_after, face_ratio (after / before);
      target_faces, target_error (faces_after / target - 1): NaN without ``target_faces``;
      surface distance (see `surface_distance`): hausdorff, mean, rms, p50, p95, p99, e_gh, hausdorff_fwd, hausdorff_bwd,
        mean_fwd, mean_bwd, each also as *_rel; n_points_fwd, n_points_bwd, bbox_diagonal;
      area / volume (see `area_volume`): area_before, area_after, area_retention, volume_before,
        volume_after, volume_change;
      quality of the simplified mesh (see `triangle_quality`): min_angle_min, min_angle_mean,
        sliver_fraction, aspect_ratio_mean, aspect_ratio_max, degenerate_faces;
      topology of the simplified mesh (see `topology_report`: a trimesh or file split at UV, colour or
        normal seams is measured with its coincident vertices joined, so ``res`` and ``res.to_trimesh()``
        read alike; the distances, vertex counts and quality take it as given): edges, boundary_edges, non_manifold_edges,
        non_manifold_vertices, components, euler, closed, orientable, genus, flipped_faces,
        flipped_fraction; of the original: boundary_edges_before, non_manifold_edges_before,
        components_before, euler_before, closed_before, genus_before (genus without the non-manifold
        vertex check, which is skipped on the original for speed: NaN all the same where the count is odd);
      appearance, only when both meshes carry it and n_samples > 0 (see `attribute_deviation`): uv_dev_rms, uv_dev_mean,
        uv_dev_p95, uv_dev_max (texture-space deviation, UV units) and likewise color_dev_*;
      time_s: wall-clock seconds this evaluation took.

    Raises:
      ValueError: malformed meshes (shapes, empty, non-finite values, bad indices) or arguments.
    """
    t0 = time.perf_counter()
    k, (o, s) = in_frame(as_mesh(original, "original"), as_mesh(simplified, "simplified"))
    n_samples = _check_samples(n_samples)
    if target_faces is None:  # same columns in every row
        target = {"target_faces": float("nan"), "target_error": float("nan")}
    else:
        target = target_report(len(s.faces), target_faces)

    def host_side():  # everything else, while the distance threads run
        return topology_report(s), topology_report(o, fans=False), _area_volume(k, [o, s]), triangle_quality(s)

    fwd, bwd, nearest, (topo_s, topo_o, area, quality) = two_way(
        o, s, n_samples, seed, extra_bwd=face_centroids(s), also=host_side
    )

    row = {
        "faces_before": len(o.faces),
        "faces_after": len(s.faces),
        "vertices_before": len(o.vertices),
        "vertices_after": len(s.vertices),
        "face_ratio": len(s.faces) / len(o.faces),
        **target,
        **_summary(fwd, bwd, o.bbox_diagonal, k),
        **area,
        **quality,
        **{k: v for k, v in topo_s.items() if k not in ("vertices", "faces")},
        **flipped_faces_report(s, o, nearest),
        **{f"{k}_before": topo_o[k] for k in _TOPOLOGY_BEFORE},
    }
    for kind in KINDS if n_samples else ():  # a deviation needs surface samples: none asked for, none made
        if corner_values(original, kind) is not None and corner_values(simplified, kind) is not None:
            row.update(attribute_deviation(original, simplified, kind=kind, n_samples=min(n_samples, 20_000),
                                           seed=seed))
    row["time_s"] = time.perf_counter() - t0
    return row
