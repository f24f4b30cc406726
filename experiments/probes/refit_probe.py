"""Probe (issue 22, suzanne at 12 faces): does a post-pass that re-fits the output's vertex positions to
the input surface (Hoppe et al. 1993's continuous step: project input samples on the output, then solve the
linear least squares for the vertex positions, a few times) lower the rms of the default and of the
``accurate`` preset, at very coarse and at ordinary face counts?

The fit here is a prototype on the results of `simplify` (numpy/scipy, float64): samples = every input
vertex + every input face's centroid, weighted by a third of the area around the vertex / the face's area;
each is attached to its nearest output triangle by barycentric coordinates; then argmin_X Σ w_i |B_i X − p_i|²
+ damping·w̄·Σ_v |x_v − x_v⁰|² (the damping holds vertices that no sample sees); ``iters`` rounds. Only
positions move; faces stay. Variants use `rank_peers.py --variant` syntax; ``+fit`` after a label's options
(``fitN=k``) is not a simplify option, so this script takes ``--iters`` and ``--damping`` and reports every
variant with and without the fit::

    python experiments/probes/refit_probe.py --meshes suzanne --targets 10 12 14 --variant base --variant accurate:preset=accurate --out experiments/results/refit_probe_suzanne

The committed results (``results/refit_probe_*``) ran at 354c1da, before ``simplify(refit=)`` existed:
their ``preset=accurate`` had no re-fit. The preset now re-fits itself, so to repeat them name its options
instead (``experiments/probes/refit_parts.py``'s NOFIT). ``simplify(refit=N)`` (`qemjax._pipeline.refit`) is this
probe made an option, with per-part attachment and a flip rule added.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from figures.rank_peers import distances, parse_variant, save_run, variant_runner  # noqa: E402

RESULTS = EXPERIMENTS / "results"


def closest_bary(p, a, b, c):
    """Barycentric coordinates (q,3) of the closest point of triangle abc to p (Ericson 5.1.5), rows."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    out = np.zeros((len(p), 3))
    done = np.zeros(len(p), bool)

    def put(mask, u, v, w):
        m = mask & ~done
        out[m] = np.stack([u, v, w], 1)[m]
        done[m] = True
    one, zero = np.ones(len(p)), np.zeros(len(p))
    put((d1 <= 0) & (d2 <= 0), one, zero, zero)
    put((d3 >= 0) & (d4 <= d3), zero, one, zero)
    put((d6 >= 0) & (d5 <= d6), zero, zero, one)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.nan_to_num(d1 / (d1 - d3))
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), 1 - t, t, zero)
        t = np.nan_to_num(d2 / (d2 - d6))
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), 1 - t, zero, t)
        t = np.nan_to_num((d4 - d3) / ((d4 - d3) + (d5 - d6)))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), zero, 1 - t, t)
        den = va + vb + vc
        den = np.where(den != 0, den, 1.0)
        v, w = vb / den, vc / den
    put(np.ones(len(p), bool), 1 - v - w, v, w)
    return out


def samples(V, F):
    """Input samples and weights: vertices (a third of the area around each) and face centroids (area)."""
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    wv = np.bincount(F.ravel(), weights=np.repeat(area / 3, 3), minlength=len(V))
    P = np.concatenate([V, V[F].mean(1)])
    w = np.concatenate([wv, area])
    keep = w > 0
    return P[keep], w[keep] / w[keep].mean()


# barycentric sample points on each output face (bwd term): the centroid, and the midpoints between it
# and the corners and the edge midpoints
_BWD = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3],
                 [0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5]])


