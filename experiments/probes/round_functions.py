"""The parallel scheduler's main-thread CPU time per function, old code against new code in one process.

Wraps the round's stages and helpers of both packages (the old one at a git revision, unpacked as
``qemjax_old`` by `ab_compare.load_old`; module paths must match, so use a revision of the same layout),
runs warm `qemjax.simplify` calls alternately, and prints each function's main-thread CPU time per run
(``time.thread_time``, inclusive; a function submitted to the host worker thread counts that thread's time)
and its calls, old and new. On a shared machine whole-run wall times move by 10-30 % from run to run; the
per-function CPU time shows where a change saves.

    python experiments/probes/round_functions.py --rev cc30b35 --mesh cow --ratio 0.1 --repeats 10
"""
from __future__ import annotations

import argparse
import collections
import functools
import importlib
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import ab_compare  # noqa: E402
import meshes as bench_meshes  # noqa: E402

# (module, object or None, function name)
WRAPPED = [("_schedulers.parallel.stages", "Round", n) for n in ("cost", "select", "contract")] + \
    [("_schedulers.parallel.staged", "StagedRound", "validate")] + \
    [("_schedulers.parallel.compiled", "LoopRound", "passes")] + \
    [("_schedulers.parallel.compiled", "GlueRound", n) for n in ("carry", "select", "contract")] + \
    [("_schedulers.parallel.staged", None, n) for n in ("independent_sets", "accepted", "start_flips")] + \
    [("_schedulers.parallel.stages", None, n) for n in ("start_price", "start_merge", "set_rows")] + \
    [("_mesh.topology", None, n) for n in ("link_ok", "coincidence_count")] + \
    [("_mesh.incidence", "FaceLists", n) for n in ("touched_with_dead", "contract_touched")]
OLD_NAMES = {"_mesh.topology": "_topology", "_mesh.incidence": "_incidence"}  # before the layout regroup (61c71ce)


def wrap(pkg: str, times: collections.Counter, calls: collections.Counter) -> None:
    for mod, owner, name in WRAPPED:
        try:
            m = importlib.import_module(f"{pkg}.{mod}")
        except ModuleNotFoundError:
            m = importlib.import_module(f"{pkg}.{OLD_NAMES[mod]}")
        target = getattr(m, owner) if owner else m
        f = getattr(target, name)

        @functools.wraps(f)
        def timed(*a, _f=f, _k=f"{owner + '.' if owner else ''}{name}", **kw):
            c0 = time.thread_time()
            try:
                return _f(*a, **kw)
            finally:
                times[_k] += time.thread_time() - c0
                calls[_k] += 1
        setattr(target, name, timed)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", default="HEAD")
    p.add_argument("--mesh", default="cow")
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--repeats", type=int, default=10)
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    old = ab_compare.load_old(args.rev)
    import qemjax as new
    m = bench_meshes.load(args.mesh)
    stats = {tag: (collections.Counter(), collections.Counter()) for tag in ("old", "new")}
    wrap("qemjax_old", *stats["old"])
    wrap("qemjax", *stats["new"])
    libs = {"old": old, "new": new}
    for lib in libs.values():
        for _ in range(2):
            lib.simplify((m.V, m.F), ratio=args.ratio)
    for t, c in stats.values():
        t.clear()
        c.clear()
    total = collections.Counter()
    for r in range(args.repeats):
        for tag in (("old", "new") if r % 2 == 0 else ("new", "old")):
            c0 = time.thread_time()
            libs[tag].simplify((m.V, m.F), ratio=args.ratio)
            total[tag] += time.thread_time() - c0
    R = args.repeats
    print(f"{args.mesh} -> {args.ratio:g}: main-thread CPU ms per run (inclusive), {args.rev} (old) vs working tree "
          f"(new), {R} alternating warm runs each")
    print(f"{'function':34s} {'old':>7s} {'new':>7s} {'new/old':>7s} {'calls':>6s}")
    print(f"{'simplify (whole call)':34s} {total['old'] / R * 1e3:7.1f} {total['new'] / R * 1e3:7.1f} "
          f"{total['new'] / total['old']:7.2f}")
    to, co = stats["old"]
    tn, cn = stats["new"]
    for k in sorted(to, key=lambda k: -to[k]):
        print(f"{k:34s} {to[k] / R * 1e3:7.1f} {tn[k] / R * 1e3:7.1f} {tn[k] / to[k] if to[k] else float('nan'):7.2f} "
              f"{co[k] // R:6d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
