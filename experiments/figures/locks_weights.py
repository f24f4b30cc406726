"""Locked vertices and importance weights (`qemjax._pipeline.locks`): what locks cost in time, and what weights do to
the local error, in one run.

1. Time: ``simplify`` with no locks, 1 % and 10 % of the vertices locked (random, fixed seed), per
   scheduler, warm (one untimed run of each first), repeats interleaved; the median and its ratio to no
   locks. The greedy scheduler takes locks in its compiled verified batches (`greedy.batches`; before
   2026-11-27 it left them for its one-at-a-time loop, which is what results/locks_weights.md measured).
2. Weights: the vertices of a cap (x > 0.5 of the mesh's half-extent along x) weighted 1 (none), 10 and 100;
   the distance from every input vertex to the output surface, rms and max, inside the cap and outside,
   relative to the bounding-box diagonal, and the share of output vertices in the cap.

    python experiments/figures/locks_weights.py                      # bumpy sphere (20,480 faces) and the cow
    python experiments/figures/locks_weights.py --repeats 3 --out experiments/results/locks_weights.md
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import qemjax
from qemjax import shapes
from qemjax._mesh.nearest import nearest_triangles

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def meshes():
    out = {"bumpy-sphere-5": shapes.bumpy_sphere(subdivisions=5)}
    cow = SHARED / "cow.obj"
    if cow.exists():
        m = qemjax.load(str(cow)) if hasattr(qemjax, "load") else None
        if m is not None:
            out["cow"] = m
    return {k: (np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)) for k, m in out.items()}


def locks_for(n: int, share: float, seed: int = 0):
    k = int(round(share * n))
    return None if k == 0 else np.sort(np.random.default_rng(seed).choice(n, k, replace=False))


def run(mesh, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        res = qemjax.simplify(mesh, **kw)
        return res, time.perf_counter() - t0


def timing(name, mesh, ratio, repeats, out):
    n = len(mesh[0])
    shares = (0.0, 0.01, 0.10)
    for scheduler in ("parallel", "greedy"):
        cfgs = [dict(ratio=ratio, scheduler=scheduler, locked=locks_for(n, s)) for s in shares]
        times = [[] for _ in cfgs]
        results = [run(mesh, **c)[0] for c in cfgs]  # warm-up (and the outputs checked below)
        for _ in range(repeats):
            for i, c in enumerate(cfgs):
                times[i].append(run(mesh, **c)[1])
        med = [statistics.median(t) for t in times]
        for s, c, r, m in zip(shares, cfgs, results, med):
            lk = c["locked"]
            exact = "-" if lk is None else str(all(
                np.array_equal(r.vertices[np.flatnonzero(r.source_vertices == i)[0]], mesh[0][i]) for i in lk))
            out.append(f"| {name} | {scheduler} | {s:.0%} | {len(r.faces)} | {r.stop_reason} | {m:.3f} | "
                       f"{m / med[0]:.2f} | {exact} |")
            print(out[-1], flush=True)


def local_error(mesh, res, region):
    V, F = mesh
    corners = np.ascontiguousarray(res.vertices[res.faces].transpose(1, 2, 0))
    d = nearest_triangles(corners, V)[0]
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    return [(float(np.sqrt(np.mean(d[m] ** 2))) / diag, float(d[m].max()) / diag) for m in (region, ~region)]


def weights(name, mesh, ratio, out, schedulers=("parallel", "greedy")):
    V = mesh[0]
    lo, hi = V.min(0), V.max(0)
    region = V[:, 0] > 0.5 * (lo[0] + hi[0]) + 0.25 * (hi[0] - lo[0])
    for scheduler in schedulers:
        for w in (1.0, 10.0, 100.0):
            res, _ = run(mesh, ratio=ratio, scheduler=scheduler,
                         vertex_weights=None if w == 1.0 else np.where(region, w, 1.0))
            (ri, mi), (ro, mo) = local_error(mesh, res, region)
            share = float(np.mean(region[res.source_vertices]))
            out.append(f"| {name} | {scheduler} | {w:g} | {region.mean():.1%} | {share:.1%} | {ri:.2e} | {mi:.2e} "
                       f"| {ro:.2e} | {mo:.2e} |")
            print(out[-1], flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ratio", type=float, default=0.05, help="the weights' runs")
    ap.add_argument("--time-ratio", type=float, default=0.3,
                    help="the timed runs (10 %% locked vertices need room: at 0.05 they block the target)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=None, help="write the tables here (markdown)")
    args = ap.parse_args(argv)
    ms = meshes()
    out = [f"# Locks and weights (`python experiments/figures/locks_weights.py --ratio {args.ratio} --time-ratio "
           f"{args.time_ratio} --repeats {args.repeats}`)", "",
           f"## Time of locks (ratio {args.time_ratio}; warm medians, interleaved repeats; ratio to no locks, "
           "same run)", "",
           "| mesh | scheduler | locked | faces out | stop | median s | × no locks | locked exact |",
           "|---|---|---|---|---|---|---|---|"]
    for name, mesh in ms.items():
        timing(name, mesh, args.time_ratio, args.repeats, out)
    out += ["", f"## Weights on a cap (ratio {args.ratio}) (x in the top quarter of the extent): local error",
            "", "Distance from each input vertex to the output surface / bounding-box diagonal, inside the "
            "cap and outside it.", "",
            "| mesh | scheduler | cap weight | cap share of input vertices | cap share of output vertices | "
            "rms in cap | max in cap | rms outside | max outside |", "|---|---|---|---|---|---|---|---|---|"]
    for name, mesh in ms.items():
        weights(name, mesh, args.ratio, out)
    text = "\n".join(out) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    else:
        sys.stdout.write(text)


if __name__ == "__main__":
    main()
