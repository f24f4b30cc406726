"""rms and Hausdorff of qemjax variants on one mesh over a range of face counts: is a comparison at one
count a trend or noise?

At very coarse outputs (suzanne at 1 %: 12 faces; rocker-arm-small at 1 %: 16) one contraction more or
less, or one placement elsewhere, changes the distance by tens of percent, so a single case says little
about which variant is better there. This runs each variant (the syntax of `rank_peers.py --variant`) at
every target of ``--targets`` and prints the faces reached, rms and Hausdorff (relative, as
`rank_peers.distances`) and the ratio of each variant to the first::

    python experiments/probes/target_sweep.py --mesh suzanne --targets 10 12 14 16 20 24 30 40 --variant base \\
        --variant mem03:memoryless=True,memory_weight=0.3,placement=rank,rank_eps=1e-3,max_shift=0.5
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from figures.rank_peers import distances, parse_variant, save_run, variant_runner  # noqa: E402

RESULTS = EXPERIMENTS / "results"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--targets", nargs="+", type=int, required=True)
    ap.add_argument("--variant", action="append", required=True, help="as rank_peers.py --variant")
    ap.add_argument("--out", default=None, help="path without extension (default: results/target_sweep_MESH)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    runners = {label: variant_runner(label, rev, s) for label, rev, s in map(parse_variant, args.variant)}
    mesh = bench_meshes.load(args.mesh)
    labels = list(runners)
    rows = []
    lines = ["| target | " + " | ".join(f"{lb} faces / rms / H" for lb in labels)
             + " | " + " | ".join(f"{lb} / {labels[0]} rms, H" for lb in labels[1:]) + " |",
             "|---" * (1 + 2 * len(labels) - 1) + "|"]
    worse = {lb: 0 for lb in labels[1:]}
    for target in args.targets:
        here = {}
        for label, run in runners.items():
            res = run(mesh.V, mesh.F, target)
            V2, F2 = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
            here[label] = dict(mesh=args.mesh, target=target, variant=label, faces_out=len(F2),
                               **distances(mesh.V, mesh.F, V2, F2))
            rows.append(here[label])
        b = here[labels[0]]
        for lb in labels[1:]:
            worse[lb] += here[lb]["rms_rel"] > 1.03 * b["rms_rel"]
        lines.append(f"| {target} | " + " | ".join(f"{r['faces_out']} / {r['rms_rel']:.3e} / {r['hausdorff_rel']:.3e}"
                                                   for r in here.values())
                     + " | " + " | ".join(f"{here[lb]['rms_rel'] / b['rms_rel']:.3f}, "
                                          f"{here[lb]['hausdorff_rel'] / b['hausdorff_rel']:.3f}"
                                          for lb in labels[1:]) + " |")
        print(lines[-1], flush=True)
    lines += ["", "; ".join(f"{lb}: rms more than 3 % worse than {labels[0]} at {n} of {len(args.targets)} targets"
                            for lb, n in worse.items())]
    text = "\n".join(lines)
    print(lines[-1])
    save_run(args.out or str(RESULTS / f"target_sweep_{args.mesh}"), rows, list(rows[0]), text,
             "target_sweep.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
