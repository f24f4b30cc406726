"""The re-fit's price, old code against new in one process: per case, the warm wall time of the default
`simplify` and of ``refit=1`` (and of ``method="accurate"`` with ``--accurate``) for the package at ``--rev``
and for the working tree, alternating, with the ratio refit=1 / default of each version and whether the
outputs are identical (hashes as `ab_compare`; issue 32: the goal is refit=1 at <= 1.5x the default).

    python experiments/probes/refit_ab.py --rev main --cases stanford-bunny:0.1 armadillo:0.1 armadillo:0.01 cow:0.1 \
        --repeats 5 --out experiments/results/refit_ab
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

from ab_compare import digest, load_old  # noqa: E402
from figures.rank_peers import save_run  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", default="main", help="the old code's git revision")
    ap.add_argument("--cases", nargs="+", default=["stanford-bunny:0.1", "armadillo:0.1", "armadillo:0.01",
                                                    "cow:0.1"], help="MESH:RATIO")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--accurate", action="store_true", help="also time method='accurate'")
    ap.add_argument("--out", default=None, help="save the table (.md) and rows (.csv) under this stem")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import meshes as bench_meshes

    old = load_old(args.rev)
    import qemjax as new

    configs = {"default": {}, "refit=1": {"refit": 1}}
    if args.accurate:
        configs["accurate"] = {"method": "accurate"}
    libs = {"old": old, "new": new}
    rows = []
    lines = ["| case | faces out | " + " | ".join(f"{v} {c} s" for c in configs for v in libs)
             + " | refit/default old | refit/default new | refit outputs |", "|---" * (5 + 2 * len(configs)) + "|"]
    for case in args.cases:
        name, ratio = case.rsplit(":", 1)
        m = bench_meshes.load(name)
        target = max(4, round(float(ratio) * m.n_faces))
        runs = [(v, c) for c in configs for v in libs]
        for v, c in runs:  # warm-up (compilation)
            libs[v].simplify((m.V, m.F), target_faces=target, **configs[c])
        t = {r: [] for r in runs}
        h = {}
        for rep in range(args.repeats):
            for v, c in (runs if rep % 2 == 0 else runs[::-1]):
                t0 = time.perf_counter()
                res = libs[v].simplify((m.V, m.F), target_faces=target, **configs[c])
                t[(v, c)].append(time.perf_counter() - t0)
                h[(v, c)] = digest(res)
        med = {r: statistics.median(x) for r, x in t.items()}
        same = all(h[("old", c)] == h[("new", c)] for c in configs)
        row = dict(mesh=name, ratio=float(ratio), target=target, faces_out=len(res.faces), repeats=args.repeats,
                   **{f"{v}_{c}": med[(v, c)] for v, c in runs},
                   ratio_old=med[("old", "refit=1")] / med[("old", "default")],
                   ratio_new=med[("new", "refit=1")] / med[("new", "default")], identical=same,
                   **{f"hash_{v}_{c}": h[(v, c)] for v, c in runs})
        rows.append(row)
        lines.append(f"| {name} @ {ratio} | {len(res.faces)} | " + " | ".join(f"{med[r]:.3f}" for r in runs)
                     + f" | {row['ratio_old']:.2f} | {row['ratio_new']:.2f} | "
                     + ("identical" if same else "DIFFERENT") + " |")
        print(lines[-1], flush=True)
    if args.out:
        save_run(args.out, rows, list(rows[0]), "\n".join(lines), "refit_ab.py", argv)
    return 0 if all(r["identical"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
