"""Peak memory of one simplification: armadillo Loop-subdivided ×64 (≈5.5 M faces) to 1 %.

Run it as its own process (the peak is the process's high-water mark, loading included):

    python experiments/figures/memory_peak.py [--mesh armadillo-x64] [--ratio 0.01]

Prints and appends to results/memory.csv: faces in/out, time, peak RSS (GiB) and RSS after loading; also
prints the sha256 of the output arrays (`memory_profile.output_hash`: a memory change must keep it).
"""
from __future__ import annotations

import argparse
import csv
import resource
import sys
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

from figures.memory_profile import output_hash, rss_gib  # noqa: E402  (numpy only: jax starts after the mesh loads)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--mesh", default="armadillo-x64")
    ap.add_argument("--ratio", type=float, default=0.01)
    ap.add_argument("--scheduler", default="parallel")
    ap.add_argument("--no-measure", action="store_true", help="simplify(measure=False): no measured distance")
    args = ap.parse_args(argv)
    import meshes  # experiments/meshes.py: builds and caches the subdivided armadillo

    import qemjax

    bm = meshes.load(args.mesh)
    V, F = bm.V, bm.F
    after_load = rss_gib()
    t0 = time.perf_counter()
    r = qemjax.simplify((V, F), ratio=args.ratio, scheduler=args.scheduler, measure=False if args.no_measure else None)
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    row = {"mesh": args.mesh, "faces_in": len(F), "faces_out": len(r.faces), "ratio": args.ratio,
           "scheduler": args.scheduler, "time_s": round(dt, 2), "compile_s": round(r.stats["compile_s"], 2),
           "rounds": r.stats["rounds"], "rss_after_load_gib": round(after_load, 2),
           "peak_rss_gib": round(peak, 2), "measured": r.stats.get("distance_max") is not None}
    print(row)
    print("output sha256", output_hash(r))
    out = EXPERIMENTS / "results" / "memory.csv"
    new = not out.exists()
    if not new:  # a file from before a column was added: rewrite it with the new header (old rows: empty there)
        with open(out, newline="") as f:
            old = list(csv.DictReader(f))
        if old and set(row) - set(old[0]):
            with open(out, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(row))
                w.writeheader()
                w.writerows(old)
    with open(out, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


if __name__ == "__main__":
    main()
