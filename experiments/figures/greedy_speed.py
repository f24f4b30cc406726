"""Warm wall time of the greedy scheduler (``scheduler="greedy"``) and a hash of its output, per mesh; with
``--rev``, the package at that git revision runs in the same process, alternating with the working tree's,
so both see the same machine state (and the hashes show whether the outputs are the same).

    python experiments/figures/greedy_speed.py                          # cow and stanford-bunny -> 10 %
    python experiments/figures/greedy_speed.py --rev a9c2f4d --repeats 3
    python experiments/figures/greedy_speed.py --rev eee561e --non-manifold --method classic   # preserve_topology=False
    python experiments/figures/greedy_speed.py --rev eee561e --meshes cow.obj --locked-share 0.01 --weights  # locks
    python experiments/figures/greedy_speed.py --rev 1843c68 --meshes spot/spot.obj cow.obj --attributes uv  # seams

The hash is sha256 over the output vertices, faces, history pairs, positions and costs, and the run's stop
reason, contraction count and rejections by rule (the rules that refused some pair; hashes from before
2026-11-24 19:30 UTC also counted rules at zero, so they differ from these), and with ``--attributes`` the
output's wedge values and wedge faces. Meshes come from ../shared/meshes (absent ones skip, and so do
meshes without the attributes asked for).
Each version simplifies each mesh once first (compilation, caches), outside the timings. Wall and process
CPU time are both reported (medians): on a shared machine the CPU time is the steadier of the two.
"""
from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]  # this checkout's qemjax

import qemjax  # noqa: E402
from ab_compare import load_old  # noqa: E402

SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"


def digest(res) -> str:
    h = hashlib.sha256()
    for name, a in (("vertices", res.vertices), ("faces", res.faces), ("pairs", res.history.pairs),
                    ("positions", res.history.positions), ("costs", res.history.costs)):
        a = np.ascontiguousarray(a)
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    # rules that refused nothing are left out: a version with a new rule (main's 'locked', 0) hashes the same
    for name in ("uv", "colors", "normals", "wedge_faces"):  # kept attributes (runs without: none)
        a = getattr(res, name, None)
        if a is not None:
            a = np.ascontiguousarray(a)
            h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
            h.update(a.tobytes())
    refused = sorted((k, v) for k, v in res.stats["rejected_by"].items() if v)
    h.update(repr((res.stop_reason, res.stats["contractions"], refused)).encode())
    return h.hexdigest()[:16]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["cow.obj", "stanford-bunny.obj"])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per mesh and version (median reported)")
    ap.add_argument("--rev", default=None, help="also run the package at this git revision")
    ap.add_argument("--method", default=None, help="the cost method (default: simplify's)")
    ap.add_argument("--non-manifold", action="store_true", help="preserve_topology=False")
    ap.add_argument("--locked-share", type=float, default=0.0,
                    help="lock this share of the input vertices (random, seed 0)")
    ap.add_argument("--weights", action="store_true", help="vertex_weights: random in [0.5, 2) (seed 1)")
    ap.add_argument("--attributes", default=None, help="attributes to keep (e.g. uv); meshes without them skip")
    args = ap.parse_args()
    kw = ({} if args.method is None else {"method": args.method}) | (
        {"preserve_topology": False} if args.non_manifold else {}) | (
        {} if args.attributes is None else {"attributes": args.attributes})
    warnings.simplefilter("ignore")
    versions = [("new", qemjax)] + ([(args.rev, load_old(args.rev))] if args.rev else [])
    print(f"qemjax from {Path(qemjax.__file__).parent}; ratio {args.ratio}, {args.repeats} warm runs each; {kw}; "
          f"locked share {args.locked_share}, weights {args.weights}")
    for mesh in args.meshes:
        path = SHARED / mesh
        if not path.exists():
            print(f"SKIP {mesh} ({path} absent)")
            continue
        n = len(qemjax.load(str(path)).vertices) if args.locked_share or args.weights else 0
        if args.locked_share:
            kw["locked"] = np.random.default_rng(0).choice(n, int(round(args.locked_share * n)), replace=False)
        if args.weights:
            kw["vertex_weights"] = 0.5 + 1.5 * np.random.default_rng(1).random(n)
        times = {label: [] for label, _ in versions}
        cpus = {label: [] for label, _ in versions}
        hashes = {}
        if args.attributes:
            try:
                qemjax.simplify(str(path), ratio=0.99, attributes=args.attributes)
            except ValueError as e:
                print(f"SKIP {mesh} ({e})")
                continue
        for label, pkg in versions:  # warm-up: compilation and file caches
            res = pkg.simplify(str(path), ratio=args.ratio, scheduler="greedy", **kw)
            hashes[label] = digest(res)
            faces = (len(res.faces), res.stats["contractions"])
        for _ in range(args.repeats):
            for label, pkg in versions:
                t, c = time.perf_counter(), time.process_time()
                res = pkg.simplify(str(path), ratio=args.ratio, scheduler="greedy", **kw)
                times[label].append(time.perf_counter() - t)
                cpus[label].append(time.process_time() - c)
                if digest(res) != hashes[label]:
                    print(f"  {label}: output changed between runs ({hashes[label]} -> {digest(res)})")
        for label, _ in versions:
            t = times[label]
            print(f"{mesh:20s} {label:8s} warm median {statistics.median(t):6.2f} s  (min {min(t):.2f}, "
                  f"max {max(t):.2f})  cpu {statistics.median(cpus[label]):6.2f} s  faces {faces[0]}, "
                  f"contractions {faces[1]}  sha256 {hashes[label]}",
                  flush=True)
        if len(versions) == 2:
            (a, ta), (b, tb) = [(k, statistics.median(v)) for k, v in times.items()]
            ca, cb = (statistics.median(cpus[k]) for k in (a, b))
            same = "same output" if hashes[a] == hashes[b] else "OUTPUTS DIFFER"
            print(f"{'':20s} {b} / {a}: wall {tb / ta:.1f}x, cpu {cb / ca:.1f}x  ({same})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
