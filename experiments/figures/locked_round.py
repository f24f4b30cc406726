"""A part of a huge mesh as partitioned simplification gives it: about 100 k faces cut from a bumpy sphere, with
a band of vertices along the cut locked (its boundary and the rings inside it, about 3 % of the vertices). Warm
wall and CPU time (median of --repeats, after one untimed run of each) of

* the locked run on the path it takes by itself (`selection.fits`),
* the same locked run forced onto the parallel scheduler's numpy stages (`fits` answering no: the path every
  locked run took before locks reached the compiled round),
* the unlocked run, for reference,

the runs interleaved, and whether the two locked runs give the same bits (vertices, faces, history, stop
reason).

    python experiments/figures/locked_round.py
    python experiments/figures/locked_round.py --subdivisions 7 --keep 0.31 --rings 1 --ratio 0.25 --repeats 5
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
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import round_choice  # noqa: E402
from machine import cpu_model  # noqa: E402


def part(subdivisions: int, keep: float):
    """The faces of a bumpy sphere whose centroids lie in the top ``keep`` share of its height (z), the unused
    vertices dropped: an open cap with one boundary loop."""
    from qemjax import shapes

    m = shapes.bumpy_sphere(subdivisions)
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    z = V[F].mean(1)[:, 2]
    F = F[z >= np.quantile(z, 1.0 - keep)]
    used = np.unique(F)
    new = np.full(len(V), -1, np.int64)
    new[used] = np.arange(len(used))
    return V[used], new[F]


def band(V, F, rings: int) -> np.ndarray:
    """(n,) bool: the boundary vertices and ``rings`` rings of neighbours inside them."""
    from qemjax._mesh import topology as topo

    E, count = topo.edges(F, len(V))
    mask = np.zeros(len(V), bool)
    mask[E[count == 1].reshape(-1)] = True
    for _ in range(rings):
        mask[E[mask[E[:, 0]] | mask[E[:, 1]]].reshape(-1)] = True
    return mask


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subdivisions", type=int, default=7)
    ap.add_argument("--keep", type=float, default=0.31, help="the share of the sphere's faces the part keeps")
    ap.add_argument("--rings", type=int, default=1, help="rings locked inside the boundary")
    ap.add_argument("--ratio", type=float, default=0.25)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--weights", action="store_true", help="also pass vertex_weights (random in [0.5, 2])")
    args = ap.parse_args()
    import qemjax

    V, F = part(args.subdivisions, args.keep)
    locked = band(V, F, args.rings)
    kw = dict(ratio=args.ratio, measure=False)
    if args.weights:
        kw["vertex_weights"] = np.random.default_rng(0).uniform(0.5, 2.0, len(V))

    def run(name):
        lk = None if name == "unlocked" else locked
        with round_choice.forced("numpy" if name == "locked, numpy stages" else None):
            t, c = time.perf_counter(), time.process_time()
            r = qemjax.simplify((V, F), locked=lk, **kw)
            dt = (time.perf_counter() - t, time.process_time() - c)
        return r, dt

    names = ("locked", "locked, numpy stages", "unlocked")
    times = {k: [] for k in names}
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with round_choice.recorded() as taken:
            for name in names:  # warm: each path's compilations
                out[name], _ = run(name)
        paths = dict(zip(names, taken))
        for _ in range(args.repeats):
            for name in names:
                _, dt = run(name)
                times[name].append(dt)
    a, b = out["locked"], out["locked, numpy stages"]
    same = (np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
            and all(np.array_equal(getattr(a.history, f), getattr(b.history, f))
                    for f in ("pairs", "positions", "costs")) and a.stop_reason == b.stop_reason)
    print(f"# python experiments/figures/locked_round.py --subdivisions {args.subdivisions} --keep {args.keep} "
          f"--rings {args.rings} --ratio {args.ratio} --repeats {args.repeats}{' --weights' if args.weights else ''}")
    print(f"# {cpu_model()}; part: {len(F)} faces, {len(V)} vertices, {int(locked.sum())} locked "
          f"({100 * locked.mean():.1f} %); output {len(a.faces)} faces, stop {a.stop_reason!r}")
    print("| run | compiled round | median wall s | median CPU s | wall s of each run |")
    print("|---|---|---|---|---|")
    for name in names:
        ts = [t for t, _ in times[name]]
        cs = [c for _, c in times[name]]
        print(f"| {name} | {'yes' if paths[name] else 'no'} | {statistics.median(ts):.3f} | "
              f"{statistics.median(cs):.3f} | {' '.join(f'{t:.3f}' for t in ts)} |")
    print(f"locked run on its own path / numpy stages: same bits: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