def refit(V, F, X, G, iters=3, damping=1e-3, bwd=0.0, power=0.0):
    """Output positions X (k,3) of faces G re-fitted to the input (V, F) (module docstring). bwd: weight of
    the other direction (points on the output's faces to their nearest input points; its total weight is
    bwd times the forward samples'); power: IRLS, each residual weighted by (r / rms)^power."""
    from qemjax._mesh.nearest import nearest_triangles

    P, w = samples(V, F)
    X = np.array(X, np.float64)
    k = len(X)
    in_corners = np.ascontiguousarray(np.transpose(V[F], (1, 2, 0)))
    for _ in range(iters):
        corners = np.ascontiguousarray(np.transpose(X[G], (1, 2, 0)))
        d, f = nearest_triangles(corners, P)
        tri = G[f]
        B = closest_bary(P, X[tri[:, 0]], X[tri[:, 1]], X[tri[:, 2]])
        ww = w.copy()
        if power:
            ww = ww * (d / max(np.sqrt(np.mean(d * d)), 1e-300)) ** power
        rows = np.repeat(np.arange(len(P)), 3)
        A = sp.csr_matrix((B.ravel() * np.repeat(np.sqrt(ww), 3), (rows, tri.ravel())), shape=(len(P), k))
        rhs = A.T @ (P * np.sqrt(ww)[:, None])
        N = A.T @ A
        if bwd:
            area = 0.5 * np.linalg.norm(np.cross(X[G[:, 1]] - X[G[:, 0]], X[G[:, 2]] - X[G[:, 0]]), axis=1)
            S = np.einsum("sc,fcx->fsx", _BWD, X[G]).reshape(-1, 3)
            Bs = np.tile(_BWD, (len(G), 1))
            ts = np.repeat(G, len(_BWD), axis=0)
            ws = np.repeat(area, len(_BWD))
            ws = bwd * ws * (w.sum() / max(ws.sum(), 1e-300))
            d2, f2 = nearest_triangles(in_corners, S)
            fi = F[f2]
            Q = np.einsum("qc,qcx->qx", closest_bary(S, V[fi[:, 0]], V[fi[:, 1]], V[fi[:, 2]]), V[fi])
            if power:
                ws = ws * (d2 / max(np.sqrt(np.mean(d2 * d2)), 1e-300)) ** power
            rs = np.repeat(np.arange(len(S)), 3)
            A2 = sp.csr_matrix((Bs.ravel() * np.repeat(np.sqrt(ws), 3), (rs, ts.ravel())), shape=(len(S), k))
            N = N + A2.T @ A2
            rhs = rhs + A2.T @ (Q * np.sqrt(ws)[:, None])
        lam = damping * w.sum() / k
        N = (N + lam * sp.identity(k)).tocsc()
        rhs = rhs + lam * X
        solve = spla.factorized(N)
        X = np.stack([solve(rhs[:, i]) for i in range(3)], 1)
    return X


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", required=True)
    ap.add_argument("--targets", nargs="*", type=int, default=None, help="face targets (default: --ratios)")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--variant", action="append", required=True, help="as rank_peers.py --variant")
    ap.add_argument("--iters", type=int, default=3)
    ap.add_argument("--damping", type=float, default=1e-3)
    ap.add_argument("--bwd", type=float, default=0.0, help="weight of the output-to-input direction")
    ap.add_argument("--power", type=float, default=0.0, help="IRLS exponent on the residuals")
    ap.add_argument("--out", required=True, help="path without extension")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    runners = {label: variant_runner(label, rev, s) for label, rev, s in map(parse_variant, args.variant)}
    labels = list(runners)
    rows, lines = [], ["| mesh | target | faces | " + " | ".join(f"{lb} rms / H | {lb}+fit rms / H" for lb in labels)
                       + " | " + " | ".join(f"{lb}(+fit) / {labels[0]} rms" for lb in labels) + " |",
                       "|---" * (3 + 2 * len(labels) + len(labels)) + "|"]
    for name in args.meshes:
        mesh = bench_meshes.load(name)
        targets = args.targets or [max(4, int(round(r * mesh.n_faces))) for r in args.ratios]
        for target in targets:
            here = {}
            for label, run in runners.items():
                res = run(mesh.V, mesh.F, target)
                X, G = np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64)
                d0 = distances(mesh.V, mesh.F, X, G)
                X2 = refit(mesh.V, mesh.F, X, G, args.iters, args.damping, args.bwd, args.power)
                d1 = distances(mesh.V, mesh.F, X2, G)
                here[label] = (len(G), d0, d1)
                rows.append(dict(mesh=name, target=target, variant=label, faces_out=len(G), rms_rel=d0["rms_rel"],
                                 hausdorff_rel=d0["hausdorff_rel"], fit_rms_rel=d1["rms_rel"],
                                 fit_hausdorff_rel=d1["hausdorff_rel"]))
            b = here[labels[0]][1]["rms_rel"]
            lines.append(f"| {name} | {target} | " + "/".join(str(here[lb][0]) for lb in labels) + " | "
                         + " | ".join(f"{d0['rms_rel']:.3e} / {d0['hausdorff_rel']:.3e} | "
                                      f"{d1['rms_rel']:.3e} / {d1['hausdorff_rel']:.3e}"
                                      for _, d0, d1 in here.values())
                         + " | " + " | ".join(f"{here[lb][1]['rms_rel'] / b:.3f} ({here[lb][2]['rms_rel'] / b:.3f})"
                                              for lb in labels) + " |")
            print(lines[-1], flush=True)
    save_run(args.out, rows, list(rows[0]), "\n".join(lines), "refit_probe.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
