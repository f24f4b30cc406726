"""What one round's compiled selection costs (`round_jit.select_validate`), and where: the set-up over every
pair (keys, working set) against the passes, whose time goes to the rule checks (link condition, coincident
faces, flip test) of the pairs each pass selects.

Records the inputs of the first rounds of a warm run, then times each call again (best of 5) with no
pass (set-up only), one pass, and all of them, and divides the passes' time by the rule checks they made
(accepted + rejected pairs).

    python experiments/select_cost.py --meshes cow stanford-bunny --rounds 0 3 8
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

import numpy as np  # noqa: E402

import meshes as bench_meshes  # noqa: E402


def _copy(args):
    return [a.copy() if isinstance(a, np.ndarray) else a for a in args]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny"])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--rounds", nargs="+", type=int, default=[0, 3, 8])
    args = ap.parse_args()
    import qemjax
    from qemjax._schedulers import round_jit

    fn = round_jit.select_validate
    names = fn.py_func.__code__.co_varnames[: fn.py_func.__code__.co_argcount]
    at = names.index("max_passes")
    print(f"# python experiments/select_cost.py --meshes {' '.join(args.meshes)} --ratio {args.ratio} "
          f"--rounds {' '.join(map(str, args.rounds))}")
    print("| mesh | round | pairs | set-up ms | one pass ms | all passes ms | rule checks | µs per check |")
    print("|---|---|---|---|---|---|---|---|")
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
            round_jit.select_validate = spy
            try:
                qemjax.simplify(mesh, ratio=args.ratio)
            finally:
                round_jit.select_validate = fn
        for r in args.rounds:
            if r >= len(saved):
                continue
            a = saved[r]
            best = {}
            for passes in (0, 1, a[at]):
                ts = []
                for _ in range(5):
                    b = _copy(a)
                    b[at] = passes
                    t = time.perf_counter()
                    out = fn(*b)
                    ts.append(time.perf_counter() - t)
                best[passes] = (min(ts), len(out[0]) + len(out[2]))
            t0, (t1, c1), (ta, ca) = best[0][0], best[1], best[a[at]]
            print(f"| {name} | {r} | {len(a[0])} | {t0 * 1e3:.2f} | {t1 * 1e3:.2f} | {ta * 1e3:.2f} | {ca} | "
                  f"{(ta - t0) / max(ca, 1) * 1e6:.2f} |")


if __name__ == "__main__":
    main()
