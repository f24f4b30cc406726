"""The greedy queue on flat grids (every interior cost ties at 0) and on a bumpy one: faces, rejected
contractions, seconds; with ``--rev``, the package at that git revision runs each case right after the
working tree's (same process, same machine state).

    python experiments/probes/greedy_flat.py                      # 50×50 and 100×100 grids (and a bumpy 50×50) to 1 %
    python experiments/probes/greedy_flat.py 50 --rev 02a1390     # old against new
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
from ab_compare import load_old  # noqa: E402

import qemjax
from qemjax import shapes


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=[50, 100])
    ap.add_argument("--rev", default=None, help="also run the package at this git revision")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    versions = [("new", qemjax)] + ([(args.rev, load_old(args.rev))] if args.rev else [])
    for label, pkg in versions:  # compile first, outside the timings
        pkg.simplify(shapes.grid(8), ratio=0.2, scheduler="greedy")
    for n in args.sizes:
        for bumpy in (False, True):
            if bumpy and n != args.sizes[0]:
                continue
            V, F = shapes.grid(n)
            if bumpy:
                V = V + np.c_[np.zeros((len(V), 2)), 0.02 * np.random.default_rng(0).normal(size=len(V))]
            for label, pkg in versions:
                t, c = time.perf_counter(), sum(os.times()[:2])
                r = pkg.simplify((V, F), ratio=0.01, scheduler="greedy")
                cpu = sum(os.times()[:2]) - c
                print(f"{label:8s} {'bumpy' if bumpy else 'flat'} grid {n}x{n}: {len(F)} -> {len(r.faces)} faces, "
                      f"{r.stats['rejected']} rejected, {time.perf_counter() - t:.1f} s ({cpu:.1f} s CPU), {getattr(r, 'stop_reason', '-')}", flush=True)


if __name__ == "__main__":
    main()
