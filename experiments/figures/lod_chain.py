"""LOD chains: `qemjax.lod_chain` (one run, every level replayed from its record) against one `simplify`
run per level, and against meshoptimizer's chain of calls (each level simplified from the one before, on
the same vertex buffer, as its README's LOD recipe does) and meshoptimizer's separate calls.

Times are wall-clock medians over ``--repeats`` alternating repeats in one process, after one untimed warm
call of each (qemjax: compilation). Quality: two-way surface distance of every level to the input
(`qemjax.metrics.surface_distance`, rms and Hausdorff relative to the bounding-box diagonal).
Writes ``results/lod_chain.csv`` (one row per mesh, method and level; ``chain_*_s`` are the times of all
levels together; qemjax methods carry the scheduler in their name unless it is the parallel one) and
prints a table.

    python experiments/figures/lod_chain.py --meshes stanford-bunny armadillo --repeats 3
"""
from __future__ import annotations

import argparse
import csv
import datetime
import statistics
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402
import peers  # noqa: E402

import qemjax  # noqa: E402

RESULTS = EXPERIMENTS / "results"
FIELDS = ("date", "mesh", "faces_in", "method", "ratio", "target", "faces", "chain_median_s",
          "chain_min_s", "repeats", "rms_rel", "hausdorff_rel")


def qemjax_chain(V, F, ratios, scheduler):
    chain = qemjax.lod_chain((V, F), ratios=ratios, scheduler=scheduler)
    return [(lv.vertices, lv.faces) for lv in chain.levels]


def qemjax_separate(V, F, ratios, scheduler):
    return [(r.vertices, r.faces) for r in (qemjax.simplify((V, F), ratio=x, scheduler=scheduler)
                                            for x in ratios)]


def _meshopt(indices, positions, target):
    import meshoptimizer

    dest = np.empty(indices.size, np.uint32)
    k = meshoptimizer.simplify(dest, indices, positions, target_index_count=3 * int(target),
                               target_error=peers.MESHOPT_ERROR_LIMIT)
    return dest[:k]


def meshopt_chain(V, F, ratios, scheduler=None):
    """Each level from the previous level's indices (same vertex buffer)."""
    positions = np.ascontiguousarray(V, np.float32)
    idx = np.ascontiguousarray(F.reshape(-1), np.uint32)
    out = []
    for r in sorted(ratios, reverse=True):
        idx = _meshopt(idx, positions, max(1, round(r * len(F))))
        out.append(peers.compact(V, idx.reshape(-1, 3)))
    return out


def meshopt_separate(V, F, ratios, scheduler=None):
    positions = np.ascontiguousarray(V, np.float32)
    idx = np.ascontiguousarray(F.reshape(-1), np.uint32)
    return [peers.compact(V, _meshopt(idx, positions, max(1, round(r * len(F)))).reshape(-1, 3))
            for r in sorted(ratios, reverse=True)]


METHODS = {"qemjax chain": qemjax_chain, "qemjax separate": qemjax_separate,
           "meshoptimizer chain": meshopt_chain, "meshoptimizer separate": meshopt_separate}


def _label(method, scheduler):
    """The method's name in the table: qemjax's carry the scheduler unless it is the parallel one."""
    return method if scheduler == "parallel" or not method.startswith("qemjax") else f"{method} ({scheduler})"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["stanford-bunny"])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.5, 0.25, 0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scheduler", default="parallel")
    ap.add_argument("--samples", type=int, default=200_000, help="surface samples for the distances")
    ap.add_argument("--out", default=str(RESULTS / "lod_chain.csv"))
    args = ap.parse_args(argv)
    ratios = sorted(args.ratios, reverse=True)
    rows = []
    today = datetime.date.today().isoformat()
    for name in args.meshes:
        mesh = bench_meshes.load(name)
        V, F = mesh.V, mesh.F
        for fn in METHODS.values():  # warm: compilation, caches
            fn(V, F, ratios, args.scheduler)
        times = {k: [] for k in METHODS}
        levels = {}
        for rep in range(args.repeats):
            order = list(METHODS) if rep % 2 == 0 else list(METHODS)[::-1]
            for k in order:
                t0 = time.perf_counter()
                levels[k] = METHODS[k](V, F, ratios, args.scheduler)
                times[k].append(time.perf_counter() - t0)
        for k in METHODS:
            for r, (Vl, Fl) in zip(ratios, levels[k]):
                d = qemjax.metrics.surface_distance((V, F), (Vl, Fl), n_samples=args.samples)
                rows.append(dict(date=today, mesh=name, faces_in=len(F), method=_label(k, args.scheduler), ratio=r,
                                 target=max(1, round(r * len(F))), faces=len(Fl),
                                 chain_median_s=round(statistics.median(times[k]), 4),
                                 chain_min_s=round(min(times[k]), 4), repeats=args.repeats,
                                 rms_rel=f"{d['rms_rel']:.4g}", hausdorff_rel=f"{d['hausdorff_rel']:.4g}"))
        print(f"\n{name}: {len(F)} faces, {args.scheduler} scheduler, medians of {args.repeats}")
        print(f"{'method':24s} {'all levels s':>12s}  " + "  ".join(f"rms@{r:g}" for r in ratios))
        for k in METHODS:
            label = _label(k, args.scheduler)
            rms = [row["rms_rel"] for row in rows if row["mesh"] == name and row["method"] == label]
            print(f"{k:24s} {statistics.median(times[k]):12.3f}  " + "  ".join(f"{x:>8s}" for x in rms))
    out = Path(args.out)
    new = not out.exists()
    with out.open("a", newline="") as f:
        w = csv.DictWriter(f, FIELDS)
        if new:
            w.writeheader()
        w.writerows(rows)
    print(f"\nappended {len(rows)} rows to {out}")


if __name__ == "__main__":
    main()
