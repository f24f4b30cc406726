"""Memoryless quadrics for the last stretch only: does the Hausdorff gain of memoryless runs come from the
last contractions?

For every benchmark mesh at 10 % and 1 % (targets as `figures/rank_peers.py`): the default run, then for
each K of ``--restart``: the default without its re-fit to K × the target, then a memoryless run
(``memory_weight=0.3``, no re-fit) from that mesh to the target (its history quadrics start from the
intermediate mesh: the memory of the input is lost), then one re-fit round to the *input*
(`qemjax._pipeline.refit.refit`, one part), and ``--full``: the memoryless run from the start (with its
re-fit). rms and Hausdorff (relative, `rank_peers.distances`) over the best peer's of ``--peers CSV`` (a
`rank_peers.py` result), counted as `rank_peers.py` counts them::

    python experiments/probes/late_memoryless.py --restart 4 10 --full
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from figures.rank_peers import distances  # noqa: E402


def best_peers(path: Path) -> dict:
    """{(mesh, ratio): {"rms_rel", "hausdorff_rel"}}: the lowest of the peers' rows (ok) of a `rank_peers.py` CSV."""
    best = {}
    for r in csv.DictReader(open(path)):
        if r["method"].startswith("qemjax") or r["status"] != "ok":
            continue
        b = best.setdefault((r["mesh"], float(r["ratio"])), {"rms_rel": np.inf, "hausdorff_rel": np.inf})
        for k in b:
            b[k] = min(b[k], float(r[k]))
    return best


def cases(names, best: dict):
    """(name, mesh, ratio, target, the best peer's distances) of every benchmark mesh of ``names`` (None: all)
    at 10 % and 1 % that ``best`` (`best_peers`) holds, the target as `figures/rank_peers.py` takes it."""
    for name in names or bench_meshes.names():
        m = bench_meshes.load(name)
        for ratio in (0.1, 0.01):
            if (name, ratio) in best:
                yield name, m, ratio, max(4, round(ratio * m.n_faces)), best[(name, ratio)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--restart", nargs="*", type=float, default=[4.0])
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_min_angle.csv"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax._pipeline.refit import refit

    cos_max = qemjax.Topology().cos_max  # the default run's flip rule
    best = best_peers(Path(args.peers))
    labels = ["default"] + [f"restart {k:g}x" for k in args.restart] + (["memoryless"] if args.full else [])
    rows = []
    for name, m, ratio, target, ref in cases(args.meshes, best):
        outs, secs = [], []
        t0 = time.perf_counter()
        res = qemjax.simplify((m.V, m.F), target_faces=target, late_memoryless=0)  # the summed default
        outs.append((res.vertices, res.faces))
        secs.append(time.perf_counter() - t0)
        for k in args.restart:
            t0 = time.perf_counter()
            a = qemjax.simplify((m.V, m.F), target_faces=int(k * target), refit=0, late_memoryless=0)
            b = qemjax.simplify((np.asarray(a.vertices), np.asarray(a.faces)), target_faces=target, refit=0,
                                memoryless=True, memory_weight=0.3)
            X = refit(m.V, m.F, np.asarray(b.vertices, np.float64), np.asarray(b.faces), 1, cos_max)
            outs.append((X, b.faces))
            secs.append(time.perf_counter() - t0)
        if args.full:
            t0 = time.perf_counter()
            res = qemjax.simplify((m.V, m.F), target_faces=target, memoryless=True, memory_weight=0.3)
            outs.append((res.vertices, res.faces))
            secs.append(time.perf_counter() - t0)
        row = []
        for (X, G), s in zip(outs, secs):
            d = distances(m.V, m.F, np.asarray(X, np.float64), np.asarray(G, np.int64))
            row.append((d["rms_rel"] / ref["rms_rel"], d["hausdorff_rel"] / ref["hausdorff_rel"], s))
        rows.append(row)
        print(f"{name:18s} {ratio:5g} " + "  ".join(f"{lab}: rms {a:.3f} H {b:.3f}"
                                                     for lab, (a, b, _) in zip(labels, row)), flush=True)
    print()
    for i, lab in enumerate(labels):
        print(f"{lab}: rms <= best peer in {sum(r[i][0] <= 1 for r in rows)}/{len(rows)}; Hausdorff <= best peer in "
              f"{sum(r[i][1] <= 1 for r in rows)}/{len(rows)}; seconds {sum(r[i][2] for r in rows):.1f} (cold, summed)")


if __name__ == "__main__":
    main()
