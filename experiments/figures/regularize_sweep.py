"""Sliver fraction and rms against the regularisation weight λ (``simplify(regularize=λ)``), next to peers.

Every shared mesh at each ratio: qemjax (parallel, ``--method``: ``classic`` by default, the method of the
table in docs/methods.md) at each λ, pymeshlab (its quality threshold at the
default 0.3 and at 1.0) and meshoptimizer, all measured by `qemjax.metrics.evaluate` (sliver: smallest angle
under 10°; rms two-way, relative to the bounding-box diagonal). Prints per-λ summaries and writes
``results/regularize_sweep.csv`` (the file docs/methods.md cites) when every option has its default; any
other run writes ``regularize_sweep_custom.csv`` beside it unless ``--out`` names a file.

    python experiments/figures/regularize_sweep.py                       # all shared meshes, 10 % and 1 %
    python experiments/figures/regularize_sweep.py --method default      # the package's default method
    python experiments/figures/regularize_sweep.py --meshes cow --ratios 0.1 --lambdas 0 0.1

meshoptimizer's ``Regularize`` flag (1 << 4 in meshoptimizer.h) is not in the Python binding installed here
(0.2.30a0): passing it returns the same indices as without it, so only its default run is listed.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))


def pymeshlab_quality(V, F, target, thr):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(V, np.float64), face_matrix=np.asarray(F, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(target), optimalplacement=True,
                                                preservenormal=True, qualitythr=thr)
    out = ms.current_mesh()
    import peers

    return peers.compact(out.vertex_matrix(), out.face_matrix())


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--lambdas", nargs="+", type=float, default=[0.0, 0.03, 0.1, 0.3, 1.0])
    ap.add_argument("--method", default="classic",
                    help="qemjax's method (default: classic, the method of docs/methods.md's table)")
    ap.add_argument("--out", default=None, help="the CSV to write (default: results/regularize_sweep.csv with the "
                                                "default options, else results/regularize_sweep_custom.csv)")
    args = ap.parse_args(argv)
    from figures.line_quadrics import out_path

    args.out = args.out or out_path(ap, args, "regularize_sweep.csv")
    return args


def main(argv=None):
    args = parse_args(argv)
    import pandas as pd

    import meshes as bench
    import peers
    import qemjax
    from qemjax import metrics

    rows = []
    for name in args.meshes or bench.names():
        bm = bench.load(name)
        V, F = bm.V, bm.F
        for ratio in args.ratios:
            target = max(1, int(round(ratio * len(F))))
            runs = {}
            for lam in args.lambdas:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = qemjax.simplify((V, F), target_faces=target, method=args.method, regularize=lam)
                runs[f"qemjax λ={lam:g}"] = (r.vertices, r.faces, lam)
            runs["pymeshlab"] = (*pymeshlab_quality(V, F, target, 0.3), np.nan)
            runs["pymeshlab qualitythr=1"] = (*pymeshlab_quality(V, F, target, 1.0), np.nan)
            runs["meshoptimizer"] = (*peers.simplify_meshoptimizer(V, F, target), np.nan)
            for method, (V2, F2, lam) in runs.items():
                e = metrics.evaluate((V, F), (V2, F2), target_faces=target)
                rows.append(dict(mesh=name, ratio=ratio, method=method, qemjax_method=args.method,
                                 regularize=lam, faces=len(F2),
                                 sliver_fraction=e["sliver_fraction"], min_angle_mean=e["min_angle_mean"],
                                 rms_rel=e["rms_rel"], hausdorff_rel=e["hausdorff_rel"]))
            print(name, ratio, " ".join(f"{r['method']}: {r['sliver_fraction']:.3f}/{r['rms_rel']:.2e}"
                                        for r in rows[-len(runs):]), flush=True)
    df = pd.DataFrame(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    summary(df)


def summary(df):
    """Per ratio and method: median sliver fraction, median rms over λ=0's, and how often the sliver
    fraction is at or below pymeshlab's."""
    base = df[df.method == "qemjax λ=0"].set_index(["mesh", "ratio"])
    pml = df[df.method == "pymeshlab"].set_index(["mesh", "ratio"])
    print("\n| ratio | method | median sliver fraction | median rms / λ=0 | sliver <= pymeshlab |")
    print("|---|---|---|---|---|")
    for (ratio, method), g in df.groupby(["ratio", "method"], sort=False):
        g = g.set_index(["mesh", "ratio"])
        rel = (g.rms_rel / base.rms_rel.reindex(g.index)).median()
        le = int((g.sliver_fraction <= pml.sliver_fraction.reindex(g.index)).sum())
        print(f"| {ratio:g} | {method} | {g.sliver_fraction.median():.4f} | {rel:.3f} | {le}/{len(g)} |")


if __name__ == "__main__":
    main()
