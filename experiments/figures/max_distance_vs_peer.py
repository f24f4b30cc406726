"""qemjax's guaranteed distance (``simplify(max_distance_rel=R)``) against meshoptimizer's error-bounded
simplification (``meshoptimizer.simplify`` with ``target_error`` and no face target).

For each mesh and bound R (a fraction of the input's bounding-box diagonal): the faces each reaches, and the
two-way sampled distance each result lies from the input as `qemjax.metrics.surface_distance` measures it
(seed 0: vertices plus random area-weighted samples, exact point-triangle distances; ``hausdorff_rel``),
and whether that exceeds R. qemjax's bound holds at its own samples (vertices and face centroids, both
ways: docs/metrics.md, "A distance you can ask for"); the random samples here are other points, so they
may exceed it by a little. meshoptimizer's ``target_error`` is relative to the mesh's extent (its
``simplify_scale``, the bounding box's largest side), so R × diagonal / extent is passed to hold the same
distance; its error is its own estimate, not a checked distance.

Meshes: made in code (`qemjax.shapes`) and, when ``../shared/meshes`` exists (beside the repository), a few
real ones. Prints a markdown table and the CPU model.

    python experiments/figures/max_distance_vs_peer.py [--quick] [--bounds 0.001 0.005 0.01]
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import qemjax
from qemjax import peers, shapes
from qemjax.metrics import surface_distance
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
from machine import cpu_model  # noqa: E402

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "meshes"
REAL = ("cow.obj", "fandisk.obj", "homer.obj", "rocker-arm.obj", "max-planck-10k.obj", "3holes.off",
        "fertility.off", "stanford-bunny.obj")  # of different kinds: with the two made in code, 10 meshes
BOUNDS = (0.001, 0.005, 0.01)


def meshes(quick: bool) -> dict:
    out = {"bumpy_sphere(4)": shapes.bumpy_sphere(4), "torus(48, 24)": shapes.torus()}
    if not quick and SHARED.is_dir():
        import trimesh

        for name in REAL:
            p = SHARED / name
            if p.exists():
                m = trimesh.load(p, process=False, force="mesh")
                out[name] = (np.asarray(m.vertices), np.asarray(m.faces))
    return out


def meshopt(V, F, error: float):
    """meshoptimizer.simplify to ``error`` (its relative units) with no face target: (V, F) compacted."""
    import meshoptimizer

    idx = np.ascontiguousarray(F.reshape(-1), np.uint32)
    pos = np.ascontiguousarray(V, np.float32)
    dst = np.empty(idx.size, np.uint32)
    n = meshoptimizer.simplify(dst, idx, pos, target_index_count=0, target_error=error)
    return peers.compact(V, dst[:n].reshape(-1, 3))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="the meshes made in code only")
    ap.add_argument("--bounds", type=float, nargs="+", default=list(BOUNDS))
    args = ap.parse_args()
    rows = []
    for name, mesh in meshes(args.quick).items():
        for R in args.bounds:
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = qemjax.simplify(mesh, max_distance_rel=R)
            q_s = time.perf_counter() - t
            V, F = res.input_vertices, res.input_faces  # the cleaned input: both start from it
            extent = float(np.max(V.max(0) - V.min(0)))
            diag = float(np.linalg.norm(V.max(0) - V.min(0)))
            t = time.perf_counter()
            mV, mF = meshopt(V, F, R * diag / extent)
            m_s = time.perf_counter() - t
            qd = surface_distance((V, F), (res.vertices, res.faces), seed=0)["hausdorff_rel"]
            md = surface_distance((V, F), (mV, mF), seed=0)["hausdorff_rel"] if len(mF) else float("nan")
            rows.append((name, len(F), R, len(res.faces), res.stats["distance_two_way_max_rel"], qd, qd > R,
                         q_s, len(mF), md, md > R, m_s))
    print(f"CPU: {cpu_model()}\n")
    print("| mesh | faces in | bound (of diag) | qemjax faces | qemjax checked | qemjax sampled | over? | qemjax s "
          "| meshopt faces | meshopt sampled | over? | meshopt s |")
    print("|" + "---|" * 12)
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {100 * r[2]:.2g} % | {r[3]} | {100 * r[4]:.3g} % | {100 * r[5]:.3g} % | "
              f"{'yes' if r[6] else 'no'} | {r[7]:.2f} | {r[8]} | {100 * r[9]:.3g} % | {'yes' if r[10] else 'no'} "
              f"| {r[11]:.3f} |")


if __name__ == "__main__":
    main()
