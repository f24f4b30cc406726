"""The nearest-face grid's cube side (`_mesh.grid_nearest.CUBE_EDGE`, a multiple of the output's median
edge): the query's time for the default's samples (every input vertex and face centroid) against its
output, for several multiples, with the answers compared (any cube side gives the same faces and distances:
the search is exact, ties go to the lowest index).

For each case ``MESH:RATIO`` the default's output is made once (no re-fit); each multiple is timed
``--repeats`` times (median), in alternating order.

    python experiments/probes/grid_cube.py --cases cow:0.1 stanford-bunny:0.1 armadillo-x16:0.01 --edges 0.5 1 1.5
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

import meshes as bench_meshes  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1", "stanford-bunny:0.1", "armadillo-x16:0.01"])
    ap.add_argument("--edges", nargs="+", type=float, default=[0.25, 0.5, 1.0, 1.5, 2.0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax._mesh import grid_nearest
    from qemjax._pipeline.refit import samples, unit_frame

    default = grid_nearest.CUBE_EDGE
    print(f"# python experiments/probes/grid_cube.py --cases {' '.join(args.cases)} --edges "
          f"{' '.join(f'{e:g}' for e in args.edges)} --repeats {args.repeats}")
    print("| case | samples | output faces | cube edge / median edge | query ms (median) | vs "
          f"{default:g} | same answers |")
    print("|---|---|---|---|---|---|---|")
    try:
        for case in args.cases:
            name, ratio = case.split(":")
            m = bench_meshes.load(name)
            res = qemjax.simplify((m.V, m.F), ratio=float(ratio), refit=0, measure=False)
            centre, unit = unit_frame(m.V)
            P = samples((m.V - centre) / unit, m.F, np.zeros(len(m.V), np.int64))[0]
            X, G = (res.vertices - centre) / unit, res.faces
            times = {e: [] for e in args.edges}
            answers = {}
            for rep in range(args.repeats):
                for e in (args.edges if rep % 2 == 0 else args.edges[::-1]):
                    grid_nearest.CUBE_EDGE = e
                    grid_nearest.nearest(X, G, P[:1000])  # compiled, threads started
                    t = time.perf_counter()
                    f, d = grid_nearest.nearest(X, G, P)
                    times[e].append(time.perf_counter() - t)
                    answers.setdefault(e, (f, d))
            base = statistics.median(times[default]) if default in times else None
            ref = answers[args.edges[0]]
            for e in args.edges:
                med = statistics.median(times[e])
                same = np.array_equal(answers[e][0], ref[0]) and answers[e][1].tobytes() == ref[1].tobytes()
                print(f"| {case} | {len(P)} | {len(G)} | {e:g} | {med * 1e3:.2f} | "
                      f"{'' if base is None else f'{med / base:.2f}'} | {'yes' if same else 'NO'} |", flush=True)
    finally:
        grid_nearest.CUBE_EDGE = default
    return 0


if __name__ == "__main__":
    sys.exit(main())
