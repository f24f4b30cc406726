"""The quadrics a partitioned run carries, seen in core: one run to the target against two stages (summed
quadrics to ``--first`` of the faces, then the default from that output to the target), the second stage
starting from its own faces' quadrics or from those the first stage carried out (`qemjax._partition.carry`,
what each level of a partitioned run now does). For each output: the largest distance of the input's
vertices and face centroids from it (in → out, relative to the diagonal, exact) and where it lies::

    python experiments/probes/carry_two_stage.py --meshes stanford-bunny-x16 armadillo-x16
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))


def main(argv=None) -> int:
    import meshes
    import qemjax
    from qemjax._mesh.grid_nearest import nearest
    from qemjax._partition.carry import Carry
    from qemjax._pipeline.stages import SEED

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["stanford-bunny-x16"])
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--first", type=float, default=1 / 16, help="the first stage's share of the faces")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    for name in args.meshes:
        bm = meshes.load(name)
        V, F = bm.V, bm.F
        diag = float(np.linalg.norm(V.max(0) - V.min(0)))
        unit = float(np.max(V.max(0) - V.min(0)))
        P = np.concatenate([V, V[F].mean(1)])
        target = int(round(args.ratio * len(F)))
        first = Carry(V, None, unit)
        mid = qemjax.simplify((V, F), ratio=args.first, measure=False, late_memoryless=0, refit=0,
                              **{SEED: first})
        runs = {"one run": qemjax.simplify((V, F), target_faces=target, measure=False),
                "two stages, own quadrics": qemjax.simplify((mid.vertices, mid.faces), target_faces=target,
                                                            measure=False),
                "two stages, carried": qemjax.simplify(
                    (mid.vertices, mid.faces), target_faces=target, measure=False,
                    **{SEED: Carry(mid.vertices, first.export(mid), unit)})}
        print(f"## {name} ({len(F)} faces -> {target}; first stage {len(mid.faces)} faces)")
        for label, r in runs.items():
            d = nearest(r.vertices, r.faces.astype(np.int64), P)[1]
            i = int(np.argmax(d))
            print(f"{label}: in -> out max {d[i] / diag:.5f} of the diagonal at {np.round(P[i], 3).tolist()}, "
                  f"rms over those points {np.sqrt(np.mean(d * d)) / diag:.6f}")
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
