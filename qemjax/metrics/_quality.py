"""Per-triangle shape quality, and area / volume retention."""

from __future__ import annotations

import numpy as np

from .._pipeline.fit_rules import SLIVER_DEG  # a face whose smallest angle is below it is a sliver
from ._common import _DEGENERATE_REL, MeshArrays, as_mesh, in_frame, to_mesh_units

HISTOGRAM_EDGES_DEG = np.arange(0.0, 61.0, 5.0)  # 0, 5, ..., 60: the smallest angle of a triangle is <= 60


def _angles_deg(mesh: MeshArrays) -> np.ndarray:
    """(m, 3) float64 interior angles in degrees at corners a, b, c; atan2(|cross|, dot) stays accurate for
    needle and cap triangles. Degenerate faces get angles of 0 (and 180)."""
    c = mesh.corners
    ab, ac, bc = c[1] - c[0], c[2] - c[0], c[2] - c[1]
    twice_area = mesh.double_areas
    at_a = np.arctan2(twice_area, (ab * ac).sum(axis=0))
    at_b = np.arctan2(twice_area, -(ab * bc).sum(axis=0))
    at_c = np.arctan2(twice_area, (ac * bc).sum(axis=0))
    return np.degrees(np.stack([at_a, at_b, at_c], axis=1))


def min_angles(mesh) -> np.ndarray:
    """(m,) float64 smallest interior angle of each face, degrees (0 for degenerate faces)."""
    return _angles_deg(in_frame(as_mesh(mesh))[1][0]).min(axis=1)


def min_angle_histogram(mesh, bin_edges=HISTOGRAM_EDGES_DEG) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of the smallest interior angle per face.

    Args:
      mesh: any accepted mesh (see `evaluate`).
      bin_edges: (k + 1,) increasing edges in degrees; default 0, 5, ..., 60 (12 bins, the last one closed).
    Returns:
      counts (k,) int64 and bin_edges (k + 1,) float64 (degrees); counts sum to the number of faces when
      the edges span [0, 60].
    """
    got = " ".join(repr(bin_edges).split())  # one line, also for an array numpy prints on several
    said = f"bin_edges must be a 1-D increasing array of at least 2 values, got {got}"
    try:  # text or a ragged list raised numpy's own conversion error, naming no argument
        edges = np.asarray(bin_edges, dtype=np.float64)
    except (ValueError, TypeError):
        raise ValueError(said) from None
    if edges.ndim != 1 or len(edges) < 2 or not (np.diff(edges) > 0).all():
        raise ValueError(said)
    # a face's smallest angle is at most 60°; rounding may give 60.000...01, which the last bin would miss
    counts, _ = np.histogram(np.minimum(min_angles(mesh), 60.0), bins=edges)
    return counts.astype(np.int64), edges


def triangle_quality(mesh) -> dict:
    """Shape quality of the faces, as a flat dict of scalars.

    Returns:
      min_angle_min, min_angle_mean: smallest interior angle per face (degrees), minimum and mean over faces.
      sliver_fraction: fraction of faces whose smallest angle is below 10 degrees.
      aspect_ratio_mean, aspect_ratio_max: aspect ratio = longest edge / (2 * sqrt(3) * inradius), 1 for an
        equilateral triangle and growing without bound as a face degenerates (inradius = 2 * area /
        perimeter). Over non-degenerate faces; NaN when there are none.
      degenerate_faces: faces with (numerically) zero area, twice-area <= 1e-12 * longest edge^2 (int).
    """
    m = in_frame(as_mesh(mesh))[1][0]  # its values are ratios: the same in any frame
    angles = _angles_deg(m).min(axis=1)
    c = m.corners
    lengths = np.sqrt(np.stack([((c[1] - c[0]) ** 2).sum(0), ((c[2] - c[1]) ** 2).sum(0), ((c[0] - c[2]) ** 2).sum(0)]))
    longest = lengths.max(axis=0)
    perimeter = lengths.sum(axis=0)
    twice_area = m.double_areas
    degenerate = twice_area <= _DEGENERATE_REL * longest**2
    # longest / (2 sqrt3 r) with r = 2A / P = twice_area / P.
    aspect = longest[~degenerate] * perimeter[~degenerate] / (2.0 * np.sqrt(3.0) * twice_area[~degenerate])
    return {
        "min_angle_min": float(angles.min()),
        "min_angle_mean": float(angles.mean()),
        "sliver_fraction": float((angles < SLIVER_DEG).mean()),
        "aspect_ratio_mean": float(aspect.mean()) if aspect.size else float("nan"),
        "aspect_ratio_max": float(aspect.max()) if aspect.size else float("nan"),
        "degenerate_faces": int(degenerate.sum()),
    }


def surface_area(mesh: MeshArrays) -> float:
    """Total area (mesh units squared)."""
    return float(mesh.double_areas.sum() / 2.0)


def signed_volume(mesh: MeshArrays) -> float:
    """Enclosed volume (mesh units cubed) by the divergence theorem, positive for outward-facing normals;
    NaN unless the mesh is closed (every edge in two faces, traversed in opposite directions)."""
    if not mesh.welded.edges.closed:  # split at UV seams, a closed surface all the same
        return float("nan")
    # Sum of (a - r) . ((b - a) x (c - a)) / 6 over faces: a cone from r over each face. r = the mean vertex
    # keeps precision for meshes far from the origin (a closed surface's volume does not depend on r).
    a = mesh.corners[0] - mesh.vertices.mean(axis=0)[:, None]
    n = mesh.cross
    return float((a[0] * n[0] + a[1] * n[1] + a[2] * n[2]).sum() / 6.0)


def area_volume(original, simplified) -> dict:
    """Surface area retention and volume change, as a flat dict of scalars.

    Returns:
      area_before, area_after: total areas (mesh units squared). area_retention: area_after / area_before.
      volume_before, volume_after: enclosed volumes (mesh units cubed), NaN for a mesh that is not closed
        (some edge not in exactly two faces, a face on no edge, or faces not consistently oriented).
      volume_change: volume_after / volume_before - 1 (dimensionless), NaN unless both meshes are closed.
    """
    return _area_volume(*in_frame(as_mesh(original, "original"), as_mesh(simplified, "simplified")))


def _area_volume(k: int, meshes: list) -> dict:
    """`area_volume` of the original and simplified meshes measured in the frame of `_common.in_frame`
    with exponent k."""
    o, s = meshes
    area_o, area_s = surface_area(o), surface_area(s)
    vol_o, vol_s = signed_volume(o), signed_volume(s)
    with np.errstate(divide="ignore", invalid="ignore"):
        retention = np.float64(area_s) / area_o
        change = np.float64(vol_s) / vol_o - 1.0
    return {
        "area_before": to_mesh_units(area_o, 2, k),
        "area_after": to_mesh_units(area_s, 2, k),
        "area_retention": float(retention),
        "volume_before": to_mesh_units(vol_o, 3, k),
        "volume_after": to_mesh_units(vol_s, 3, k),
        "volume_change": float(change),
    }
