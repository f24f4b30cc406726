"""What the default would still take with every line of Python and numpy glue in its rounds gone: the time
inside the round's compiled loops (`round_jit`: selection with validation, the faces' and pairs'
contraction, clearing the rejections; `round_glue_jit`: the prices carried, the gate, the order and the
contraction with the device call's inputs), the wait for the device (`stats["kernels_s"]`), the re-fit and the
measured distance, summed, against the whole run and against a goal of G × meshoptimizer's time.

Each compiled loop is wrapped with a timer; warm runs, medians.

A second table sets the goal's room for the host loops (the goal less the device wait, the re-fit and the
measured distance) beside what one part of them alone takes: the rule checks of every pair that the
selection tested in the run (link condition, coincident faces, part and seam rules, the flip test), replayed
as one compiled loop per round on that round's inputs, without the selection's scans or the contraction
(`select_cost.rules_alone`, best of 3 per round), and the whole run's checks against its contractions.

    python experiments/round_floor.py --cases cow:0.1:20 stanford-bunny:0.1:5 --repeats 7
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

import meshes as bench_meshes  # noqa: E402

LOOPS = ("select_validate", "contract_faces", "contract_edges", "clear_bad")  # round_jit's, called from Python
GLUE = ("carry", "under_gate", "order_fit", "contract")  # round_glue_jit's (which call round_jit's inside)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1:20", "stanford-bunny:0.1:5"],
                    help="mesh:ratio:goal (the goal as a multiple of meshoptimizer's time)")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    import qemjax
    from qemjax import peers
    from qemjax._schedulers import round_glue_jit, round_jit

    from select_cost import _copy, rules_alone

    spent = {"loops": 0.0}
    select_validate = round_jit.select_validate  # (the compiled function, before it is wrapped)
    for module, name in [(round_jit, n) for n in LOOPS] + [(round_glue_jit, n) for n in GLUE]:
        fn = getattr(module, name)

        def timed(*a, _fn=fn):
            t = time.perf_counter()
            try:
                return _fn(*a)
            finally:
                spent["loops"] += time.perf_counter() - t
        setattr(module, name, timed)
    budget = []
    print(f"# python experiments/round_floor.py --cases {' '.join(args.cases)} --repeats {args.repeats}")
    print("| case | whole run ms | compiled loops ms | device wait ms | re-fit ms | measured distance ms | "
          "sum (the floor) ms | meshoptimizer ms | goal ms | floor / goal |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for case in args.cases:
        name, ratio, goal = case.split(":")
        bm = bench_meshes.load(name)
        target = int(len(bm.F) * float(ratio))
        rows = {k: [] for k in ("run", "loops", "kernels", "refit", "distance", "mo")}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            qemjax.simplify((bm.V, bm.F), target_faces=target)  # warm
            peers.run_peer("meshoptimizer", bm.V, bm.F, target)
            for _ in range(args.repeats):
                spent["loops"] = 0.0
                t = time.perf_counter()
                r = qemjax.simplify((bm.V, bm.F), target_faces=target)
                rows["run"].append(time.perf_counter() - t)
                rows["loops"].append(spent["loops"])
                rows["kernels"].append(r.stats["kernels_s"])
                rows["refit"].append(r.stats["refit_s"] or 0.0)
                rows["distance"].append(r.stats["distance_s"] or 0.0)
                rows["mo"].append(peers.run_peer("meshoptimizer", bm.V, bm.F, target)[2])  # its call alone
        med = {k: statistics.median(v) * 1e3 for k, v in rows.items()}
        floor = med["loops"] + med["kernels"] + med["refit"] + med["distance"]
        g = float(goal) * med["mo"]
        print(f"| {name} → {ratio} | {med['run']:.1f} | {med['loops']:.1f} | {med['kernels']:.1f} | "
              f"{med['refit']:.1f} | {med['distance']:.1f} | {floor:.1f} | {med['mo']:.2f} | {g:.1f} "
              f"({goal}×) | {floor / g:.2f} |")
        room = g - (med["kernels"] + med["refit"] + med["distance"])
        checks, alone, contracted = _rule_checks(qemjax, bm, target, select_validate, _copy, rules_alone)
        budget.append(f"| {name} → {ratio} | {g:.1f} | {room:.1f} | {med['loops']:.1f} | {checks} | {contracted} | "
                      f"{alone * 1e3:.1f} | {alone * 1e3 / room:.2f} |")
    print()
    print("| case | goal ms | room for the host loops ms | the loops now ms | rule checks | contractions | "
          "rule checks alone ms | rule checks alone / room |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(budget))


def _rule_checks(qemjax, bm, target, fn, copy, rules_alone):
    """(pairs tested, seconds the tests alone take, contractions) over one warm run: every call's inputs of
    ``fn`` (`round_jit.select_validate`) recorded, then its tested pairs (accepted and rejected) replayed
    through the rules alone."""
    import numpy as np

    from qemjax._schedulers import round_jit

    timed = round_jit.select_validate
    names = fn.py_func.__code__.co_varnames[: fn.py_func.__code__.co_argcount]
    saved = []

    def spy(*a):
        saved.append(copy(a))
        return fn(*a)
    round_jit.select_validate = spy
    try:
        r = qemjax.simplify((bm.V, bm.F), target_faces=target)
    finally:
        round_jit.select_validate = timed
    checks = alone = 0
    for a in saved:
        out = fn(*copy(a))
        tested = np.concatenate([out[0], out[2]])
        checks += len(tested)
        if len(tested):
            alone += rules_alone(copy(a), tested, names, repeats=3)
    return checks, alone, r.stats["contractions"]


if __name__ == "__main__":
    main()
