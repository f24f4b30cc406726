"""The re-fit's samples weighted toward a higher norm (iteratively reweighted least squares): does it lower
the Hausdorff distance?

The re-fit minimises Σ w_i d_i² (`qemjax._pipeline.refit`, an L2 fit), which trades the largest distances
for the mean. Here each sample's weight is multiplied by floor + (d_i / d_rms)^(p − 2), d_i its distance to
the output before the round's fit (so one round fits toward Σ w d^p), the weights rescaled to the same
sum; ``p=2`` is the package's re-fit. A variant is ``LABEL`` or ``LABEL,p=P,floor=F[,KEY=VALUE...]``
(other keys: keywords of ``simplify``). rms and Hausdorff (relative, `rank_peers.distances`) over the best
peer's of ``--peers CSV`` (a `rank_peers.py` result)::

    python experiments/probes/refit_weights.py --meshes cow fertility --variants base p4,p=4 p4f,p=4,floor=0.2
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from figures.rank_peers import distances  # noqa: E402
from probes.late_memoryless import best_peers, cases  # noqa: E402

WEIGHTING = {}  # the variant's p and floor, read by the patched assembly


def _value(v: str):
    return {"true": True, "false": False}.get(v.lower(), float(v) if v.replace(".", "", 1).isdigit() else v)


def patch():
    """Wrap the re-fit's assembly of the normal equations so that it reweights the samples."""
    from qemjax._pipeline import refit as R

    plain = R._system

    def system(Ps, sw, X, G, f, col, lay, lam):
        p = WEIGHTING.get("p", 2.0)
        if p != 2.0:
            B = R._barycentric_at(Ps, X, G, f, R.slivers(X, G))
            d = np.linalg.norm(np.einsum("ij,ijk->ik", B, X[G[f]]) - Ps, axis=1)
            w = sw ** 2
            scale = WEIGHTING.get("floor", 0.0) + (d / max(np.sqrt((w * d * d).sum() / w.sum()), 1e-300)) ** (p - 2)
            sw = sw * np.sqrt(scale * w.sum() / (w * scale).sum())
        return plain(Ps, sw, X, G, f, col, lay, lam)
    R._system = system


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", default=["base"])
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_min_angle.csv"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import qemjax

    patch()
    best = best_peers(Path(args.peers))
    rows = {v: [] for v in args.variants}
    for name, m, ratio, target, ref in cases(args.meshes, best):
        for v in args.variants:
            items = dict(kv.split("=", 1) for kv in v.split(",")[1:])
            WEIGHTING.clear()
            WEIGHTING.update({k: float(items.pop(k)) for k in ("p", "floor") if k in items})
            res = qemjax.simplify((m.V, m.F), target_faces=target, late_memoryless=0,  # the summed default
                                  **{k: _value(x) for k, x in items.items()})
            d = distances(m.V, m.F, np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64))
            rows[v].append((d["rms_rel"] / ref["rms_rel"], d["hausdorff_rel"] / ref["hausdorff_rel"]))
            print(f"{name:18s} {ratio:5g} {v:28s} rms {rows[v][-1][0]:.3f}  H {rows[v][-1][1]:.3f}", flush=True)
    print()
    for v, rr in rows.items():
        print(f"{v}: rms <= best peer in {sum(a <= 1 for a, _ in rr)}/{len(rr)}; Hausdorff <= best peer in "
              f"{sum(b <= 1 for _, b in rr)}/{len(rr)}; Hausdorff ratio median {np.median([b for _, b in rr]):.3f}")


if __name__ == "__main__":
    main()
