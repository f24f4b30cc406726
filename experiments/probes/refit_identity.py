"""The re-fit post-pass of the package at ``--rev`` against the working tree's, on the same simplified meshes:
bit-identical positions, and the post-pass's own time (`_refit.refit`, median of ``--repeats``, alternating).
Each case is simplified once with the working tree's default (no re-fit); both versions' `_refit.refit` then
re-fit that output, as ``simplify(refit=rounds)`` does (``method="accurate"`` too, with its own output).

    python experiments/probes/refit_identity.py --rev main --out experiments/results/refit_identity
"""
from __future__ import annotations

import argparse
import hashlib
import importlib
import statistics
import sys
import time
import warnings
from pathlib import Path


EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from ab_compare import load_old  # noqa: E402
from figures.rank_peers import save_run  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", default="main")
    ap.add_argument("--meshes", nargs="+", default=None, help="default: every shared mesh")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--methods", nargs="+", default=["qem", "accurate"])
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax._mesh import topology as topo
    from qemjax._pipeline import refit as new_refit

    old = load_old(args.rev)
    try:  # the package's layout before and after the regrouping (61c71ce)
        old_refit = importlib.import_module(old.__name__ + "._pipeline.refit")
    except ModuleNotFoundError:
        old_refit = importlib.import_module(old.__name__ + "._refit")
    cos_max = qemjax.Topology().cos_max
    rows, lines = [], ["| mesh | ratio | method | faces out | old refit s | new refit s | new / old | identical |",
                       "|---|---|---|---|---|---|---|---|"]
    for name in args.meshes or bench_meshes.names():
        m = bench_meshes.load(name)
        V, F = m.V, m.F
        label = topo.parts(F, len(V))[1]
        for ratio in args.ratios:
            for method in args.methods:
                target = max(4, round(ratio * len(F)))
                kw = {"refit": 0} if method == "accurate" else {}
                res = qemjax.simplify((V, F), target_faces=target, method=method, **kw)
                call = (V, F, res.vertices, res.faces, args.rounds, cos_max, label, res.source_faces)
                t = {"old": [], "new": []}
                out = {}
                for rep in range(args.repeats):
                    for tag, mod in ((("old", old_refit), ("new", new_refit)) if rep % 2 == 0
                                     else (("new", new_refit), ("old", old_refit))):
                        t0 = time.perf_counter()
                        out[tag] = mod.refit(*call)
                        t[tag].append(time.perf_counter() - t0)
                same = out["old"].tobytes() == out["new"].tobytes()
                med = {k: statistics.median(v) for k, v in t.items()}
                rows.append(dict(mesh=name, ratio=ratio, method=method, faces_out=len(res.faces), old_s=med["old"],
                                 new_s=med["new"], identical=same,
                                 hash=hashlib.sha256(out["new"].tobytes()).hexdigest()[:16]))
                lines.append(f"| {name} | {ratio:g} | {method} | {len(res.faces)} | {med['old']:.3f} | "
                             f"{med['new']:.3f} | {med['new'] / med['old']:.2f} | {'yes' if same else 'NO'} |")
                print(lines[-1], flush=True)
    n_same = sum(r["identical"] for r in rows)
    lines.append(f"\n{n_same}/{len(rows)} identical; median new/old "
                 f"{statistics.median(r['new_s'] / r['old_s'] for r in rows):.2f}")
    print(lines[-1])
    if args.out:
        save_run(args.out, rows, list(rows[0]), "\n".join(lines), "refit_identity.py", argv)
    return 0 if n_same == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
