"""The two safeguards of ``simplify(refit=N)`` (`qemjax._pipeline.refit`), switched off one at a time on the cases
that showed why they are there: samples attached within their own part (else the nearest output face of
any part) and the flip rule's halved moves (else a move that turns a face is undone at once, or, with no
rule, kept). Each case runs the ``accurate`` preset's options with ``refit=0`` (rank_peers' variant
syntax), then `_refit.refit` with 3 rounds in each mode; rms and Hausdorff as `rank_peers.distances`::

    python experiments/probes/refit_parts.py --out experiments/results/refit_parts
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

NOFIT = ("nofit:memoryless=True,memory_weight=0.3,placement=rank,rank_eps=1e-3,max_shift=0.5,area_power=0.6,"
         "boundary_weight=10")
CASES = [("truck", 477), ("truck", 924), ("beetle", 21), ("suzanne", 10), ("cow", 58), ("3holes", 72)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=str(EXPERIMENTS / "results" / "refit_parts"))
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from qemjax._pipeline import refit as _refit
    from qemjax._mesh import topology as topo

    run = variant_runner(*parse_variant(NOFIT))
    cos90 = float(np.cos(np.radians(90.0)))
    modes = {  # name: (per part, HALVINGS, cos_max)
        "no refit": None,
        "one part, no flip rule": (False, 4, -2.0),
        "one part, undo": (False, 0, cos90),
        "one part, halve": (False, 4, cos90),
        "parts, undo": (True, 0, cos90),
        "parts, halve (simplify)": (True, 4, cos90),
    }
    rows, lines = [], ["| case | faces | " + " | ".join(f"{m} rms / H" for m in modes) + " |",
                       "|---" * (2 + len(modes)) + "|"]
    saved = _refit.HALVINGS
    for name, target in CASES:
        mesh = bench_meshes.load(name)
        res = run(mesh.V, mesh.F, target)
        X, G = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
        label = topo.parts(mesh.F, len(mesh.V))[1]
        cells = []
        for mode, spec in modes.items():
            if spec is None:
                Y = X
            else:
                per_part, halvings, cos_max = spec
                _refit.HALVINGS = halvings
                try:
                    kw = dict(part=label, source_faces=res.source_faces) if per_part else {}
                    Y = _refit.refit(mesh.V, mesh.F, X, G, args.rounds, cos_max, **kw)
                finally:
                    _refit.HALVINGS = saved
            d = distances(mesh.V, mesh.F, Y, G)
            rows.append(dict(mesh=name, target=target, faces_out=len(G), mode=mode, **d))
            cells.append(f"{d['rms_rel']:.3e} / {d['hausdorff_rel']:.3e}")
        lines.append(f"| {name} @ {target} | {len(G)} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    save_run(args.out, rows, list(rows[0]), "\n".join(lines), "refit_parts.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
