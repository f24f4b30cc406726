"""Where a greedy run's time goes, per contraction: process CPU time of the verified batches' stages
(`qemjax._schedulers.greedy_batches`), each timed by wrapping it, in µs per contraction, with the device
calls (merge, price, row updates: the JAX dispatch and the wait) apart.

    python experiments/greedy_profile.py                         # stanford-bunny -> 10 %
    python experiments/greedy_profile.py --mesh cow.obj

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

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent)]  # this checkout's qemjax

import qemjax  # noqa: E402
from qemjax._schedulers import greedy_batches as gb  # noqa: E402

SHARED = HERE.parent.parent / "shared" / "meshes"
STAGES = [  # (name, depth): methods of greedy_batches._Batches, and the device calls
    ("batch", 0), ("speculate", 1), ("next_entry", 2), ("prefetch", 3), ("flip_tests", 4), ("check", 2),
    ("contract", 2), ("price_intervals", 1), ("first_wrong", 1), ("commit", 1), ("push", 2), ("record", 2),
    ("undo", 1), ("device: merge", 1), ("device: price", 1), ("device: set_rows", 1)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="stanford-bunny.obj")
    ap.add_argument("--ratio", type=float, default=0.1)
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

    for name, _ in STAGES:
        if not name.startswith("device"):
            setattr(gb._Batches, name, timed(name, getattr(gb._Batches, name)))
    gb.start_merge = timed("device: merge", gb.start_merge, waits=True)
    gb.start_price = timed("device: price", gb.start_price, waits=True)
    gb.set_rows = timed("device: set_rows", gb.set_rows)
    path = str(SHARED / args.mesh)
    qemjax.simplify(path, ratio=args.ratio, scheduler="greedy")  # warm-up
    spent.clear()
    t, c = time.perf_counter(), time.process_time()
    res = qemjax.simplify(path, ratio=args.ratio, scheduler="greedy")
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    n = res.stats["contractions"]
    print(f"{args.mesh} -> {args.ratio:g}: {n} contractions, wall {wall:.2f} s, cpu {cpu:.2f} s "
          f"({1e6 * cpu / n:.0f} µs per contraction)")
    for name, depth in STAGES:
        if name in spent:
            print(f"  {'  ' * depth}{name:{24 - 2 * depth}s} {spent[name]:6.2f} s  {1e6 * spent[name] / n:6.1f} µs")
    outside = cpu - spent.get("batch", 0.0)
    print(f"  {'outside the batches':24s} {outside:6.2f} s  {1e6 * outside / n:6.1f} µs   (setup, first pricing, "
          f"output, simplify's own stages)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
