"""Where the Hausdorff distance peaks: qemjax (default) and the best peer, per shared mesh and ratio.

For each shared mesh (welded, `meshes.load`) and ratio (10 % and 1 %): qemjax with its defaults and the
peer with the lowest Hausdorff distance in ``results/rank_default_final.csv`` (``--peers-csv``) simplify to ``max(4, round(ratio ·
faces))`` faces. The two-way sampled distance is computed as `qemjax.metrics.surface_distance` does (same
samples, seed 0: every vertex plus 100 000 area-weighted points per mesh, exact point-to-triangle
distances), and the ``--top`` (100) samples with the largest distance, pooled over both directions, are
located on the *original* surface: an original sample where it lies, a sample of the simplified mesh at
its nearest point of the original. Each such location gets the flags (several may hold):

- ``boundary``: within ``r`` of a boundary edge of the original;
- ``crease``: within ``r`` of a sharp edge (dihedral angle between its two faces' normals > 60°);
- ``thin``: the part is thin there: a ray from the point along the inward normal (minus the face normal)
  hits the original surface again within ``2·r``;
- ``elsewhere``: none of these.

``r`` is half the mean edge length of the simplified mesh of that case (the scale a simplified surface
can resolve; it grows as the ratio falls), so "near" means "within half an output edge" and "thin" means
"thinner than one output edge".

Prints a table per case (the top-1 sample's flags, the fraction of the top samples with each flag, which
side holds the maximum: ``fwd`` original → simplified, ``bwd`` simplified → original) and a summary; rows go to
``results/hausdorff_where.csv`` and the printed text to ``results/hausdorff_where.txt``::

    python experiments/figures/hausdorff_where.py
    python experiments/figures/hausdorff_where.py --meshes cow beetle --ratios 0.1 --top 50
    python experiments/figures/hausdorff_where.py --option memoryless=true,memory_weight=0.3 \
        --out experiments/results/hausdorff_where_mem03      # qemjax with these simplify keywords
"""
from __future__ import annotations

import argparse
import csv
import sys
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
import peers as bench_peers  # noqa: E402
from ab_compare import _value  # noqa: E402  (an option value: bool, number or text)
from figures.rank_peers import save_run  # noqa: E402

RESULTS = EXPERIMENTS / "results"
CLASSES = ("boundary", "crease", "thin", "elsewhere")
CREASE_DEG = 60.0
N_SAMPLES = 100_000


def best_peers(path: Path) -> dict:
    """(mesh, ratio) -> the peer with the lowest Hausdorff distance in a rank_peers CSV."""
    best = {}
    with open(path) as fh:
        for r in csv.DictReader(fh):
            if r["method"] in bench_peers.PEERS and r["status"] == "ok":
                key = (r["mesh"], float(r["ratio"]))
                if key not in best or float(r["hausdorff_rel"]) < best[key][1]:
                    best[key] = (r["method"], float(r["hausdorff_rel"]))
    return {k: v[0] for k, v in best.items()}


