"""numpy's ``V.min(0)`` and ``V.max(0)`` on a mesh's (n,3) vertices against the compiled loop that replaces
them (`qemjax._mesh.box_bounds.row_bounds`), warm medians, and whether they agree bit for bit.

    python experiments/figures/bounds_cost.py --meshes cow armadillo-x16
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402
from machine import median_time  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "armadillo-x16"])
    ap.add_argument("--repeats", type=int, default=21)
    args = ap.parse_args()
    from qemjax._mesh.box_bounds import row_bounds

    print(f"# python experiments/figures/bounds_cost.py --meshes {' '.join(args.meshes)}")
    print("| mesh | vertices | numpy min(0) + max(0) ms | row_bounds ms | ns a value, numpy | same bits |")
    print("|---|---|---|---|---|---|")
    for name in args.meshes:
        V = np.ascontiguousarray(bench_meshes.load(name).V, np.float64)
        t_np = median_time(lambda: (V.min(0), V.max(0)), args.repeats)
        t_jit = median_time(lambda: row_bounds(V), args.repeats)
        lo, hi = row_bounds(V)
        same = all(np.array_equal(a.view(np.int64), b.view(np.int64))  # bits: signed zeros and NaNs too
                   for a, b in ((lo, V.min(0)), (hi, V.max(0))))
        print(f"| {name} | {len(V)} | {t_np * 1e3:.3f} | {t_jit * 1e3:.3f} | {t_np / (2 * V.size) * 1e9:.1f} | "
              f"{same} |")


if __name__ == "__main__":
    main()
