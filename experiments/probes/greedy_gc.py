"""How much of a greedy run (``scheduler="greedy"``) Python's cyclic garbage collector takes: one warm run
per mesh with the collector as the scheduler leaves it, and one with `common.gc_paused` made a no-op
(the collector running throughout, as before it existed), each with the collections timed by
`gc.callbacks`.

    python experiments/probes/greedy_gc.py                       # cow and stanford-bunny -> 10 %
"""
from __future__ import annotations

import argparse
import contextlib
import gc
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]  # this checkout's qemjax

import qemjax  # noqa: E402
from qemjax._schedulers import greedy  # noqa: E402

SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["cow.obj", "stanford-bunny.obj"])
    ap.add_argument("--ratio", type=float, default=0.1)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    spent = {"n": 0, "s": 0.0}
    t0 = []

    def timed(phase, info):
        if phase == "start":
            t0.append(time.perf_counter())
        else:
            spent["n"] += 1
            spent["s"] += time.perf_counter() - t0.pop()

    paused = greedy.gc_paused
    for mesh in args.meshes:
        path = SHARED / mesh
        if not path.exists():
            print(f"SKIP {mesh} ({path} absent)")
            continue
        qemjax.simplify(str(path), ratio=args.ratio, scheduler="greedy")  # warm-up
        for label, pause in (("collector paused", paused), ("collector running", contextlib.nullcontext)):
            greedy.gc_paused = pause
            spent.update(n=0, s=0.0)
            gc.callbacks.append(timed)
            t, c = time.perf_counter(), time.process_time()
            qemjax.simplify(str(path), ratio=args.ratio, scheduler="greedy")
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            gc.callbacks.remove(timed)
            print(f"{mesh:20s} {label:18s} wall {wall:6.2f} s  cpu {cpu:6.2f} s  collections {spent['n']:5d}  "
                  f"in them {spent['s']:6.2f} s", flush=True)
        greedy.gc_paused = paused
    return 0


if __name__ == "__main__":
    sys.exit(main())
