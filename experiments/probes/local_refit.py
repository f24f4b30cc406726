"""A local re-fit (issue 42) against the exact global one: each input sample's output face found through the
contraction record instead of the grid search over the whole output.

Local attachment: a sample's candidate faces are the output faces around its vertex's image (for a face
centroid, its three corners' images) and around those images' neighbours (`result.vertex_map`, the record's
map from input vertices to output vertices); the nearest of them, exactly (`grid_nearest.closest_d2`), in a
compiled loop. Global: the re-fit's own `grid_nearest.nearest` (exact over all output faces).

For each case: how many samples the local search attaches to another face than the global one, the time
of each attachment (best of 5, on the re-fit's input), and the default method's measured distance (rms and
max, mesh units, `stats["distance_*"]`) with either attachment in its re-fit (the same run otherwise).

    python experiments/probes/local_refit.py --meshes cow fandisk stanford-bunny --ratios 0.1 0.01
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

import meshes as bench_meshes  # noqa: E402
from qemjax._mesh.grid_nearest import closest_d2  # noqa: E402


def _csr(G: np.ndarray, k: int):
    """Faces around each of k vertices: (start (k+1,), faces)."""
    order = np.argsort(G.ravel(), kind="stable")
    start = np.searchsorted(G.ravel()[order], np.arange(k + 1))
    return start.astype(np.int64), (order // 3).astype(np.int64)


@njit(cache=True)
def _local(P, X, G, start, faces, images, nimg):
    """For each sample p: the nearest face among those around its images and their neighbours."""
    q = P.shape[0]
    out = np.empty(q, np.int64)
    seen = np.full(G.shape[0], -1, np.int64)
    ring = np.empty(4096, np.int64)
    for p in range(q):
        bf, bd = -1, np.inf
        nr = 0
        for t in range(nimg[p]):  # the images and their neighbours
            v = images[p, t]
            if v < 0:
                continue
            ring[nr] = v
            nr += 1
            for s in range(start[v], start[v + 1]):
                f = faces[s]
                for c in range(3):
                    if nr < len(ring):
                        ring[nr] = G[f, c]
                        nr += 1
        for i in range(nr):
            v = ring[i]
            for s in range(start[v], start[v + 1]):
                f = faces[s]
                if seen[f] == p:
                    continue
                seen[f] = p
                d = closest_d2(P[p, 0], P[p, 1], P[p, 2], X, G[f, 0], G[f, 1], G[f, 2])
                if d < bd or (d == bd and f < bf):
                    bf, bd = f, d
        out[p] = bf
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "fandisk", "stanford-bunny"])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    args = ap.parse_args()
    import qemjax
    from qemjax._mesh import grid_nearest
    from qemjax._pipeline import refit as refit_mod

    print(f"# python experiments/probes/local_refit.py --meshes {' '.join(args.meshes)} --ratios "
          f"{' '.join(map(str, args.ratios))}")
    print("| case | samples | attached elsewhere | global attach ms | local attach ms | rms global | rms local "
          "| local / global rms | max global | max local | local / global max |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    plain = refit_mod._attach
    for name in args.meshes:
        bm = bench_meshes.load(name)
        for ratio in args.ratios:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                base = qemjax.simplify((bm.V, bm.F), ratio=ratio,
                                       method=dataclasses.replace(qemjax.QEM.default(), refit=0))
                V, F = np.asarray(base.input_vertices, np.float64), np.asarray(base.input_faces, np.int64)
                n, m = len(V), len(F)
                vmap = np.asarray(base.vertex_map, np.int64)
                images = np.full((n + m, 3), -1, np.int64)
                images[:n, 0] = vmap
                images[n:] = vmap[F]
                nimg = np.r_[np.ones(n, np.int64), np.full(m, 3, np.int64)]
                seen = {}

                def local_attach(X, G, gpart, P, spart):
                    if len(P) != n + m or len(np.unique(gpart)) != 1:  # samples dropped or several parts
                        raise RuntimeError("case outside this experiment: zero-area faces or parts")
                    start, faces = _csr(G, len(X))
                    f = _local(P, X, G, start, faces, images, nimg)
                    t = []
                    for _ in range(5):
                        t0 = time.perf_counter()
                        _local(P, X, G, start, faces, images, nimg)
                        t.append(time.perf_counter() - t0)
                    tg = []
                    for _ in range(5):
                        t0 = time.perf_counter()
                        fg = grid_nearest.nearest(X, G, P)[0]
                        tg.append(time.perf_counter() - t0)
                    seen.update(samples=len(P), elsewhere=int(np.sum(f != fg)), local_s=min(t), global_s=min(tg))
                    return f.astype(np.int64)

                glob = qemjax.simplify((bm.V, bm.F), ratio=ratio)
                refit_mod._attach = local_attach
                try:
                    loc = qemjax.simplify((bm.V, bm.F), ratio=ratio)
                except RuntimeError as e:
                    print(f"| {name} {ratio} | {e} |")
                    continue
                finally:
                    refit_mod._attach = plain
            gs, ls = glob.stats, loc.stats
            print(f"| {name} {ratio} | {seen['samples']} | {seen['elsewhere']} "
                  f"({seen['elsewhere'] / seen['samples']:.2%}) | {seen['global_s'] * 1e3:.2f} | "
                  f"{seen['local_s'] * 1e3:.2f} | {gs['distance_rms']:.4g} | {ls['distance_rms']:.4g} | "
                  f"{ls['distance_rms'] / gs['distance_rms']:.4f} | {gs['distance_max']:.4g} | "
                  f"{ls['distance_max']:.4g} | {ls['distance_max'] / gs['distance_max']:.4f} |")


if __name__ == "__main__":
    main()
