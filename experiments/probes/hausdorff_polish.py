"""Probe: a local minimax polish after the default run. Does moving the vertices next to the worst sample
(whichever way it lies) lower the Hausdorff distance without costing rms?

After `qemjax.simplify` (the default), repeat: find the sample farthest from the other surface, both ways
(the input's vertices and face centroids to the output; the output's vertices and face centroids to the
input, as `_pipeline.bound.Checker` samples them); move the output vertex (or face) that carries it toward
the other surface's nearest point; keep the move when the largest distance over both sample sets falls,
no face turns by the flip angle, and the two-way rms (the mean of both sides' area-weighted mean squares) does not rise by more than
``--rms-slack`` (of the default's); stop when the worst sample's move is refused. The ranking's measure
(`metrics.surface_distance`, seed 0, as `figures/rank_peers.py`) is then taken of both, against the best
peer's from ``--peers`` (a rank_peers CSV)::

    python experiments/probes/hausdorff_polish.py --peers experiments/results/rank_boundary_weight.csv
    python experiments/probes/hausdorff_polish.py --meshes cow face --ratios 0.1 --iters 50
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

import meshes as bench_meshes  # noqa: E402

PEERS = ("meshoptimizer", "fast-simplification", "pyfqmr", "pymeshlab", "libigl")


def best_peers(path):
    best = {}
    for r in csv.DictReader(open(path)):
        if r["method"] in PEERS and r["status"] == "ok":
            k = (r["mesh"], float(r["ratio"]))
            b = best.setdefault(k, [np.inf, np.inf])
            b[0] = min(b[0], float(r["rms_rel"]))
            b[1] = min(b[1], float(r["hausdorff_rel"]))
    return best


def polish(V, F, X, G, iters, rms_slack, cos_max=0.0):
    """The probe's polish (module docstring) in the input's unit frame; returns (X, moves made)."""
    from qemjax._mesh.arrays import face_normals
    from qemjax._mesh.grid_nearest import nearest, slivers
    from qemjax._pipeline.fit_rules import _barycentric_at
    from qemjax._pipeline.refit import _sample_rows, unit_frame

    centre, unit = unit_frame(V)
    Vn, Xn = (V - centre) / unit, (X - centre) / unit
    P, w, _ = _sample_rows(Vn, F, np.zeros(len(V), np.int64))
    used = np.unique(G)

    # the output's samples: its vertices, then per face the barycentric points of BARY (edge midpoints,
    # the centroid, points toward each corner): a coarse face bulges between its corners
    BARY = np.array([[.5, .5, 0], [0, .5, .5], [.5, 0, .5], [1 / 3, 1 / 3, 1 / 3],
                     [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
    owner = np.concatenate([np.full(len(used), -1), np.repeat(np.arange(len(G)), len(BARY))])
    bw = np.tile(BARY, (len(G), 1))

    def state(Y):
        f, d = nearest(Y, G, P)
        T = Y[G]  # (j,3,3)
        Q = np.concatenate([Y[used], np.einsum("kb,kbx->kx", bw, np.repeat(T, len(BARY), axis=0))])
        g, e = nearest(Vn, F, Q)
        a = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
        qw = np.concatenate([np.zeros(len(used)), np.repeat(a / len(BARY), len(BARY))])
        rms = np.sqrt((np.sum(w * d * d) / w.sum() + np.sum(qw * e * e) / qw.sum()) / 2)
        return f, d, Q, g, e, rms

    n0 = face_normals(Xn, G)
    at = [[] for _ in range(len(Xn))]
    for k, t in enumerate(G):
        for v in t:
            at[v].append(k)
    moves = 0
    f, d, Q, g, e, rms = state(Xn)
    rms_limit = rms * (1 + rms_slack)
    for _ in range(iters):
        H = max(d.max(), e.max())
        cands = []
        if d.max() >= e.max():
            i = int(np.argmax(d))
            b = _barycentric_at(P[i:i + 1], Xn, G, f[i:i + 1], slivers(Xn, G))[0]
            tri = G[f[i]]
            c = b @ Xn[tri]
            delta = P[i] - c
            j = int(np.argmax(b))
            for t in (1.0, 0.5, 0.25, 0.125):
                cands.append(({tri[j]: t * delta / max(b[j], 0.5)}))
                cands.append(({v: t * delta for v in tri}))
        else:
            i = int(np.argmax(e))
            bi = _barycentric_at(Q[i:i + 1], Vn, F, g[i:i + 1], slivers(Vn, F))[0]
            r = bi @ Vn[F[g[i]]]
            delta = r - Q[i]
            verts = [used[i]] if owner[i] < 0 else list(G[owner[i]])
            for t in (1.0, 0.5, 0.25, 0.125):
                cands.append({v: t * delta for v in verts})
        for mv in cands:
            Y = Xn.copy()
            for v, dv in mv.items():
                Y[v] = Y[v] + dv
            faces = np.unique(np.concatenate([at[v] for v in mv]))
            n1 = face_normals(Y, G[faces])
            if np.any(np.einsum("ij,ij->i", n0[faces], n1) <= cos_max):
                continue
            s = state(Y)
            if max(s[1].max(), s[4].max()) < H and s[5] <= rms_limit:
                Xn, (f, d, Q, g, e, rms) = Y, s
                moves += 1
                break
        else:
            break
    return Xn * unit + centre, moves


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=None)
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--iters", type=int, default=200)
    ap.add_argument("--rms-slack", type=float, default=0.005)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_boundary_weight.csv"))
    args = ap.parse_args()
    import qemjax
    from qemjax.metrics import surface_distance

    best = best_peers(args.peers)
    names = args.meshes or sorted({k[0] for k in best})
    won = [0, 0, 0, 0]
    print(f"# python experiments/probes/hausdorff_polish.py {' '.join(sys.argv[1:])}")
    print("| mesh | ratio | moves | rms / peer: default, polished | H / peer: default, polished |")
    print("|---|---|---|---|---|")
    for name in names:
        m = bench_meshes.load(name)
        for ratio in args.ratios:
            if (name, ratio) not in best:
                continue
            t = max(4, round(ratio * m.n_faces))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = qemjax.simplify((m.V, m.F), target_faces=t)
            X, G = np.asarray(r.vertices, np.float64), np.asarray(r.faces, np.int64)
            Y, moves = polish(m.V, m.F, X, G, args.iters, args.rms_slack)
            a = surface_distance((m.V, m.F), (X, G), seed=0)
            b = surface_distance((m.V, m.F), (Y, G), seed=0)
            pr, ph = best[(name, ratio)]
            row = (a["rms_rel"] / pr, b["rms_rel"] / pr, a["hausdorff_rel"] / ph, b["hausdorff_rel"] / ph)
            won = [w + (x <= 1) for w, x in zip(won, row)]
            print(f"| {name} | {ratio} | {moves} | {row[0]:.3f}, {row[1]:.3f} | {row[2]:.3f}, {row[3]:.3f} |",
                  flush=True)
    print(f"\nrms <= best peer: default {won[0]}, polished {won[1]}; Hausdorff <= best peer: default {won[2]}, "
          f"polished {won[3]}")


if __name__ == "__main__":
    main()
