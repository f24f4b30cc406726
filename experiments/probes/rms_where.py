"""Where the rms distance comes from: its square split by where each sample lies (boundary, crease, other).

`hausdorff_where.py` looks at the largest distances only; rms is a mean over all samples, so a variant can
win on Hausdorff and lose on rms (beetle at 10 %, issue 22). For each case and qemjax variant (the syntax
of `rank_peers.py --variant`), this takes the two-way samples of `metrics.surface_distance` (seed 0),
places each on the original surface (a simplified sample at its nearest original point) and classes it:
``boundary`` within r of an original boundary edge, else ``crease`` within r of an edge sharper than 60°,
else ``other``; r is half the mean edge length of that variant's output, as in `hausdorff_where`.
rms² = e_gh = Σ d² / N over both sides; the table gives each class's share of that sum (in units of the
first variant's e_gh, so the shares of two variants add up to their e_gh ratio) and the faces out::

    python experiments/probes/rms_where.py --meshes beetle suzanne --ratios 0.1 0.01 --variant base \\
        --variant mem03:memoryless=True,memory_weight=0.3,placement=rank,rank_eps=1e-3,max_shift=0.5
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
from figures.hausdorff_where import edge_features, segment_distance, two_way_points  # noqa: E402
from figures.rank_peers import parse_variant, save_run, variant_runner  # noqa: E402

RESULTS = EXPERIMENTS / "results"
ZONES = ("boundary", "crease", "other")


def zone_shares(V, F, V2, F2, feats) -> dict:
    """e_gh (absolute) and each zone's Σ d² / N (absolute) for the simplification (V2, F2) of (V, F)."""
    import trimesh.triangles

    from qemjax.metrics import _common
    from qemjax._mesh.nearest import nearest_triangles

    boundary, sharp, _ = feats
    o, s = _common.as_mesh((V, F)), _common.as_mesh((V2, F2))
    pts_o, d_fwd, pts_s, d_bwd = two_way_points(o, s)
    _, face = nearest_triangles(o.corners, pts_s)
    P = np.concatenate([pts_o, trimesh.triangles.closest_point(V[F[face]], pts_s)])
    d2 = np.concatenate([d_fwd, d_bwd]) ** 2
    e = V2[np.concatenate([F2[:, [0, 1]], F2[:, [1, 2]], F2[:, [2, 0]]])]
    r = 0.5 * float(np.mean(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)))
    near_b = segment_distance(P, V[boundary[:, 0]], V[boundary[:, 1]]) <= r
    near_c = ~near_b & (segment_distance(P, V[sharp[:, 0]], V[sharp[:, 1]]) <= r)
    masks = {"boundary": near_b, "crease": near_c, "other": ~(near_b | near_c)}
    out = {"e_gh": float(d2.mean()), "diag": o.bbox_diagonal, "faces_out": len(F2)}
    out.update({z: float(d2[m].sum() / len(d2)) for z, m in masks.items()})
    out.update({f"n_{z}": int(m.sum()) for z, m in masks.items()})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", required=True, help="as rank_peers.py --variant")
    ap.add_argument("--meshes", nargs="+", required=True)
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--out", default=str(RESULTS / "rms_where"), help="path without extension")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    variants = [parse_variant(s) for s in args.variant]
    runners = {label: variant_runner(label, rev, settings) for label, rev, settings in variants}
    rows, lines = [], ["| mesh | ratio | variant | faces | rms_rel | e_gh / first | boundary | crease | other |",
                       "|---|---|---|---|---|---|---|---|---|"]
    for name in args.meshes:
        mesh = bench_meshes.load(name)
        V, F = np.asarray(mesh.V, np.float64), np.asarray(mesh.F, np.int64)
        feats = edge_features(V, F)
        for ratio in args.ratios:
            target = max(4, int(round(ratio * mesh.n_faces)))
            first = None
            for label, run in runners.items():
                res = run(mesh.V, mesh.F, target)
                z = zone_shares(V, F, np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64),
                                feats)
                first = first or z["e_gh"]
                rows.append(dict(mesh=name, ratio=ratio, target=target, variant=label, **z))
                lines.append(f"| {name} | {ratio:g} | {label} | {z['faces_out']} | "
                             f"{np.sqrt(z['e_gh']) / z['diag']:.3e} | {z['e_gh'] / first:.3f} | "
                             + " | ".join(f"{z[k] / first:.3f}" for k in ZONES) + " |")
                print(lines[-1], flush=True)
    text = "\n".join(lines)
    save_run(args.out, rows, list(rows[0]), text, "rms_where.py", argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
