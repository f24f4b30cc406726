"""Issue 41's two sweeps, re-run as a user meets them: `qemjax sweep big.toml` on three ~100 k-face shared
meshes (armadillo, stanford-bunny, bumpy-cube) × 4 or 8 configurations × 2 targets, metrics with 20 000
samples, in its own process. Measures when the first row reaches the CSV, sends Ctrl-C (SIGINT) at
``--stop-at`` seconds, and records the seconds until the process exits, its exit code and last line, the rows
kept; then re-runs the same command to the end (its time, the rows it skipped, whether the kept rows stayed
byte for byte). A fresh compilation-cache folder per sweep (the first run compiles; the rerun loads).

    python experiments/probes/sweep_interrupt.py --configs 4 --stop-at 45
    python experiments/probes/sweep_interrupt.py --configs 8 --stop-at 45

Prints the rows and appends them to results/sweep_interrupt.csv.
"""
from __future__ import annotations

import argparse
import datetime
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
ROOT = EXPERIMENTS.parent
sys.path.insert(0, str(EXPERIMENTS))
import csv_rows  # noqa: E402
SHARED = ROOT.parent / "shared" / "meshes"
MESHES = ("armadillo.obj", "stanford-bunny.obj", "bumpy-cube.obj")
GRIDS = {4: 'boundary_weight = [1.0, 100.0]\nregularize = [0.0, 0.1]\n',
         8: 'boundary_weight = [1.0, 100.0]\nregularize = [0.0, 0.1]\nplacement = ["optimal", "endpoints"]\n'}


def _rows(path: Path) -> list[str]:
    try:
        return path.read_text().splitlines()[1:]
    except FileNotFoundError:
        return []


def run(folder: Path, env: dict, stop_at: float | None) -> dict:
    table = folder / "big.csv"
    cmd = [sys.executable, "-m", "qemjax", "sweep", str(folder / "big.toml"), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first, sent, before = None, None, len(_rows(table))
    while proc.poll() is None:
        now = time.perf_counter() - t0
        if first is None and len(_rows(table)) > before:
            first = now
        if stop_at is not None and sent is None and now >= stop_at:
            proc.send_signal(signal.SIGINT)
            sent = now
        time.sleep(0.05)
    end = time.perf_counter() - t0
    out, err = proc.communicate()
    last = (err.strip().splitlines() or [""])[-1] if proc.returncode else out.strip().splitlines()[-1]
    return {"rc": proc.returncode, "first_row_s": None if first is None else round(first, 1),
            "sigint_at_s": None if sent is None else round(sent, 1),
            "stop_s": None if sent is None else round(end - sent, 1), "wall_s": round(end, 1),
            "rows": len(_rows(table)), "last_line": last}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", type=int, choices=sorted(GRIDS), default=4)
    ap.add_argument("--stop-at", type=float, default=45.0)
    args = ap.parse_args(argv)
    out_rows = []
    with tempfile.TemporaryDirectory(prefix="qemjax-interrupt-") as tmp:
        folder = Path(tmp)
        meshes = ", ".join(f'"{SHARED / m}"' for m in MESHES)
        (folder / "big.toml").write_text(f'meshes = [{meshes}]\ntargets = [0.1, 0.02]\nout = "big.csv"\n'
                                         f'[metrics]\nn_samples = 20000\n[grid]\n{GRIDS[args.configs]}')
        env = dict(os.environ, PYTHONPATH=str(ROOT), QEMJAX_CACHE_DIR=str(folder / "cache"))
        env.pop("QEMJAX_NO_CACHE", None)
        first = run(folder, env, args.stop_at)
        kept = _rows(folder / "big.csv")
        second = run(folder, env, None)
        after = _rows(folder / "big.csv")
        it = iter(after)
        untouched = all(any(r == k for r in it) for k in kept)
        stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M")
        for label, r in (("ctrl-c", first), ("rerun", second)):
            out_rows.append({"date": stamp, "cells": 3 * args.configs * 2, "run": label, **r,
                             "kept_rows_untouched": untouched if label == "rerun" else "",
                             "load_avg": round(os.getloadavg()[0], 2),
                             "command": f"python experiments/probes/sweep_interrupt.py --configs {args.configs} "
                                        f"--stop-at {args.stop_at:g}"})
    for r in out_rows:
        print(r)
    csv_rows.append(EXPERIMENTS / "results" / "sweep_interrupt.csv", out_rows)


if __name__ == "__main__":
    main()
