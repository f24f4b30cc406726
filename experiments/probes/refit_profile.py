"""Where the re-fit's time goes: one warm `simplify` with ``refit=1`` under cProfile, beside the same run
without it (issue 32: the re-fit is what keeps the accurate ranks above 1.5x the default's time at 10 %).

    python experiments/probes/refit_profile.py --mesh stanford-bunny --ratio 0.1

Prints the two warm wall times (median of 3) and the cumulative times of the re-fit's stages
(`qemjax._pipeline.refit.refit`, the nearest-triangle search and its index) in the profiled run.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
import meshes  # noqa: E402

import qemjax  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="stanford-bunny")
    ap.add_argument("--ratio", type=float, default=0.1)
    args = ap.parse_args(argv)
    m = meshes.load(args.mesh)
    t = max(4, round(args.ratio * m.n_faces))
    runs = {"default": {}, "refit=1": {"refit": 1}}
    for kw in runs.values():
        qemjax.simplify((m.V, m.F), target_faces=t, **kw)  # warm
    times = {k: [] for k in runs}
    for _ in range(3):
        for k, kw in runs.items():
            t0 = time.perf_counter()
            qemjax.simplify((m.V, m.F), target_faces=t, **kw)
            times[k].append(time.perf_counter() - t0)
    for k, v in times.items():
        print(f"{args.mesh} -> {t} faces, {k}: warm median {np.median(v):.3f} s")
    pr = cProfile.Profile()
    pr.enable()
    qemjax.simplify((m.V, m.F), target_faces=t, refit=1)
    pr.disable()
    stats = pstats.Stats(pr).stats
    total = sum(v[3] for (f, _, name), v in stats.items() if name == "simplify" and f.endswith("_pipeline/api.py"))
    for label, (file, name) in {"simplify (profiled)": ("_pipeline/api.py", "simplify"),
                                "scheduler run": ("parallel.py", "run"),
                                "refit": ("_pipeline/refit.py", "refit"),
                                "  nearest_triangles": ("_mesh/nearest.py", "nearest_triangles"),
                                "    grid index build": ("_mesh/nearest.py", "__init__"),
                                "    grid query": ("_mesh/nearest.py", "settle"),
                                "    KD-tree queries": ("_mesh/nearest.py", "query")}.items():
        cum = max((v[3] for (f, _, n), v in stats.items() if f.endswith(file) and n == name), default=0.0)
        print(f"{label:24s} {cum:.3f} s  ({cum / total:.0%})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
