"""Speed against the fast peers, with the machine's noise taken out as far as one process can.

Single benchmark runs on a shared 2-core VM move by 10-30 % from run to run (peers included), so one
timing per method says little about a ratio. This script runs qemjax (warm: one untimed call first) and
the chosen peers in turn, ``--repeats`` times, in one process, alternating the order each repeat, and
reports each method's median and minimum and the ratios of the medians. Appends one row per method to
``results/speed_ratio.csv``.

    python experiments/figures/speed_ratio.py --mesh armadillo-x16 --ratio 0.01 --repeats 5
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
import peers  # noqa: E402

RESULTS = EXPERIMENTS / "results"
FIELDS = ("date", "mesh", "faces_in", "ratio", "target", "method", "repeats", "median_s", "min_s",
          "median_vs_qemjax", "times_s")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", default="armadillo-x16")
    p.add_argument("--ratio", type=float, default=0.01)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--peers", nargs="+", default=["meshoptimizer", "fast-simplification", "pyfqmr"],
                   choices=sorted(peers.PEERS))
    p.add_argument("--methods", nargs="+", default=["default", "classic"],
                   help="qemjax methods or presets to time (the first is the one the ratios are against)")
    p.add_argument("--out", type=Path, default=RESULTS / "speed_ratio.csv")
    args = p.parse_args(argv)

    import qemjax

    mesh = bench_meshes.load(args.mesh)
    target = max(4, round(args.ratio * mesh.n_faces))

    def run_qemjax(method):
        t0 = time.perf_counter()
        qemjax.simplify((mesh.V, mesh.F), target_faces=target, method=method)
        return time.perf_counter() - t0

    runners = {f"qemjax-{m}": (lambda m=m: run_qemjax(m)) for m in args.methods}
    first = f"qemjax-{args.methods[0]}"
    for name in args.peers:
        runners[name] = lambda name=name: peers.run_peer(name, mesh.V, mesh.F, target)[2]
    for run in runners.values():  # compile / warm up, untimed
        run()
    times = {name: [] for name in runners}
    for i in range(args.repeats):
        order = list(runners) if i % 2 == 0 else list(reversed(list(runners)))
        for name in order:
            times[name].append(runners[name]())
        print(f"repeat {i + 1}: " + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in times.items()), flush=True)

    med = {k: float(np.median(v)) for k, v in times.items()}
    rows = []
    date = time.strftime("%Y-%m-%d")
    for name, ts in times.items():
        rows.append({"date": date, "mesh": args.mesh, "faces_in": mesh.n_faces, "ratio": args.ratio,
                     "target": target, "method": name, "repeats": args.repeats,
                     "median_s": round(med[name], 3), "min_s": round(min(ts), 3),
                     "median_vs_qemjax": round(med[name] / med[first], 3),
                     "times_s": " ".join(f"{t:.3f}" for t in ts)})
    print(f"\n{args.mesh} ({mesh.n_faces} faces) -> {target} faces, {args.repeats} repeats, one process")
    print(f"| method | median s | min s | {first} / method (medians) |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r['method']} | {med[r['method']]:.4f} | {min(times[r['method']]):.4f} | "
              f"{med[first] / med[r['method']]:.2f} |")
    new = not args.out.exists()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        if new:
            w.writeheader()
        w.writerows(rows)
    print(f"appended to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
