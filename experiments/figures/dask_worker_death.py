"""Issue 41: a Dask worker that dies mid-sweep must never lose the sweep. Each run starts a 2-worker
`LocalCluster` (one thread each), runs a 24-cell sweep (cow and homer, or generated meshes without
../shared/meshes, × boundary_weight {1, 100} × regularize {0, 0.1} × 3 targets, metrics off) with ``out=``
a CSV, and SIGKILLs one worker once the first rows are in the file. A run passes when the sweep returns
all 24 rows, none with an error, each equal (output hash) to the in-process sweep, and the file holds them.

    python experiments/figures/dask_worker_death.py --runs 10

Prints one line per run and the count; appends to results/dask_worker_death.csv.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]
SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"

import csv_rows  # noqa: E402
import qemjax  # noqa: E402
from qemjax import shapes  # noqa: E402

GRID = {"boundary_weight": [1.0, 100.0], "regularize": [0.0, 0.1]}
TARGETS = [0.1, 0.05, 0.02]


def _rows(path: Path) -> int:
    try:
        return max(len(path.read_text().splitlines()) - 1, 0)
    except FileNotFoundError:
        return 0


def one_run(meshes, want, folder: Path) -> dict:
    from distributed import Client, LocalCluster

    out = folder / "s.csv"
    if out.exists():
        out.unlink()
    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        pid = next(iter(client.run(os.getpid).values()))
        killed = []

        def killer():
            t = time.monotonic()
            while _rows(out) < 2 and time.monotonic() - t < 300:
                time.sleep(0.02)
            os.kill(pid, signal.SIGKILL)
            killed.append(_rows(out))

        with concurrent.futures.ThreadPoolExecutor(1) as side:
            job = side.submit(killer)
            try:
                df = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, executor=client, out=out, progress=False)
                err = ""
            except Exception as exc:  # noqa: BLE001 - a lost sweep is what this counts
                df, err = None, f"{type(exc).__name__}: {exc}"[:200]
            job.result()
    ok = (df is not None and len(df) == len(want) and (df["error"] == "").all()
          and list(df["result_sha256"]) == list(want["result_sha256"]) and _rows(out) == len(want))
    return {"ok": ok, "rows_when_killed": killed[0] if killed else None, "rows": 0 if df is None else len(df),
            "failed_rows": 0 if df is None else int((df["error"] != "").sum()), "file_rows": _rows(out),
            "seconds": round(time.perf_counter() - t0, 1), "error": err}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=10)
    args = ap.parse_args(argv)
    if (SHARED / "cow.obj").exists():
        meshes = {"cow": str(SHARED / "cow.obj"), "homer": str(SHARED / "homer.obj")}
    else:
        meshes = {"ball": shapes.bumpy_sphere(4), "torus": shapes.torus(n_major=64, n_minor=32)}
    want = qemjax.sweep(meshes, GRID, TARGETS, metrics=False, progress=False)
    rows = []
    with tempfile.TemporaryDirectory(prefix="qemjax-dask-death-") as tmp:
        for i in range(args.runs):
            r = one_run(meshes, want, Path(tmp))
            r = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"), "run": i + 1,
                 **r, "load_avg": round(os.getloadavg()[0], 2),
                 "command": f"python experiments/figures/dask_worker_death.py --runs {args.runs}"}
            print(r, flush=True)
            rows.append(r)
    print(f"{sum(r['ok'] for r in rows)} of {len(rows)} runs kept every row")
    csv_rows.append(EXPERIMENTS / "results" / "dask_worker_death.csv", rows)


if __name__ == "__main__":
    main()
