"""Edge flips after the default run: do flips that raise the smallest angle of an edge's two faces, only where
the two faces are nearly coplanar, remove slivers without costing distance?

For every benchmark mesh at 10 % and 1 % (targets as `figures/rank_peers.py`): the default run; then passes
of edge flips until none applies (an interior edge ab with faces abc and bad becomes cd when cd is not an
edge yet, a and b keep three neighbours or more, the smallest angle of the two faces rises, and the normals
of the old and new faces are all within ``--dihedral`` degrees of each other), with and without one re-fit
round to the input afterwards (`qemjax._pipeline.refit.refit`, one part). rms and Hausdorff (relative,
`rank_peers.distances`) over the best peer's, and whether the sliver fraction
(`qemjax.metrics.triangle_quality`) is at or below pymeshlab's, from ``--peers CSV``::

    python experiments/probes/edge_flips.py --dihedral 2 5 10
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
from numba import njit

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from probes.late_memoryless import best_peers, cases  # noqa: E402
from probes.tangential_relax import pymeshlab_slivers, print_totals, score  # noqa: E402


@njit(cache=True)
def _min_angle_cos(p0, p1, p2):
    """The largest cosine of the triangle's three angles (the smallest angle's), -2 for a degenerate one."""
    best = -2.0
    for a, b, c in ((p0, p1, p2), (p1, p2, p0), (p2, p0, p1)):
        u = b - a
        v = c - a
        nu = np.sqrt(np.dot(u, u))
        nv = np.sqrt(np.dot(v, v))
        if nu == 0.0 or nv == 0.0:
            return 2.0
        cs = np.dot(u, v) / (nu * nv)
        if cs > best:
            best = cs
    return best


@njit(cache=True)
def _unit_normal(p0, p1, p2):
    n = np.cross(p1 - p0, p2 - p0)
    ln = np.sqrt(np.dot(n, n))
    if ln == 0.0:
        return n, False
    return n / ln, True


@njit(cache=True)
def _flip_pass(X, G, cos_dihedral, max_passes):
    """Flips on G (m,3) in place (module docstring); returns the number of flips."""
    m = G.shape[0]
    n = X.shape[0]
    flips = 0
    for _ in range(max_passes):
        # edge -> faces, rebuilt each pass (a dict keyed by the sorted pair)
        first = dict()
        second = dict()
        nbr = [set([np.int64(0)]) for _ in range(n)]
        for v in range(n):
            nbr[v].clear()
        for f in range(m):
            for k in range(3):
                a, b = G[f, k], G[f, (k + 1) % 3]
                key = (min(a, b), max(a, b))
                if key in second:
                    second[key] = np.int64(-1)  # three faces or more: not flipped
                elif key in first:
                    second[key] = np.int64(f)
                else:
                    first[key] = np.int64(f)
                nbr[a].add(b)
                nbr[b].add(a)
        done = 0
        touched = np.zeros(m, np.bool_)
        for key, f2 in second.items():
            f1 = first[key]
            if f2 < 0 or touched[f1] or touched[f2]:
                continue
            a, b = key
            # orient: f1 holds a -> b
            k1 = -1
            for k in range(3):
                if G[f1, k] == a and G[f1, (k + 1) % 3] == b:
                    k1 = k
            if k1 < 0:
                f1, f2 = f2, f1
                for k in range(3):
                    if G[f1, k] == a and G[f1, (k + 1) % 3] == b:
                        k1 = k
                if k1 < 0:
                    continue
            c = G[f1, (k1 + 2) % 3]
            d = -1
            for k in range(3):
                if G[f2, k] != a and G[f2, k] != b:
                    d = G[f2, k]
            if d < 0 or c == d or d in nbr[c] or len(nbr[a]) <= 3 or len(nbr[b]) <= 3:
                continue
            pa, pb, pc, pd = X[a], X[b], X[c], X[d]
            before = max(_min_angle_cos(pa, pb, pc), _min_angle_cos(pb, pa, pd))
            after = max(_min_angle_cos(pa, pd, pc), _min_angle_cos(pd, pb, pc))
            if after >= before - 1e-9:
                continue
            n1, ok1 = _unit_normal(pa, pb, pc)
            n2, ok2 = _unit_normal(pb, pa, pd)
            n3, ok3 = _unit_normal(pa, pd, pc)
            n4, ok4 = _unit_normal(pd, pb, pc)
            if not (ok1 and ok2 and ok3 and ok4):
                continue
            if (np.dot(n1, n2) < cos_dihedral or np.dot(n3, n4) < cos_dihedral or np.dot(n1, n3) < cos_dihedral
                    or np.dot(n1, n4) < cos_dihedral or np.dot(n2, n3) < cos_dihedral
                    or np.dot(n2, n4) < cos_dihedral):
                continue
            G[f1, 0], G[f1, 1], G[f1, 2] = a, d, c
            G[f2, 0], G[f2, 1], G[f2, 2] = d, b, c
            nbr[a].discard(b)
            nbr[b].discard(a)
            nbr[c].add(d)
            nbr[d].add(c)
            touched[f1] = True
            touched[f2] = True
            done += 1
        flips += done
        if done == 0:
            break
    return flips


def flip_edges(X, G, dihedral_deg: float, max_passes: int = 20):
    G = np.ascontiguousarray(G, np.int64).copy()
    k = _flip_pass(np.ascontiguousarray(X, np.float64), G, np.cos(np.radians(dihedral_deg)), max_passes)
    return G, k


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dihedral", nargs="+", type=float, default=[2.0, 5.0, 10.0])
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_late_memoryless.csv"))
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
        res = qemjax.simplify((m.V, m.F), target_faces=target)
        X0, G0 = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
        outs = [("default", X0, G0)]
        for dh in args.dihedral:
            G, k = flip_edges(X0, G0, dh)
            outs += [(f"flips {dh:g}", X0, G), (f"flips {dh:g}, re-fit", refit(m.V, m.F, X0, G, 1, cos_max), G)]
        print(score(m, name, ratio, ref, pml[(name, ratio)], outs, totals), flush=True)
    print()
    print_totals(totals)


if __name__ == "__main__":
    main()
