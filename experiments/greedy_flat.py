"""The greedy queue on flat grids (every interior cost ties at 0): faces, rejected contractions, seconds.

    python experiments/greedy_flat.py                 # 50×50 and 100×100 grids (and a bumpy 50×50) to 1 %
"""
from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import qemjax
from qemjax import shapes


def main(sizes=(50, 100)):
    warnings.simplefilter("ignore")
    for n in sizes:
        for bumpy in (False, True):
            if bumpy and n != sizes[0]:
                continue
            V, F = shapes.grid(n)
            if bumpy:
                V = V + np.c_[np.zeros((len(V), 2)), 0.02 * np.random.default_rng(0).normal(size=len(V))]
            t = time.perf_counter()
            r = qemjax.simplify((V, F), ratio=0.01, scheduler="greedy")
            print(f"{'bumpy' if bumpy else 'flat'} grid {n}x{n}: {len(F)} -> {len(r.faces)} faces, "
                  f"{r.stats['rejected']} rejected, {time.perf_counter() - t:.1f} s, {r.stop_reason}", flush=True)


if __name__ == "__main__":
    main(tuple(int(a) for a in sys.argv[1:]) or (50, 100))
