"""Precision beside far-away parts: a unit icosphere simplified alone, shifted by 1e7, and next to one
triangle 1e6 away; how far its contracted vertices end up from the sphere (radius range), for the working
tree and (``--rev``) an older revision in the same process.

    python experiments/figures/part_precision.py --rev 02a1390
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
from ab_compare import load_old  # noqa: E402

import qemjax
from qemjax import shapes


def cases(V, F):
    yield "alone", V, F, 0.0
    yield "offset 1e7", V + 1e7, F, 1e7
    for off in (0.0, 1e7):
        tri = np.array([[1e6, 0, 0], [1e6 + 1, 0, 0], [1e6, 1, 0]]) + off
        yield f"outlier 1e6{' + offset 1e7' if off else ''}", np.vstack([V + off, tri]), \
            np.vstack([F, len(V) + np.array([[0, 1, 2]])]), off


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default=None, help="also run the package at this git revision")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    versions = [("new", qemjax)] + ([(args.rev, load_old(args.rev))] if args.rev else [])
    V, F = shapes.icosphere(4)
    for scheduler in ("parallel", "greedy"):
        for name, V2, F2, off in cases(V, F):
            for label, pkg in versions:
                r = pkg.simplify((V2, F2), target_faces=1024 + (len(F2) > len(F)), scheduler=scheduler)
                moved = np.isin(r.source_vertices, r.history.pairs[:, 0])
                rad = np.linalg.norm(r.vertices[moved] - off, axis=1)
                rad = rad[rad < 2]
                print(f"{scheduler:8s} {name:26s} {label:8s} contracted vertices' radii "
                      f"{rad.min():.4f}..{rad.max():.4f} (max |r-1| {np.abs(rad - 1).max():.2e})", flush=True)


if __name__ == "__main__":
    main()
