"""Where a partitioned run's farthest point lies, against the in-core run's: for each mesh, the exact
largest distance of the input's vertices and face centroids from the output (in → out) and of the output's
from the input (out → in), relative to the diagonal, with where it lies, for the in-core run and the
partitioned run (2 local workers) with the memoryless last stretch in the last level only (the package's)
and in every level (``--late every`` of `figures/partition_bench.py`); then the input around the farthest
input point: its vertex's faces, edge lengths and offset from its neighbours' mean, and (``--levels``) that
point's distance from each level's output (a partitioned run with its scratch folder kept)::

    python experiments/probes/partition_far.py --meshes armadillo-x16 stanford-bunny-x16
    python experiments/probes/partition_far.py --meshes stanford-bunny-x16 --levels
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))
sys.path.insert(0, str(EXPERIMENTS / "figures"))


def farthest(V, F, X, G):
    from qemjax._mesh.grid_nearest import nearest

    P = np.concatenate([V, V[F].mean(1)])
    d_in = nearest(X, G.astype(np.int64), P)[1]
    Q = np.concatenate([X, X[G].mean(1)])
    d_out = nearest(V, F.astype(np.int64), Q)[1]
    i, j = int(np.argmax(d_in)), int(np.argmax(d_out))
    return (d_in[i], P[i]), (d_out[j], Q[j])


def levels(V, F, point, ratio, diag) -> None:
    """The distance of ``point`` from the stitched outputs of each level of a partitioned run."""
    import tempfile

    import qemjax
    from qemjax._mesh.grid_nearest import nearest
    from qemjax._partition import pieces

    with tempfile.TemporaryDirectory() as folder:
        qemjax.simplify((V, F), ratio=ratio, measure=False, partition=qemjax.Partition(workers=2, scratch=folder))
        for level in sorted(Path(folder).glob("level*")):
            files = sorted(str(f) for f in level.glob("*.npz") if f.name.startswith(("part_", "group_")))
            X, G, _, _ = pieces.stitch(files)
            d = nearest(X, G.astype(np.int64), point[None])[1][0]
            print(f"  {level.name}: {len(files)} pieces, {len(G)} faces; that point {d / diag:.5f} of the "
                  f"diagonal from them")


def main(argv=None) -> int:
    import meshes
    import qemjax
    from partition_bench import _levels

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["armadillo-x16", "stanford-bunny-x16"])
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--levels", action="store_true", help="the farthest input point's distance level by level")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for name in args.meshes:
        bm = meshes.load(name)
        V, F = bm.V, bm.F
        diag = float(np.linalg.norm(V.max(0) - V.min(0)))
        runs = {"in core": qemjax.simplify((V, F), ratio=args.ratio, measure=False)}
        for late in ("last", "every"):
            with _levels(late):
                runs[f"partitioned, late={late}"] = qemjax.simplify(
                    (V, F), ratio=args.ratio, measure=False, partition=qemjax.Partition(workers=2))
        print(f"## {name} ({len(F)} faces -> {args.ratio:g}), diagonal {diag:.4g}")
        worst = None
        for label, r in runs.items():
            (di, pi), (do, po) = farthest(V, F, r.vertices, r.faces)
            print(f"{label}: in -> out {di / diag:.5f} at {np.round(pi, 3).tolist()}; "
                  f"out -> in {do / diag:.5f} at {np.round(po, 3).tolist()}")
            if label != "in core" and (worst is None or di > worst[0]):
                worst = (di, pi)
        k = int(np.argmin(np.linalg.norm(V - worst[1], axis=1)))  # the input vertex at (or nearest) that point
        faces = np.flatnonzero((F == k).any(1))
        ring = np.setdiff1d(np.unique(F[faces]), [k])
        edges = np.linalg.norm(V[ring] - V[k], axis=1)
        median_edge = float(np.median(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1)))
        print(f"the input vertex nearest the partitioned runs' farthest input point: {len(faces)} faces, edges "
              f"{np.round(edges, 4).tolist()} (the mesh's median edge {median_edge:.2g}), "
              f"{np.linalg.norm(V[k] - V[ring].mean(0)):.3g} from its neighbours' mean", flush=True)
        if args.levels:
            levels(V, F, worst[1], args.ratio, diag)
        print(flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
