"""The measured distance with and without the re-fit's faces as seeds (`grid_nearest.nearest(seed=)`): the
same stats, and the time of the distance pass alone, warm medians.

Each case runs the default once; its measured-distance call is caught with its arguments (input, output,
samples, seeds), then timed both ways.

    python experiments/probes/distance_seeds.py --cases cow:0.1 stanford-bunny:0.1 stanford-bunny:0.01 armadillo:0.01
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1", "stanford-bunny:0.1"], help="mesh:ratio")
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    import qemjax
    from qemjax._pipeline import measure, stages

    caught = {}
    distance = measure.distance

    def catch(*a):
        caught["args"] = a
        return distance(*a)
    stages._measure.distance = catch
    print(f"# python experiments/probes/distance_seeds.py --cases {' '.join(args.cases)} --repeats {args.repeats}")
    print("| case | samples | unseeded ms | seeded ms | ratio | same stats |")
    print("|---|---|---|---|---|---|")
    for case in args.cases:
        name, ratio = case.split(":")
        bm = bench_meshes.load(name)
        qemjax.simplify((bm.V, bm.F), target_faces=round(float(ratio) * bm.n_faces))
        V, F, X, G, sampled, seeds = caught["args"]
        out = {}
        for label, s in (("unseeded", None), ("seeded", seeds)):
            ts = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                stats = distance(V, F, X, G, sampled, s)
                ts.append(time.perf_counter() - t)
            out[label] = (statistics.median(ts) * 1e3, stats)
        same = all(out["unseeded"][1][k] == out["seeded"][1][k] for k in ("distance_max", "distance_rms"))
        print(f"| {name} → {ratio} | {len(sampled[0])} | {out['unseeded'][0]:.2f} | {out['seeded'][0]:.2f} | "
              f"{out['seeded'][0] / out['unseeded'][0]:.2f} | {'yes' if same else 'NO'} |")


if __name__ == "__main__":
    main()
