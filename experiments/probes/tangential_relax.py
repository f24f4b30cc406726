"""Tangential relaxation after the default run: does moving each vertex toward its neighbours' centroid
within its tangent plane remove slivers without costing distance?

For every benchmark mesh at 10 % and 1 % (targets as `figures/rank_peers.py`): the default run; then
``--iters`` steps of x ← x + α·T(c − x) (c: the mean of the vertex's neighbours, T: the projection on the
plane of its area-weighted normal; boundary vertices stay; a step that turns a face by 60° or more is undone
at that face's corners), with and without one re-fit round to the input afterwards
(`qemjax._pipeline.refit.refit`, one part). rms and Hausdorff (relative, `rank_peers.distances`) over the
best peer's, and whether the sliver fraction (`qemjax.metrics.triangle_quality`) is at or below pymeshlab's,
from ``--peers CSV`` (a `rank_peers.py` result with a ``slivers`` column)::

    python experiments/probes/tangential_relax.py --iters 3 10 --alpha 0.5
"""
from __future__ import annotations

import argparse
import csv
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from figures.rank_peers import distances  # noqa: E402
from probes.late_memoryless import best_peers, cases  # noqa: E402


def _normals(X, G):
    return np.cross(X[G[:, 1]] - X[G[:, 0]], X[G[:, 2]] - X[G[:, 0]])


def relax(X, G, iters: int, alpha: float) -> np.ndarray:
    """``iters`` tangential relaxation steps of the positions X (k,3) of faces G (module docstring)."""
    X, n = X.copy(), len(X)
    E = np.concatenate([G[:, [0, 1]], G[:, [1, 2]], G[:, [2, 0]]])
    u, c = np.unique(np.sort(E, 1), axis=0, return_counts=True)
    boundary = np.zeros(n, bool)
    boundary[u[c == 1].ravel()] = True
    deg = np.bincount(E[:, 0], minlength=n)
    for _ in range(iters):
        s = np.zeros((n, 3))
        np.add.at(s, E[:, 0], X[E[:, 1]])
        fn = _normals(X, G)
        vn = np.zeros((n, 3))
        for k in range(3):
            np.add.at(vn, G[:, k], fn)
        vn /= np.maximum(np.linalg.norm(vn, axis=1), 1e-300)[:, None]
        d = s / np.maximum(deg, 1)[:, None] - X
        d -= np.einsum("ij,ij->i", d, vn)[:, None] * vn
        d[boundary | (deg == 0)] = 0
        Y = X + alpha * d
        n1 = _normals(Y, G)
        turned = np.einsum("ij,ij->i", fn, n1) <= 0.5 * np.linalg.norm(fn, axis=1) * np.linalg.norm(n1, axis=1)
        undo = np.unique(G[turned])
        Y[undo] = X[undo]
        X = Y
    return X


def pymeshlab_slivers(path) -> dict:
    """{(mesh, ratio): pymeshlab's sliver fraction} of a `rank_peers.py` CSV with a ``slivers`` column."""
    return {(r["mesh"], float(r["ratio"])): float(r["slivers"]) for r in csv.DictReader(open(path))
            if r["method"] == "pymeshlab" and r.get("slivers")}


def score(m, name, ratio, ref, pml: float, outs, totals: dict) -> str:
    """One case's line: for each (label, positions, faces) of ``outs``, rms and Hausdorff over the best peer's
    ``ref`` and the sliver fraction (at or below pymeshlab's ``pml`` counted in ``totals[label]``)."""
    from qemjax.metrics import triangle_quality

    line = f"{name:16s} {ratio:5g} pymeshlab slivers {pml:.3f}"
    for label, X, G in outs:
        d = distances(m.V, m.F, X, G)
        s = triangle_quality((X, G))["sliver_fraction"]
        r = (d["rms_rel"] / ref["rms_rel"], d["hausdorff_rel"] / ref["hausdorff_rel"], s <= pml)
        totals.setdefault(label, []).append(r)
        line += f" | {label}: rms {r[0]:.3f} H {r[1]:.3f} slivers {s:.3f}"
    return line


def print_totals(totals: dict) -> None:
    for label, rr in totals.items():
        print(f"{label}: rms <= best peer in {sum(a <= 1 for a, _, _ in rr)}/{len(rr)}; Hausdorff <= best peer in "
              f"{sum(b <= 1 for _, b, _ in rr)}/{len(rr)}; slivers <= pymeshlab in {sum(c for _, _, c in rr)}/{len(rr)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iters", nargs="+", type=int, default=[3, 10])
    ap.add_argument("--alpha", type=float, default=0.5)
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_min_angle.csv"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax._pipeline.refit import refit

    best = best_peers(Path(args.peers))
    pml = pymeshlab_slivers(args.peers)
    cos_max = qemjax.Topology().cos_max
    totals = {}
    for name, m, ratio, target, ref in cases(args.meshes, best):
        if (name, ratio) not in pml:
            continue
        res = qemjax.simplify((m.V, m.F), target_faces=target, late_memoryless=0)  # the summed default
        X0, G = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
        outs = [("default", X0, G)]
        for it in args.iters:
            Xr = relax(X0, G, it, args.alpha)
            outs += [(f"relax {it}, re-fit", refit(m.V, m.F, Xr, G, 1, cos_max), G), (f"relax {it}", Xr, G)]
        print(score(m, name, ratio, ref, pml[(name, ratio)], outs, totals), flush=True)
    print()
    print_totals(totals)


if __name__ == "__main__":
    main()
