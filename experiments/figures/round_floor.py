"""What the default would still take with every line of Python and numpy glue in its rounds gone: the time
inside the round's compiled loops (`parallel.selection` and `.contraction`: selection with validation, the faces' and pairs'
contraction, clearing the rejections; `glue`: the prices carried, the gate, the order and the
contraction with the device call's inputs), the wait for the device (`stats["kernels_s"]`), the re-fit and the
measured distance, summed, against the whole run and against a goal of G × a peer's time.

Each compiled loop is wrapped with a timer; warm runs, medians. A run on more faces than the compiled loops
take (`selection.MAX_FACES`) shows "-" there: its rounds run the numpy stages.

A second table asks whether the parts every run of the design must have fit in the goal: the set-up (from
the call until the first round: reading and cleaning the input, the quadrics, the pairs, the first prices
started; their wait is the first round's device wait),
the device wait, the contraction stage (`stats["contract_s"]`: the faces and pairs contracted, the device
call started), the re-fit and the measured distance as the same runs took them, and the rule checks of
every pair the selection tested (link condition, coincident faces, part and seam rules, the flip test),
replayed as one compiled loop per round on that round's inputs, warm, best of 3, without the selection's
scans or the contraction (`select_cost.rules_alone`; a large run is recorded through the compiled loops for
this, which give the same contractions, and each round is replayed as it comes; where its own numpy stages'
validation, `stats["validity_s"]`, took less, that is used). "The rest" is the whole run less those parts:
the selection's scans and gate, the glue between the stages and the output.

A case is mesh:ratio:goal, the goal a multiple of meshoptimizer's time; several goals, each as GxPEER, are
separated by commas (``armadillo-x16:0.01:2.5xmeshoptimizer,1.5xfast-simplification``).

    python experiments/figures/round_floor.py --cases cow:0.1:20 stanford-bunny:0.1:5 --repeats 7
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402

LOOPS = ("select_validate", "contract_faces", "contract_edges", "clear_bad")  # selection's and contraction's, called from Python
GLUE = ("carry", "under_gate", "order_fit", "contract")  # glue's (which call contraction's inside)


def _goals(spec: str):
    """[(multiple, peer)] of a case's goal field: "5" (meshoptimizer) or "2.5xmeshoptimizer,1.5xfast-simplification"."""
    out = []
    for g in spec.split(","):
        k, _, peer = g.partition("x")
        out.append((float(k), peer or "meshoptimizer"))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1:20", "stanford-bunny:0.1:5"],
                    help="mesh:ratio:goal (the goal as a multiple of meshoptimizer's time, or GxPEER,...)")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    import qemjax
    from qemjax import peers
    from qemjax._schedulers import parallel
    from qemjax._schedulers.parallel import contraction, glue, selection

    from figures.select_cost import _copy, rules_alone

    spent = {"loops": 0.0, "rounds_from": 0.0}
    select_validate = selection.select_validate  # (the compiled function, before it is wrapped)
    loops = [(selection, LOOPS[0])] + [(contraction, n) for n in LOOPS[1:]]
    for module, name in loops + [(glue, n) for n in GLUE]:
        fn = getattr(module, name)

        def timed(*a, _fn=fn):
            t = time.perf_counter()
            try:
                return _fn(*a)
            finally:
                spent["loops"] += time.perf_counter() - t
        setattr(module, name, timed)
    rounds = parallel.driver.rounds

    def first_round(run, rnd):  # the set-up ends where the rounds begin
        spent["rounds_from"] = time.perf_counter()
        return rounds(run, rnd)
    parallel.driver.rounds = first_round
    budget = []
    print(f"# python experiments/figures/round_floor.py --cases {' '.join(args.cases)} --repeats {args.repeats}")
    print("| case | whole run ms | compiled loops ms | device wait ms | re-fit ms | measured distance ms | "
          "sum (the floor) ms | peer ms | goal ms | floor / goal |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for case in args.cases:
        name, ratio, goal = case.split(":")
        goals = _goals(goal)
        bm = bench_meshes.load(name)
        target = int(len(bm.F) * float(ratio))
        rows = {k: [] for k in ("run", "loops", "setup", "kernels", "refit", "distance", "validation", "contract")}
        peer_s = {p: [] for _, p in goals}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            qemjax.simplify((bm.V, bm.F), target_faces=target)  # warm
            for p in peer_s:
                peers.run_peer(p, bm.V, bm.F, target)
            for _ in range(args.repeats):
                spent["loops"] = 0.0
                t = time.perf_counter()
                r = qemjax.simplify((bm.V, bm.F), target_faces=target)
                rows["run"].append(time.perf_counter() - t)
                rows["setup"].append(spent["rounds_from"] - t)
                rows["loops"].append(spent["loops"])
                rows["kernels"].append(r.stats["kernels_s"])
                rows["refit"].append(r.stats["refit_s"] or 0.0)
                rows["distance"].append(r.stats["distance_s"] or 0.0)
                rows["validation"].append(r.stats.get("validity_s", 0.0))  # the numpy stages' (else 0)
                rows["contract"].append(r.stats["contract_s"])
                for p in peer_s:
                    peer_s[p].append(peers.run_peer(p, bm.V, bm.F, target)[2])  # its call alone
        med = {k: statistics.median(v) * 1e3 for k, v in rows.items()}
        mp = {p: statistics.median(v) * 1e3 for p, v in peer_s.items()}
        k0, p0 = goals[0]
        g0 = k0 * mp[p0]
        if med["loops"] > 0:
            floor = med["loops"] + med["kernels"] + med["refit"] + med["distance"]
            loops, fl, ratio_g = f"{med['loops']:.1f}", f"{floor:.1f}", f"{floor / g0:.2f}"
        else:  # the numpy stages ran
            loops = fl = ratio_g = "-"
        print(f"| {name} → {ratio} | {med['run']:.1f} | {loops} | {med['kernels']:.1f} | "
              f"{med['refit']:.1f} | {med['distance']:.1f} | {fl} | {mp[p0]:.2f} ({p0}) | {g0:.1f} "
              f"({k0:g}×) | {ratio_g} |")
        checks, alone, contracted = _rule_checks(qemjax, bm, target, select_validate, _copy, rules_alone)
        alone *= 1e3
        how = f"{alone:.1f} ({checks} checks, {contracted} contractions)"
        if med["loops"] == 0 and med["validation"] < alone:  # the numpy stages' validation took less
            alone = med["validation"]
            how = f"{alone:.1f} (the numpy stages' validation; alone {how})"
        parts = med["setup"] + med["kernels"] + med["contract"] + med["refit"] + med["distance"] + alone
        for k, p in goals:
            g = k * mp[p]
            budget.append(f"| {name} → {ratio} | {g:.1f} ({k:g}× {p}) | {med['setup']:.1f} | {med['kernels']:.1f} | "
                          f"{med['contract']:.1f} | {med['refit']:.1f} | {med['distance']:.1f} | {how} | {parts:.1f} | {parts / g:.2f} | "
                          f"{med['run'] - parts:.1f} |")
    print()
    print("| case | goal ms | set-up ms | device wait ms | contraction ms | re-fit ms | measured distance ms | "
          "rule checks alone ms | these parts together ms | together / goal | the rest of the run ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(budget))


def _rule_checks(qemjax, bm, target, fn, copy, rules_alone):
    """(pairs tested, seconds the tests alone take, contractions) over one warm run through the compiled
    loops: each call of ``fn`` (`selection.select_validate`) is run first on a copy of its inputs to find the
    pairs it tests (accepted and rejected), which are then replayed through the rules alone."""
    import numpy as np

    from qemjax._schedulers.parallel import selection

    timed, most = selection.select_validate, selection.MAX_FACES
    got = {"checks": 0, "alone": 0.0}

    def spy(*a):
        out = fn(*copy(a))
        tested = np.concatenate([out[0], out[2]])
        got["checks"] += len(tested)
        if len(tested):
            got["alone"] += rules_alone(copy(a), tested, repeats=3)
        return fn(*a)
    selection.select_validate = spy
    selection.MAX_FACES = max(most, len(bm.F))  # (the same contractions as the numpy stages)
    try:
        r = qemjax.simplify((bm.V, bm.F), target_faces=target)
    finally:
        selection.select_validate, selection.MAX_FACES = timed, most
    return got["checks"], got["alone"], r.stats["contractions"]


if __name__ == "__main__":
    main()
