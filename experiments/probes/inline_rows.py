"""When the host worker thread pays: `select.INLINE_ROWS` (work on fewer rows runs on the calling thread)
at several values, on meshes of several sizes, in one process, alternating, outputs checked identical.

The worker overlaps the link test and the edge update with the main thread's face work. Handing it work
costs a wake-up on the other core (tens of µs on a VM), which a small mesh's passes do not repay. Prints
per mesh and ratio the median and minimum wall and CPU time of warm `simplify` calls for each value, and
each value's median over the first one's; ``--batch`` adds `simplify_batch` of sweep_bench's 64 ``qem``
configurations of the cow. Appends to ``results/inline_rows.csv``.

    python experiments/probes/inline_rows.py --values 0 32768 inf --meshes cow stanford-bunny armadillo --repeats 9
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import statistics
import sys
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from ab_compare import cpu_time, digest  # noqa: E402

import qemjax  # noqa: E402
from qemjax._schedulers import select  # noqa: E402

RESULTS = EXPERIMENTS / "results"
FIELDS = ("date", "mesh", "faces_in", "ratio", "case", "inline_rows", "repeats", "median_s", "min_s",
          "median_cpu_s", "vs_first", "load_avg")


def _value(text: str) -> int:
    return sys.maxsize if text == "inf" else int(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--values", nargs="+", default=["0", "32768", "inf"],
                    help="INLINE_ROWS values (0: always the worker; inf: never)")
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny", "armadillo"])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1])
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--batch", action="store_true", help="also the 64-configuration batch of the cow")
    args = ap.parse_args(argv)
    values = [_value(v) for v in args.values]
    cases = []
    for name in args.meshes:
        m = bench_meshes.load(name)
        for r in args.ratios:
            cases.append((name, m.n_faces, r, "simplify", lambda m=m, r=r: [qemjax.simplify((m.V, m.F), ratio=r)]))
    if args.batch:
        from figures.sweep_bench import GRIDS
        from qemjax._sweep.run import expand_grid
        cow = qemjax.load(bench_meshes.shared_files()["cow"])
        configs = [dict(c, ratio=0.1) for c in expand_grid(GRIDS["qem"])]
        cases.append(("cow", len(cow.faces), 0.1, "batch-64", lambda: qemjax.simplify_batch(cow, configs)))
    default = select.INLINE_ROWS
    rows = []
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
    print(f"# python experiments/probes/inline_rows.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    print(f"# {date} UTC, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}")
    try:
        for name, faces, r, kind, fn in cases:
            ref = None
            for v in values:  # warm, and the outputs must not depend on where the work ran
                select.INLINE_ROWS = v
                out = [digest(x) for x in fn()]
                if ref is None:
                    ref = out
                elif out != ref:
                    raise SystemExit(f"{name} @ {r}: INLINE_ROWS={v} changed the output")
            t = {v: [] for v in values}
            for i in range(args.repeats):
                for v in (values if i % 2 == 0 else values[::-1]):
                    select.INLINE_ROWS = v
                    c0, w0 = cpu_time(), time.perf_counter()
                    fn()
                    t[v].append((time.perf_counter() - w0, cpu_time() - c0))
            first = statistics.median(w for w, _ in t[values[0]])
            for v in values:
                med = statistics.median(w for w, _ in t[v])
                row = dict(date=date, mesh=name, faces_in=faces, ratio=r, case=kind,
                           inline_rows="inf" if v == sys.maxsize else v, repeats=args.repeats,
                           median_s=round(med, 4), min_s=round(min(w for w, _ in t[v]), 4),
                           median_cpu_s=round(statistics.median(c for _, c in t[v]), 4),
                           vs_first=round(med / first, 3), load_avg=round(os.getloadavg()[0], 2))
                rows.append(row)
                print(f"{name:16s} {faces:8d} {r:5.3f} {kind:9s} INLINE_ROWS={row['inline_rows']!s:>8}: "
                      f"median {med:.4f} s (min {row['min_s']:.4f}, CPU {row['median_cpu_s']:.4f}) "
                      f"{row['vs_first']:.3f}x")
    finally:
        select.INLINE_ROWS = default
    path = RESULTS / "inline_rows.csv"
    new = not path.exists()
    with open(path, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        if new:
            w.writeheader()
        w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
