"""What kept UVs cost the default's geometry, now that they turn off its memoryless last stretch (the run
warns): for each mesh and ratio, the default with ``attributes="uv"`` (summed quadrics throughout) against
``attributes=None`` (with the stretch), and ``attributes=None, late_memoryless=0`` (what the stretch alone
is worth); rms and Hausdorff relative to the input's bounding-box diagonal (`qemjax.metrics.surface_distance`).

    python experiments/probes/late_attributes.py

Meshes: the shared spot (skipped when ../shared is absent), `qemjax examples`' textured sphere (six UV charts)
and two generated meshes with planar UVs (no seams).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(EXPERIMENTS)]

from meshes import SHARED_MESHES  # noqa: E402


def planar(mesh):
    """The mesh with UVs from its x and y (no seams)."""
    import trimesh

    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    uv = (V[:, :2] - V[:, :2].min(0)) / np.ptp(V[:, :2], axis=0)
    return trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(uv=uv))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ratios", type=float, nargs="+", default=[0.1, 0.02])
    args = ap.parse_args()
    import qemjax
    from qemjax import metrics, shapes

    tmp = Path(tempfile.mkdtemp())
    shapes.write_examples(tmp, subdivisions=5)
    cases = [("textured sphere (6 UV charts)", str(tmp / "textured.obj")),
             ("bumpy sphere, planar UVs", planar(shapes.bumpy_sphere(5))),
             ("torus, planar UVs", planar(shapes.torus(n_major=160, n_minor=80)))]
    spot = SHARED_MESHES / "spot" / "spot.obj"
    if spot.exists():
        cases.insert(0, ("spot", str(spot)))
    print("| mesh | faces | ratio | UVs kept: rms, Hausdorff | attributes=None: rms, Hausdorff | kept ÷ None | "
          "None without the stretch ÷ None |\n|---|---|---|---|---|---|---|")
    for name, mesh in cases:
        for ratio in args.ratios:
            with warnings.catch_warnings():  # (the stretch's warning, and load's of the UVs it leaves out)
                warnings.simplefilter("ignore")
                orig = qemjax.load(mesh) if isinstance(mesh, str) else mesh
                kept = qemjax.simplify(mesh, ratio=ratio, attributes="uv")
                none = qemjax.simplify(mesh, ratio=ratio, attributes=None)
                summed = qemjax.simplify(mesh, ratio=ratio, attributes=None, late_memoryless=0)
            assert kept.uv is not None and "late_memoryless_off" in kept.stats
            a, b, c = (metrics.surface_distance(orig, r) for r in (kept, none, summed))
            print(f"| {name} | {len(orig.faces)} | {ratio:g} | {a['rms_rel']:.3e}, {a['hausdorff_rel']:.3e} | "
                  f"{b['rms_rel']:.3e}, {b['hausdorff_rel']:.3e} | {a['rms_rel'] / b['rms_rel']:.3f}, "
                  f"{a['hausdorff_rel'] / b['hausdorff_rel']:.3f} | {c['rms_rel'] / b['rms_rel']:.3f}, "
                  f"{c['hausdorff_rel'] / b['hausdorff_rel']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
