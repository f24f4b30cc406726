"""Where a greedy run's time goes, per contraction: process CPU time of the verified batches' stages,
each timed by wrapping it, in µs per contraction, with the device calls (merge, price, row updates: the
JAX dispatch and the wait) apart: the compiled loop (`qemjax._schedulers.greedy.batches`; its Python
twin, `greedy_batches`, was retired at 2026-11-27: ``git show eee561e:experiments/probes/greedy_profile.py`` for
its stages). ``--non-manifold``: with ``preserve_topology=False``.

    python experiments/probes/greedy_profile.py                         # stanford-bunny -> 10 %
    python experiments/probes/greedy_profile.py --mesh cow.obj --non-manifold

Nested stages are indented under the stage that calls them (their time is part of it). One warm-up run
first (compilation), then one timed run. CPU time, so other processes on a shared machine count less
than in wall time (though they still slow it through the caches).
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent)]  # this checkout's qemjax

import qemjax  # noqa: E402
from qemjax._schedulers.greedy import batches as gc  # noqa: E402
from qemjax._schedulers.greedy import speculate as jit  # noqa: E402

SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"
COMPILED = [  # (name, depth): methods of batches._Compiled, kernels of speculate, device calls
    ("batch", 0), ("jit: speculate", 1), ("price_intervals", 1), ("jit: first_wrong", 1), ("jit: undo", 1),
    ("jit: forget_gone", 1), ("jit: last_intervals", 1), ("push", 1), ("jit: push", 2), ("record", 1),
    ("room", 1), ("jit: rebuild", 1), ("device: merge", 1), ("device: price", 1), ("device: set_rows", 1)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="stanford-bunny.obj")
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--non-manifold", action="store_true", help="preserve_topology=False")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    spent = {}

    def timed(name, f, waits=False):
        def g(*a, **k):
            t = time.process_time()
            out = f(*a, **k)
            if waits:  # start_merge / start_price return a function that waits for the device
                def wait(out=out):
                    t = time.process_time()
                    try:
                        return out()
                    finally:
                        spent[name] = spent.get(name, 0.0) + time.process_time() - t
                spent[name] = spent.get(name, 0.0) + time.process_time() - t
                return wait
            spent[name] = spent.get(name, 0.0) + time.process_time() - t
            return out
        return g

    stages = COMPILED
    kw = {"preserve_topology": False} if args.non_manifold else {}
    for name, _ in stages:
        if name.startswith("jit: "):
            setattr(jit, name[5:], timed(name, getattr(jit, name[5:])))
        elif not name.startswith("device"):
            setattr(gc._Compiled, name, timed(name, getattr(gc._Compiled, name)))
    gc.start_merge = timed("device: merge", gc.start_merge, waits=True)
    gc.start_price = timed("device: price", gc.start_price, waits=True)
    gc.set_rows = timed("device: set_rows", gc.set_rows)
    path = str(SHARED / args.mesh)
    qemjax.simplify(path, ratio=args.ratio, scheduler="greedy", **kw)  # warm-up
    spent.clear()
    t, c = time.perf_counter(), time.process_time()
    res = qemjax.simplify(path, ratio=args.ratio, scheduler="greedy", **kw)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    n = res.stats["contractions"]
    print(f"{args.mesh} -> {args.ratio:g}: {n} contractions, wall {wall:.2f} s, cpu {cpu:.2f} s "
          f"({1e6 * cpu / n:.0f} µs per contraction)")
    for name, depth in stages:
        if name in spent:
            print(f"  {'  ' * depth}{name:{24 - 2 * depth}s} {spent[name]:6.2f} s  {1e6 * spent[name] / n:6.1f} µs")
    outside = cpu - spent.get("batch", 0.0)
    print(f"  {'outside the batches':24s} {outside:6.2f} s  {1e6 * outside / n:6.1f} µs   (setup, first pricing, "
          f"output, simplify's own stages)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
