"""Garland & Heckbert's Figure 3, reproduced: a 10×10 grid of closely spaced cubes simplified with pair
threshold t = 0 (edge contraction: parts shrink and vanish one by one) and t > 0 (aggregation: close
vertices pair up and the cubes merge into one object). Also the 50-part truck from ../shared/meshes.

    python experiments/figures/aggregation_cubes.py            # writes results/aggregation.csv and PNGs
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import trimesh

import qemjax
from qemjax import metrics
from qemjax.render import render

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"


def cube_grid(k: int = 10, size: float = 1.0, gap: float = 0.2):
    """k×k unit cubes (12 faces each) in a plane, ``gap`` apart."""
    b = trimesh.creation.box(extents=(size,) * 3)
    V = np.concatenate([b.vertices + [i * (size + gap), j * (size + gap), 0]
                        for i in range(k) for j in range(k)])
    F = np.concatenate([b.faces + 8 * n for n in range(k * k)])
    return V, F


def run_case(name, V, F, target, t, scheduler, pictures):
    r = qemjax.simplify((V, F), target_faces=target, pair_threshold=t, preserve_topology=False,
                        scheduler=scheduler)
    row = metrics.evaluate((V, F), r, target_faces=target)
    out = {"mesh": name, "faces_in": len(F), "target": target, "pair_threshold": t, "scheduler": scheduler,
           "faces_out": len(r.faces), "close_pairs": r.stats["close_pairs"], "time_s": r.stats["total_s"]}
    out.update({k: row[k] for k in ("components", "components_before", "hausdorff_rel", "rms_rel",
                                    "mean_rel") if k in row})
    if pictures:
        render(r, path=EXPERIMENTS / "results" / f"aggregation_{name}_t{t:g}_{target}.png", view=(60, -60),
               up="z", title=f"{name}: t={t:g}, {len(r.faces)} faces, {out.get('components')} parts")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=str(EXPERIMENTS / "results" / "aggregation.csv"))
    ap.add_argument("--no-pictures", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    V, F = cube_grid()
    if not args.no_pictures:
        render((V, F), path=EXPERIMENTS / "results" / "aggregation_cubes_input.png", view=(60, -60), up="z",
               title=f"input: 100 cubes, {len(F)} faces")
    for scheduler in ("parallel", "greedy"):
        for t in (0.0, 0.3):
            for target in (600, 200, 50):
                rows.append(run_case("cubes", V, F, target, t, scheduler,
                                     not args.no_pictures and scheduler == "parallel"))
    truck = SHARED / "truck.obj"
    if truck.exists():
        m = qemjax.load(truck)
        diag = float(np.linalg.norm(m.vertices.max(0) - m.vertices.min(0)))
        for t in (0.0, 0.01 * diag):
            for ratio in (0.2, 0.05):
                target = int(round(ratio * len(m.faces)))
                rows.append(run_case("truck", m.vertices, m.faces, target, t, "parallel", False))
    df = pd.DataFrame(rows)
    df.to_csv(args.out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(df.to_string(index=False, float_format=lambda v: f"{v:.4g}"))


if __name__ == "__main__":
    main()
