"""A/B of the batched path: `simplify_batch` of 64 QEM configurations of the cow (sweep_bench's grid
'qem', or ``--grid distinct``: since bbf71cf the 'qem' grid's cells that run alike run once, 6 runs for
the cow's 64 cells, so compare the batching itself across that revision on 'distinct') at an old git
revision against the working tree, in one process, interleaved, with the outputs checked equal. Prints the fastest wall and CPU time of each over the repeats (on a shared machine the
minimum moves least) and each against one warm `simplify` of the cow.

    taskset -c 1 python experiments/probes/batch_ab.py --rev 9f0d9de --repeats 9
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from ab_compare import cpu_time, load_old  # noqa: E402
from figures.sweep_bench import GRIDS  # noqa: E402

import qemjax  # noqa: E402
from qemjax._sweep.run import expand_grid  # noqa: E402


def _clock(fn) -> tuple[float, float]:
    c, w = cpu_time(), time.perf_counter()
    fn()
    return time.perf_counter() - w, cpu_time() - c


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="the old code's git revision")
    ap.add_argument("--mesh", default="cow")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--grid", choices=sorted(GRIDS), default="qem")
    args = ap.parse_args(argv)
    old = load_old(args.rev)
    mesh = qemjax.load(bench_meshes.shared_files()[args.mesh])
    configs = [dict(c, ratio=0.1) for c in expand_grid(GRIDS[args.grid])]
    versions = {"old": old, "new": qemjax}
    out = {k: q.simplify_batch(mesh, configs) for k, q in versions.items()}  # warm, and compared
    for a, b in zip(out["old"], out["new"]):
        if not (np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)):
            raise SystemExit("the two revisions give different outputs")
    for q in versions.values():
        q.simplify(mesh, ratio=0.1)
    t = {f"{k} {m}": [] for k in versions for m in ("one", "batch")}
    for r in range(args.repeats):
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            q = versions[k]
            for _ in range(3):
                t[f"{k} one"].append(_clock(lambda: q.simplify(mesh, ratio=0.1)))
            t[f"{k} batch"].append(_clock(lambda: q.simplify_batch(mesh, configs)))
    best = {k: (min(w for w, _ in v), min(c for _, c in v)) for k, v in t.items()}
    print(f"{args.mesh}, {len(configs)} configurations -> 10 %, {args.rev} (old) vs working tree (new); "
          f"fastest of {args.repeats} (one: of {3 * args.repeats})")
    for k in versions:
        (w1, c1), (wb, cb) = best[f"{k} one"], best[f"{k} batch"]
        print(f"{k}: one {w1:.3f} s (CPU {c1:.3f}), batch {wb:.3f} s (CPU {cb:.3f}): {wb / w1:.2f}x "
              f"(CPU {cb / c1:.2f}x)")
    print(f"batch new / old: wall {best['new batch'][0] / best['old batch'][0]:.3f}, "
          f"CPU {best['new batch'][1] / best['old batch'][1]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
