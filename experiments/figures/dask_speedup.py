"""Speed-up of `qemjax.sweep` from 1 to 2 Dask workers (and the in-process default, for comparison).

One sweep (2 shared meshes × 4 configurations × 3 targets = 24 cells, metrics on with 20 000 samples) on
a `LocalCluster(n_workers=N, threads_per_worker=1, processes=True)` for each N in ``--workers``, and in
this process without an executor. Each mode runs the sweep once cold (every worker process compiles its
own JAX kernels) and then ``--repeats`` times warm, on the same cluster; the warm median is the number to
compare. ``--ship arrays`` sends the mesh arrays with every cell's task, as `qemjax.sweep` did before it
scattered each mesh to the workers once (``--ship scatter``, the default). The machine's load average is recorded before and after each mode: other work on the machine
takes cores from the workers, so read the ratio next to it. On a 2-core machine the ideal is 2×.

Appends to ``results/dask_speedup.csv`` and prints the ratios.

    python experiments/figures/dask_speedup.py --repeats 3
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import os
import statistics
import sys
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402

import qemjax  # noqa: E402

RESULTS = EXPERIMENTS / "results"
GRID = {"boundary_weight": [1.0, 100.0], "regularize": [0.0, 0.1]}
TARGETS = [0.1, 0.05, 0.02]
METRICS = {"n_samples": 20_000}
FIELDS = ("date", "mode", "workers", "ship", "batch_size", "cells", "cold_s", "warm_median_s", "warm_times_s", "speedup_vs_1",
          "vs_in_process", "load_before", "load_after", "cpus")


@contextlib.contextmanager
def dask_cluster(n: int):
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        yield client


@contextlib.contextmanager
def in_process():
    yield None


def measure(paths: dict, executor, repeats: int, batch_size=None) -> tuple[float, list[float], int]:
    """Seconds of the cold sweep and of each warm one; the number of cells."""
    times = []
    for _ in range(1 + repeats):
        t0 = time.perf_counter()
        df = qemjax.sweep(paths, GRID, TARGETS, metrics=METRICS, executor=executor, progress=False,
                          batch_size=batch_size)
        times.append(time.perf_counter() - t0)
        assert (df["error"] == "").all(), df["error"].unique()
    return times[0], times[1:], len(df)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "homer"])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=3, help="warm runs per mode (default 3)")
    ap.add_argument("--ship", choices=["scatter", "arrays"], default="scatter",
                    help="scatter: each mesh is scattered to every worker once (qemjax.sweep's way since "
                    "_sweep._ship); arrays: the mesh arrays go with every cell's task (the way before)")
    ap.add_argument("--batch-size", type=int, default=None,
                    help="qemjax.sweep's batch_size (default: its own: EXECUTOR_BATCH cells per task, "
                    "its pieces in process); 1: one cell per task, as before batching")
    ap.add_argument("--out", default=str(RESULTS / "dask_speedup.csv"))
    args = ap.parse_args(argv)
    if args.ship == "arrays":
        qemjax._sweep.run._ship = lambda executor, loaded: loaded

    files = bench_meshes.shared_files()
    paths = {name: str(files[name]) for name in args.meshes}
    modes = [("in_process", 0, in_process)] + [("dask", n, lambda n=n: dask_cluster(n)) for n in args.workers]
    rows = []
    for mode, n, make in modes:
        load_before = os.getloadavg()[0]
        with make() as executor:
            cold, warm, cells = measure(paths, executor, args.repeats, args.batch_size)
        rows.append(dict(date=time.strftime("%Y-%m-%d %H:%M"), mode=mode, workers=n, cells=cells,
                         ship=args.ship if n else "", batch_size=args.batch_size or "default",
                         cold_s=round(cold, 3), warm_median_s=round(statistics.median(warm), 3),
                         warm_times_s=" ".join(f"{t:.3f}" for t in warm), load_before=load_before,
                         load_after=os.getloadavg()[0], cpus=os.cpu_count()))
        print(f"{mode} {n or '':>2}: cold {cold:.2f} s, warm median {statistics.median(warm):.2f} s "
              f"({rows[-1]['warm_times_s']}), load {load_before:.2f} -> {rows[-1]['load_after']:.2f}", flush=True)
    base = {r["workers"]: r["warm_median_s"] for r in rows if r["mode"] == "dask"}
    local = rows[0]["warm_median_s"]
    for r in rows:
        r["speedup_vs_1"] = round(base[1] / r["warm_median_s"], 3) if 1 in base else ""
        r["vs_in_process"] = round(local / r["warm_median_s"], 3)
    for r in rows[1:]:
        print(f"dask {r['workers']} workers: {r['speedup_vs_1']}x one worker, {r['vs_in_process']}x in process (warm)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    old = list(csv.DictReader(open(out))) if out.exists() else []  # rows of earlier runs, older columns kept
    with open(out, "w", newline="") as f:
        w = csv.DictWriter(f, FIELDS, restval="")
        w.writeheader()
        w.writerows(old + rows)
    print(f"appended {len(rows)} rows to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
