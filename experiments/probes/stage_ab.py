"""Where a warm run's time goes, old code against new code in one process: the stage timers of
`qemjax.simplify`'s stats (topology, kernels, selection with validation inside it, contraction) and the
main thread's CPU time, medians of alternating warm runs, with an output hash per side.

    python experiments/probes/stage_ab.py --rev main --mesh cow --ratio 0.1 --repeats 15
    python experiments/probes/stage_ab.py --rev main --mesh armadillo --set quality_threshold=0 late_memoryless=0 refit=0

``--set`` gives both sides settings of `simplify` (numbers or words); the second line runs the rounds a
partitioned run's levels before the last run (no shape term, summed quadrics, no re-fit) on a round of
up to 129,723 pairs (3/2 of its faces: a closed mesh's edges).

The main thread's CPU time (``time.thread_time``) counts the host work on the critical path and is less
disturbed than wall time by other processes on a shared machine; kernels run on JAX's threads beside it.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import ab_compare  # noqa: E402
import meshes as bench_meshes  # noqa: E402
from probes.round_profile import STAGES  # noqa: E402  (the scheduler's stage timers in stats)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", default="main")
    p.add_argument("--mesh", default="cow")
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--repeats", type=int, default=15)
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="settings of simplify, both sides")
    args = p.parse_args(argv)
    kw = {k: ab_compare._value(v) for k, v in (item.split("=", 1) for item in args.set)}  # as --new-option's
    warnings.simplefilter("ignore")
    old = ab_compare.load_old(args.rev)
    import qemjax as new
    m = bench_meshes.load(args.mesh)
    libs = {"old": old, "new": new}
    for lib in libs.values():  # compile, then one warm run each
        for _ in range(2):
            lib.simplify((m.V, m.F), ratio=args.ratio, **kw)
    rows = {tag: {k: [] for k in STAGES + ("run_s", "wall_s", "main_cpu_s")} for tag in libs}
    digest, rounds = {}, {}
    for r in range(args.repeats):
        for tag in (("old", "new") if r % 2 == 0 else ("new", "old")):
            t0, c0 = time.perf_counter(), time.thread_time()
            res = libs[tag].simplify((m.V, m.F), ratio=args.ratio, **kw)
            rows[tag]["main_cpu_s"].append(time.thread_time() - c0)
            rows[tag]["wall_s"].append(time.perf_counter() - t0)
            for k in STAGES + ("run_s",):
                rows[tag][k].append(res.stats.get(k, 0.0))
            # the rounds, and of them those that contracted (the others only rejected what they selected)
            digest[tag] = ab_compare.digest(res)
            rounds[tag] = f"{res.stats['rounds']} ({len(np.unique(res.history.rounds))} contracting)"
    print(f"{args.mesh} -> {args.ratio:g}{' ' + str(kw) if kw else ''}, {args.rev} (old) vs working tree (new), medians of {args.repeats} "
          f"alternating warm runs; outputs {'identical' if digest['old'] == digest['new'] else 'DIFFERENT'} "
          f"({digest['old']} / {digest['new']}), rounds {rounds['old']} / {rounds['new']}")
    print(f"{'stage':12s} {'old ms':>8s} {'new ms':>8s} {'new/old':>8s}")
    for k in STAGES + ("run_s", "wall_s", "main_cpu_s"):
        a, b = statistics.median(rows["old"][k]) * 1e3, statistics.median(rows["new"][k]) * 1e3
        note = "  (inside select_s)" if k == "validity_s" else ""
        print(f"{k:12s} {a:8.1f} {b:8.1f} {b / a if a else float('nan'):8.2f}{note}")
    return 0 if digest["old"] == digest["new"] else 1


if __name__ == "__main__":
    sys.exit(main())