def edge_features(V: np.ndarray, F: np.ndarray):
    """Boundary edges (b,2) and sharp edges (c,2) (dihedral > CREASE_DEG) of a mesh, and its face normals."""
    cr = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    nrm = np.linalg.norm(cr, axis=1)
    N = cr / np.where(nrm > 0, nrm, 1.0)[:, None]
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    face = np.tile(np.arange(len(F)), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, face = e[order], face[order]
    key = e[:, 0].astype(np.int64) * (len(V) + 1) + e[:, 1]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    boundary = e[starts[counts == 1]]
    two = starts[counts == 2]
    cosang = np.sum(N[face[two]] * N[face[two + 1]], axis=1)
    sharp = e[two[cosang < np.cos(np.radians(CREASE_DEG))]]
    return boundary, sharp, N


def segment_distance(P: np.ndarray, A: np.ndarray, B: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """(q,) distance from each point P (q,3) to the nearest of the segments A–B (s,3); inf without any."""
    out = np.full(len(P), np.inf)
    if len(A) == 0:
        return out
    D = B - A
    dd = np.maximum(np.sum(D * D, 1), 1e-300)
    for s in range(0, len(A), chunk):
        a, d, l2 = A[s:s + chunk], D[s:s + chunk], dd[s:s + chunk]
        w = P[:, None, :] - a[None]
        t = np.clip(np.sum(w * d[None], 2) / l2[None], 0.0, 1.0)
        c = w - t[..., None] * d[None]
        out = np.minimum(out, np.sqrt(np.min(np.sum(c * c, 2), 1)))
    return out


def ray_hits(O: np.ndarray, Dir: np.ndarray, V: np.ndarray, F: np.ndarray, chunk: int = 5000) -> np.ndarray:
    """(q,) distance along each ray (origin O, unit direction Dir) to its first triangle hit beyond a small
    offset (Möller–Trumbore, all triangles); inf when it hits nothing."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = b - a, c - a
    diag = np.linalg.norm(V.max(0) - V.min(0))
    eps = 1e-6 * diag
    best = np.full(len(O), np.inf)
    for s in range(0, len(F), chunk):
        E1, E2, A = e1[s:s + chunk], e2[s:s + chunk], a[s:s + chunk]
        pvec = np.cross(Dir[:, None, :], E2[None])
        det = np.sum(E1[None] * pvec, 2)
        ok = np.abs(det) > 1e-30
        inv = 1.0 / np.where(ok, det, 1.0)
        tvec = O[:, None, :] - A[None]
        u = np.sum(tvec * pvec, 2) * inv
        qvec = np.cross(tvec, E1[None])
        v = np.sum(Dir[:, None, :] * qvec, 2) * inv
        t = np.sum(E2[None] * qvec, 2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > eps)
        best = np.minimum(best, np.min(np.where(hit, t, np.inf), 1))
    return best


def two_way_points(o, s, seed: int = 0):
    """The samples and distances of `metrics.surface_distance` (same seeds): original points, their distance
    to s; simplified points, their distance to o and nearest face of o."""
    from qemjax.metrics._distance import sample_points
    from qemjax._mesh.nearest import nearest_triangles

    rng_o, rng_s = (np.random.default_rng(ss) for ss in np.random.SeedSequence(seed).spawn(2))
    pts_o = sample_points(o, N_SAMPLES, rng_o)
    pts_s = sample_points(s, N_SAMPLES, rng_s)
    d_fwd, _ = nearest_triangles(s.corners, pts_o)
    d_bwd, _ = nearest_triangles(o.corners, pts_s)
    return pts_o, d_fwd, pts_s, d_bwd


def classify(V, F, V2, F2, feats, top: int) -> dict:
    """Locate and class the ``top`` largest two-way distances of the simplification (V2, F2) of (V, F)."""
    import trimesh.triangles

    from qemjax.metrics import _common
    from qemjax._mesh.nearest import nearest_triangles

    boundary, sharp, N = feats
    o, s = _common.as_mesh((V, F)), _common.as_mesh((V2, F2))
    pts_o, d_fwd, pts_s, d_bwd = two_way_points(o, s)
    d = np.concatenate([d_fwd, d_bwd])
    pts = np.concatenate([pts_o, pts_s])
    side = np.r_[np.zeros(len(d_fwd), bool), np.ones(len(d_bwd), bool)]
    idx = np.argsort(-d, kind="stable")[:top]
    P = pts[idx]
    _, face = nearest_triangles(o.corners, P)
    P = trimesh.triangles.closest_point(V[F[face]], P)  # on the original (original samples: themselves)
    e = V2[np.concatenate([F2[:, [0, 1]], F2[:, [1, 2]], F2[:, [2, 0]]])]
    r = 0.5 * float(np.mean(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)))
    d_b = segment_distance(P, V[boundary[:, 0]], V[boundary[:, 1]])
    d_c = segment_distance(P, V[sharp[:, 0]], V[sharp[:, 1]])
    n = N[face]
    thick = ray_hits(P - 1e-7 * r * n, -n, V, F)
    flags = np.stack([d_b <= r, d_c <= r, thick <= 2 * r], 1)
    flags = np.concatenate([flags, ~flags.any(1, keepdims=True)], 1)  # (top, 4): CLASSES
    diag = o.bbox_diagonal
    frac = {c: float(np.mean(flags[:, k])) for k, c in enumerate(CLASSES)}
    return dict(hausdorff_rel=float(d.max() / diag), side="bwd" if side[idx[0]] else "fwd",
                top1="+".join(c for k, c in enumerate(CLASSES) if flags[0, k]), r_rel=r / diag,
                top1_thick_rel=float(thick[0] / diag),
                top1_boundary_rel=float(d_b[0] / diag), top1_crease_rel=float(d_c[0] / diag),
                top_d_min_rel=float(d[idx[-1]] / diag), **{f"frac_{c}": frac[c] for c in CLASSES})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=None, help="shared mesh names (default: all)")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--top", type=int, default=100, help="samples with the largest distance to class")
    ap.add_argument("--peers-csv", default=str(RESULTS / "rank_default_final.csv"),
                    help="rank_peers CSV naming the best peer (lowest Hausdorff) per case")
    ap.add_argument("--option", default="", metavar="K=V,...",
                    help="simplify keywords for qemjax (true/false: bools, numbers: floats)")
    ap.add_argument("--out", default=str(RESULTS / "hausdorff_where"), help="path without extension")
    args = ap.parse_args(argv)
    options = {k: _value(v) for k, v in (kv.split("=", 1) for kv in filter(None, args.option.split(",")))}
    warnings.simplefilter("ignore")
    import qemjax

    best = best_peers(Path(args.peers_csv))
    names = args.meshes or list(bench_meshes.shared_files())
    if not names:
        raise SystemExit("no shared meshes (../shared/meshes is absent)")
    rows = []
    for name in names:
        mesh = bench_meshes.load(name)
        V, F = np.asarray(mesh.V, np.float64), np.asarray(mesh.F, np.int64)
        feats = edge_features(V, F)
        for ratio in args.ratios:
            target = max(4, int(round(ratio * mesh.n_faces)))
            peer = best.get((name, ratio))
            res = qemjax.simplify((mesh.V, mesh.F), target_faces=target, **options)
            outs = [("qemjax", np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64))]
            if peer is not None:
                V2, F2, _ = bench_peers.run_peer(peer, mesh.V, mesh.F, target)
                outs.append((peer, np.asarray(V2, np.float64), np.asarray(F2, np.int64)))
            for method, V2, F2 in outs:
                row = dict(mesh=name, ratio=ratio, target=target, method=method,
                           role="qemjax" if method == "qemjax" else "best_peer",
                           n_boundary_edges=len(feats[0]), n_sharp_edges=len(feats[1]),
                           **classify(V, F, V2, F2, feats, args.top))
                rows.append(row)
                print(f"{name} @ {ratio:g} {method}: H {row['hausdorff_rel']:.3e} ({row['side']}) top1 "
                      f"{row['top1']}; " + " ".join(f"{c} {row['frac_' + c]:.2f}" for c in CLASSES), flush=True)
    text = report(rows, args.top)
    print(text)
    save_run(args.out, rows, list(rows[0]), text, "hausdorff_where.py", argv)
    return 0


def flag_counts(rows: list[dict]) -> str:
    """How many rows' top-1 sample has each flag (a sample may have several)."""
    c = Counter(f for r in rows for f in r["top1"].split("+"))
    return ", ".join(f"{k} {c.get(k, 0)}" for k in CLASSES)


def report(rows: list[dict], top: int) -> str:
    lines = [f"| mesh | ratio | method | H (rel) | H / qemjax H | side | r (rel) | top-1 flags | top-{top} with flag: "
             + " / ".join(CLASSES) + " |", "|---|---|---|---|---|---|---|---|---|"]  # a sample may have several
    own = {(r["mesh"], r["ratio"]): r for r in rows if r["role"] == "qemjax"}
    for r in rows:
        h0 = own[(r["mesh"], r["ratio"])]["hausdorff_rel"]
        lines.append(f"| {r['mesh']} | {r['ratio']:g} | {r['method']} | {r['hausdorff_rel']:.3e} | "
                     f"{r['hausdorff_rel'] / h0:.3f} | {r['side']} | {r['r_rel']:.2e} | {r['top1']} | "
                     + " / ".join(f"{r['frac_' + c]:.2f}" for c in CLASSES) + " |")
    lines.append("")
    for role in ("qemjax", "best_peer"):
        sel = [r for r in rows if r["role"] == role]
        if not sel:
            continue
        lines.append(f"{role}: top-1 sample's flags over {len(sel)} cases: " + flag_counts(sel)
                     + "; mean fraction of the top samples: "
                     + ", ".join(f"{k} {np.mean([r['frac_' + k] for r in sel]):.2f}" for k in CLASSES)
                     + f"; max on the bwd side in {sum(r['side'] == 'bwd' for r in sel)}")
    lag = [own[k] for k in own if any(r["role"] == "best_peer" and (r["mesh"], r["ratio"]) == k
                                      and r["hausdorff_rel"] < own[k]["hausdorff_rel"] for r in rows)]
    if lag:
        lines.append(f"cases where qemjax's Hausdorff > the best peer's ({len(lag)}): qemjax's top-1 flags "
                     + flag_counts(lag)
                     + f"; max on the bwd side in {sum(r['side'] == 'bwd' for r in lag)}")
        for ratio in sorted({r["ratio"] for r in lag}, reverse=True):
            sub = [r for r in lag if r["ratio"] == ratio]
            lines.append(f"  at {ratio:g} ({len(sub)}): " + flag_counts(sub))
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
