"""Warm time per contraction of the greedy queue (``scheduler="greedy"``) for the methods that run it one
contraction at a time, against the default method's compiled batches, on the same meshes in one process.

The default method prices a pair from its two state rows, so the queue runs in verified batches with its
host side compiled (`qemjax._schedulers.greedy.batches`). The others here re-price a contraction's whole
1-ring or rebuild state around it (ESQEM's curvature, the area difference, memoryless QEM, and the
``regularize`` and ``area_weight`` terms), and run the loop of `qemjax._schedulers.greedy`: a few device
calls and a few hundred host operations per contraction.

Time per contraction = median warm wall time of ``qemjax.simplify`` / ``res.stats["contractions"]``. ESQEM
with its default ``split_factor`` simplifies past the target (`qemjax._pipeline.split.plan`: to the target
to count the faces splitting would add, then on to the reduced target). The greedy queue goes on from its
first result where nothing on the way depended on the target, else it runs again from the input while its
stats count the second run's contractions only (then the figure is about twice its queue's);
``esqem(split_factor=None)`` runs the queue once. With ``--rev REV`` the package at that git revision runs
the same cases in the same process, alternating with this checkout's, and the output hashes say whether
both give the same bits.

    python experiments/figures/greedy_ring_cost.py                      # bumpy sphere (5,120 faces), cow, fandisk
    python experiments/figures/greedy_ring_cost.py --meshes bumpy --repeats 3 --rev 9aab674
"""
from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]  # this checkout's qemjax

import qemjax  # noqa: E402
from machine import cpu_model  # noqa: E402

SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"
METHODS = {  # label -> method, built from the package that runs it
    "default": lambda q: "default",
    "esqem": lambda q: "esqem",
    "esqem(split_factor=None)": lambda q: q.ESQEM(split_factor=None),
    "area": lambda q: "area",
    "qem(memoryless=True)": lambda q: q.QEM(memoryless=True),
    "qem(regularize=1.0)": lambda q: q.QEM(regularize=1.0),
    "qem(area_weight=1.0)": lambda q: q.QEM(area_weight=1.0),
}


def mesh_of(name: str):
    if name == "bumpy":
        m = qemjax.shapes.bumpy_sphere(4)  # 5,120 faces: the mesh `qemjax examples` writes as bumpy.obj
        return np.asarray(m.vertices), np.asarray(m.faces)
    path = SHARED / name
    return str(path) if path.exists() else None


def digest(res) -> str:
    h = hashlib.sha256()
    for a in (res.vertices, res.faces):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:12]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["bumpy", "cow.obj", "fandisk.obj"])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=1, help="timed runs per case (median), after one warm run")
    ap.add_argument("--rev", default=None, help="also run the package at this git revision")
    args = ap.parse_args(argv)
    versions = [("this checkout", qemjax)]
    if args.rev:
        from ab_compare import load_old
        versions.append((args.rev, load_old(args.rev)))
    print(f"cpu: {cpu_model()}; ratio {args.ratio}, scheduler='greedy', warm, median of {args.repeats}")
    print(f"{'mesh':12s} {'method':26s} {'version':14s} {'contr':>6s} {'wall s':>8s} {'ms/contr':>9s} "
          f"{'x default':>9s}  output")
    for name in args.meshes:
        mesh = mesh_of(name)
        if mesh is None:
            print(f"{name}: not found, skipped")
            continue
        base = {}
        for label in args.methods:
            for vname, pkg in versions:
                kw = dict(ratio=args.ratio, method=METHODS[label](pkg), scheduler="greedy")
                pkg.simplify(mesh, **kw)  # warm: compilations and caches
                ts = []
                for _ in range(args.repeats):
                    t = time.perf_counter()
                    res = pkg.simplify(mesh, **kw)
                    ts.append(time.perf_counter() - t)
                wall = statistics.median(ts)
                n = res.stats["contractions"]
                per = 1e3 * wall / max(n, 1)
                if label == "default":
                    base[vname] = per
                ratio = per / base[vname] if vname in base else float("nan")
                print(f"{name:12s} {label:26s} {vname:14s} {n:6d} {wall:8.2f} {per:9.3f} {ratio:9.1f}  "
                      f"{digest(res)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
