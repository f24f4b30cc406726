"""Methods on a mesh with two vertices of high valence (`shapes.double_cone`, a fan-triangulated cap taken to
the extreme), in both schedulers: seconds, the process's CPU seconds (all its threads: less moved than the
wall clock by other processes on a shared machine), compile seconds and the output's hash; with ``--rev``,
the package at that git revision runs each case right after the working tree's (same process, same machine
state), and the hashes say whether the outputs are the same bits.

    python experiments/probes/area_valence.py                                  # area, valences 100 and 200
    python experiments/probes/area_valence.py 200 --rev main                   # old against new
    python experiments/probes/area_valence.py 200 --rev main --repeats 3       # the fastest of three, warm
    python experiments/probes/area_valence.py 200 400 --methods default classic area esqem line probabilistic
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules
from ab_compare import load_old  # noqa: E402

import qemjax
from qemjax import shapes


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("valences", nargs="*", type=int, default=[100, 200])
    ap.add_argument("--methods", nargs="+", default=["area"])
    ap.add_argument("--schedulers", nargs="+", default=["greedy", "parallel"])
    ap.add_argument("--target", type=int, default=100, help="target_faces (default 100)")
    ap.add_argument("--rev", default=None, help="also run the package at this git revision")
    ap.add_argument("--repeats", type=int, default=1, help="runs of each case: the fastest is shown (wall and "
                    "CPU apart), with the first run's compile seconds (the later runs compile nothing)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    versions = [("new", qemjax)] + ([(args.rev, load_old(args.rev))] if args.rev else [])
    for label, pkg in versions:  # compile first, outside the timings (a small fan: the wide rings' loops too)
        for method in args.methods:
            for scheduler in args.schedulers:
                pkg.simplify(shapes.icosphere(2), target_faces=100, method=method, scheduler=scheduler)
            pkg.simplify(shapes.double_cone(130), target_faces=200, method=method, scheduler="parallel")
    for n in args.valences:
        m = shapes.double_cone(n)
        for method in args.methods:
            for scheduler in args.schedulers:
                for label, pkg in versions:
                    walls, cpus, hashes, compile_s = [], [], set(), None
                    for _ in range(max(args.repeats, 1)):
                        t, c = time.perf_counter(), time.process_time()
                        r = pkg.simplify((m.vertices, m.faces), target_faces=args.target, method=method,
                                         scheduler=scheduler)
                        walls.append(time.perf_counter() - t)
                        cpus.append(time.process_time() - c)
                        compile_s = r.stats["compile_s"] if compile_s is None else compile_s
                        hashes.add(hashlib.sha256(r.vertices.tobytes() + r.faces.tobytes()).hexdigest()[:12])
                    h = " ".join(sorted(hashes))  # (two: the runs differ)
                    print(f"{label:8s} double_cone({n}) {len(m.faces)} -> {len(r.faces)} faces, {method} {scheduler}: "
                          f"{min(walls):.1f} s (cpu {min(cpus):.1f} s, compile {compile_s:.2f} s) {h}", flush=True)


if __name__ == "__main__":
    main()
