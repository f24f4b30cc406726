"""What one round's compiled selection costs (`selection.select_validate`), and where: the set-up over every
pair (keys, working set) against the passes, whose time goes to the rule checks (link condition, coincident
faces, flip test) of the pairs each pass selects.

Records the inputs of the first rounds of a warm run, then times each call again (best of 5) with no
pass (set-up only), one pass, and all of them, and divides the passes' time by the rule checks they made
(accepted + rejected pairs). "rules alone" times the same rule checks (`selection._rules` on the pairs the
call accepted and rejected, on its input state) in one compiled loop without the passes' scans: what the
passes spend beyond it goes to the scans over the working set and the locking.

    python experiments/figures/select_cost.py --meshes cow stanford-bunny --rounds 0 3 8
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import numpy as np  # noqa: E402

import meshes as bench_meshes  # noqa: E402


_LOOP = []


def _rules_loop():
    """A compiled loop of `selection._rules` over given pairs (built once a process)."""
    if _LOOP:
        return _LOOP[0]
    from numba import njit

    from qemjax._schedulers.parallel import selection

    rules, Locks, Scratch = selection._rules, selection.Locks, selection.Scratch

    @njit(cache=False)
    def loop(sel, pairs, faces, mesh, limits, seams, mark):
        E, ecount, X, cnt = pairs.E, pairs.ecount, pairs.X, faces.count
        width = 64
        for i in sel:
            width = max(width, 4 * (cnt[E[i, 0]] + cnt[E[i, 1]]))
        scratch = Scratch(mark, np.empty(width, np.int64), np.empty(width, np.int64), np.empty(width, np.int64),
                          np.empty((12, width), np.int64))
        locks = Locks(np.zeros(0, np.bool_), np.zeros(0, np.int32))
        apex = np.empty((1, 2), np.int64)
        bad = 0
        for i in sel:
            bad += rules(E[i, 0], E[i, 1], ecount[i], X[i], faces, mesh, limits, seams, locks, scratch, apex, 0) != 0
        return bad

    _LOOP.append(loop)
    return loop


def rules_alone(a, sel, repeats=5):
    """Seconds (best of ``repeats``) of `selection._rules` on each pair of ``sel`` (rows of E), with the
    inputs ``a`` of a `selection.select_validate` call (its bundles: pairs, passes, faces, mesh, limits,
    seams, locks, work)."""
    loop = _rules_loop()
    pairs, _, faces, mesh, limits, seams, _, work = a
    args = (pairs, faces, mesh, limits, seams, work.mark)
    loop(sel[:1], *args)  # compile
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        loop(sel, *args)
        ts.append(time.perf_counter() - t)
    return min(ts)


def _copy(args):
    """A copy of a call's arguments, the arrays inside its bundles (named tuples) copied too."""
    if isinstance(args, np.ndarray):
        return args.copy()
    if isinstance(args, tuple) and hasattr(args, "_fields"):
        return type(args)(*map(_copy, args))
    if isinstance(args, (tuple, list)):
        return [_copy(a) for a in args]
    return args


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny"])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--rounds", nargs="+", type=int, default=[0, 3, 8])
    args = ap.parse_args()
    import qemjax
    from qemjax._schedulers.parallel import selection

    fn = selection.select_validate
    print(f"# python experiments/figures/select_cost.py --meshes {' '.join(args.meshes)} --ratio {args.ratio} "
          f"--rounds {' '.join(map(str, args.rounds))}")
    print("| mesh | round | pairs | set-up ms | one pass ms | all passes ms | rule checks | µs per check "
          "| rules alone ms | µs per check alone |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        bm = bench_meshes.load(name)
        mesh = (bm.V, bm.F)
        saved = []

        def spy(*a):
            saved.append(_copy(a))
            return fn(*a)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            qemjax.simplify(mesh, ratio=args.ratio)  # warm
            selection.select_validate = spy
            try:
                qemjax.simplify(mesh, ratio=args.ratio)
            finally:
                selection.select_validate = fn
        for r in args.rounds:
            if r >= len(saved):
                continue
            a = saved[r]
            best = {}
            most = a[1].max_passes
            for passes in (0, 1, most):
                ts = []
                for _ in range(5):
                    b = _copy(a)
                    b[1] = b[1]._replace(max_passes=passes)
                    t = time.perf_counter()
                    out = fn(*b)
                    ts.append(time.perf_counter() - t)
                best[passes] = (min(ts), len(out[0]) + len(out[2]))
                if passes == most:
                    checked = np.concatenate([out[0], out[2]])
            t0, (t1, c1), (ta, ca) = best[0][0], best[1], best[most]
            alone = rules_alone(_copy(a), checked)
            print(f"| {name} | {r} | {len(a[0])} | {t0 * 1e3:.2f} | {t1 * 1e3:.2f} | {ta * 1e3:.2f} | {ca} | "
                  f"{(ta - t0) / max(ca, 1) * 1e6:.2f} | {alone * 1e3:.2f} | {alone / max(ca, 1) * 1e6:.2f} |")


if __name__ == "__main__":
    main()
