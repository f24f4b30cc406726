"""What ``refit`` adds to the ``accurate`` preset's time: per case, the preset's options without the re-fit
(rank_peers' variant syntax, warm), the default `simplify` (warm), and `_refit.refit` (``--rounds``, default
1 as the preset) on that output, each the median of ``--repeats`` runs in turn in one process (wall time; single timings on
a shared machine move by 10-30 %)::

    python experiments/probes/refit_time.py --meshes armadillo stanford-bunny face cow suzanne --out experiments/results/refit_time
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from probes.refit_parts import NOFIT  # noqa: E402
from figures.rank_peers import parse_variant, save_run, variant_runner  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", required=True)
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--out", default=str(EXPERIMENTS / "results" / "refit_time"))
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax._pipeline import refit as _refit
    from qemjax._mesh import topology as topo

    nofit = variant_runner(*parse_variant(NOFIT))
    rows, lines = [], [f"| case | faces | default s | preset without refit s | refit ({args.rounds} rounds) s | "
                       "refit / (preset without refit) |",
                       "|---|---|---|---|---|---|"]
    for name in args.meshes:
        mesh = bench_meshes.load(name)
        label = topo.parts(mesh.F, len(mesh.V))[1]
        for ratio in args.ratios:
            target = max(4, int(round(ratio * mesh.n_faces)))
            res = nofit(mesh.V, mesh.F, target)  # warm-up (compilation)
            qemjax.simplify((mesh.V, mesh.F), target_faces=target)
            t = {"default": [], "nofit": [], "refit": []}
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                qemjax.simplify((mesh.V, mesh.F), target_faces=target)
                t1 = time.perf_counter()
                res = nofit(mesh.V, mesh.F, target)
                t2 = time.perf_counter()
                _refit.refit(mesh.V, mesh.F, res.vertices, res.faces, args.rounds, 0.0, label, res.source_faces)
                t3 = time.perf_counter()
                t["default"].append(t1 - t0)
                t["nofit"].append(t2 - t1)
                t["refit"].append(t3 - t2)
            med = {k: float(np.median(v)) for k, v in t.items()}
            rows.append(dict(mesh=name, ratio=ratio, target=target, faces_out=len(res.faces), **med))
            lines.append(f"| {name} @ {ratio:g} | {len(res.faces)} | {med['default']:.2f} | {med['nofit']:.2f} | "
                         f"{med['refit']:.2f} | {med['refit'] / med['nofit']:.2f} |")
            print(lines[-1], flush=True)
    save_run(args.out, rows, list(rows[0]), "\n".join(lines), "refit_time.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
