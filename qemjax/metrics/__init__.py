"""Quality metrics for mesh simplification: surface distance, area / volume, triangle quality, topology.

All metrics run on the host in float64 numpy (they are measured once per result, and must resolve errors
smaller than float32 noise). Meshes may be `trimesh.Trimesh`, ``(vertices, faces)`` tuples, or any object with
``.vertices`` (n, 3) and ``.faces`` (m, 3) arrays.

    >>> from qemjax import metrics
    >>> row = metrics.evaluate(original, simplified, target_faces=10_000)
    >>> row["hausdorff_rel"], row["rms_rel"], row["genus"], row["time_s"]
"""

from ._appearance import attribute_deviation as attribute_deviation
from ._appearance import charts as charts
from ._appearance import seam_report as seam_report
from ._appearance import uv_chart_integrity as uv_chart_integrity
from ._distance import surface_distance as surface_distance
from ._evaluate import evaluate as evaluate
from .._mesh.pointtri import point_triangle_distance as point_triangle_distance
from ._quality import area_volume as area_volume
from ._quality import min_angle_histogram as min_angle_histogram
from ._quality import triangle_quality as triangle_quality
from ._topology import topology_report as topology_report

__all__ = [
    "area_volume",
    "attribute_deviation",
    "charts",
    "seam_report",
    "uv_chart_integrity",
    "evaluate",
    "min_angle_histogram",
    "point_triangle_distance",
    "surface_distance",
    "topology_report",
    "triangle_quality",
]
