"""The area-difference paper's comparisons (Qi et al., minimum surface-area error) against QEM, reproduced on
the shared meshes, plus the combined cost Q + λ·ΔS²/ℓ² and the kernel's throughput.

    python experiments/figures/area_paper.py                  # everything (about 15 minutes on 2 cores)
    python experiments/figures/area_paper.py --quick          # parallel scheduler only, no λ sweep

Tables (printed as markdown, rows in experiments/results/area_paper.csv):
- Table 1: area at 80 % and 90 % reduction on max-planck-10k, cow and homer: area after / area before,
  and retention = 1 − |ΔA| / A (the paper's 99.97 % vs 94.30 % at 90 %);
- Table 2: retention at 20 / 40 / 60 / 80 % reduction on rocker-arm-small.off (1,600 faces);
- Table 3: two-way Hausdorff distance (relative to the bounding-box diagonal) and squared relative volume
  error (ΔV / V)² at 80 % and 90 %;
- Table 4: run time (seconds without compilation; compilation apart);
- λ sweep of ``area_weight`` with method="qem" at 90 %;
- throughput of the area kernel (pairs per second, CPU) and its share of a run
  (``results/area_kernel.csv``); a picture of both results on max-planck-10k at 90 %
  (``results/area_vs_qem_max_planck.png``).
Both schedulers run: ``greedy`` is the paper's algorithm (a priority queue), ``parallel`` qemjax's default.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))
RESULTS = EXPERIMENTS / "results"
TABLE1_MESHES = ("max-planck-10k", "cow", "homer")
SMALL = "rocker-arm-small"
LAMBDAS = (0.0, 100.0, 1000.0, 10000.0)


def run(V, F, reduction, scheduler, method="qem", area_weight=0.0):
    """One simplification and its measures."""
    import qemjax
    from qemjax import metrics

    target = max(1, int(round((1 - reduction) * len(F))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = qemjax.simplify((V, F), target_faces=target, method=method, scheduler=scheduler,
                            area_weight=area_weight)
    av = metrics.area_volume((V, F), r)
    d = metrics.surface_distance((V, F), r)
    dv = av["volume_change"]
    return dict(reduction=reduction, scheduler=scheduler, method=method, area_weight=area_weight,
                faces=len(r.faces), area_ratio=av["area_retention"],
                retention=1 - abs(av["area_retention"] - 1), volume_change=dv, volume_error_sq=dv * dv,
                hausdorff_rel=d["hausdorff_rel"], rms_rel=d["rms_rel"], run_s=r.stats["run_s"],
                compile_s=r.stats["compile_s"], stop=r.stop_reason,
                branches=" ".join(f"{k}:{v}" for k, v in r.stats["branches"].items()))


def label(row):
    return "area" if row["method"] == "area" else ("qem" if not row["area_weight"] else
                                                   f"qem+λ={row['area_weight']:g}")


def kernel_throughput(out_csv):
    """Pairs per second of the area kernel and of QEM's placement kernel on real rings (max-planck-10k),
    per batch shape, warmed up and blocked on; and the kernel's share of a run (price calls made
    synchronous and timed inside a parallel and a greedy run)."""
    import jax.numpy as jnp
    import pandas as pd

    import meshes as bench
    import qemjax
    from qemjax import _costs
    from qemjax._mesh import topology as topo
    from qemjax._costs import area, ring
    from qemjax._mesh.incidence import FaceLists
    from qemjax._mesh.units import normalize

    bm = bench.load("max-planck-10k")
    Vn, _ = normalize(bm.V, np.float32)
    E, _ = topo.edges(bm.F, len(Vn))
    fl = FaceLists(bm.F, len(Vn))
    VS = jnp.asarray(np.concatenate([np.c_[Vn, np.zeros(len(Vn), np.float32)], np.zeros((1, 4), np.float32)]))
    groups = list(ring.gather_groups(fl, E, len(Vn), with_dead=True))
    idx, rg = max(groups, key=lambda g: len(g[0]))  # the common ring size
    rows = []
    params = qemjax.AreaDifference().kernel_params()
    qem = qemjax.QEM()
    VQ = np.zeros((len(Vn) + 1, 13), np.float32)
    VQ[: len(Vn), :3] = Vn
    VQ[: len(Vn), 3:] = qem.init_state(_costs.MeshInput(Vn, bm.F, None, None))
    VQd, qp = jnp.asarray(VQ), qem.kernel_params()
    for K in (256, 4096, 65536):
        sel = np.resize(np.arange(len(idx)), K)
        P, C, M = E[idx][sel].astype(np.int32), rg.corners[sel], rg.mask[sel]
        for name, call in (("area", lambda: area._price(VS, P, params, C, M)),
                           ("qem placement", lambda: qem.price(VQd, P, qp))):
            call().block_until_ready()
            reps, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < 2.0:
                call().block_until_ready()
                reps += 1
            dt = (time.perf_counter() - t0) / reps
            rows.append(dict(kernel=name, batch=K, ring=rg.corners.shape[1], seconds=dt, pairs_per_s=K / dt))
            print(f"{name:14s} batch {K:6d} ring {rg.corners.shape[1]}: {K / dt:12,.0f} pairs/s", flush=True)
    # share of a run
    orig = area.AreaDifference.price
    spent = [0.0]

    def timed(self, *a, **k):
        t0 = time.perf_counter()
        out = orig(self, *a, **k)
        out = np.asarray(out)  # wait for it
        spent[0] += time.perf_counter() - t0
        return out
    for scheduler in ("parallel", "greedy"):
        qemjax.simplify((bm.V, bm.F), ratio=0.1, method="area", scheduler=scheduler)  # compile first
        area.AreaDifference.price = timed
        spent[0] = 0.0
        try:
            r = qemjax.simplify((bm.V, bm.F), ratio=0.1, method="area", scheduler=scheduler)
        finally:
            area.AreaDifference.price = orig
        share = spent[0] / r.stats["total_s"]
        rows.append(dict(kernel=f"area share of a {scheduler} run", batch=np.nan, ring=np.nan,
                         seconds=spent[0], pairs_per_s=np.nan, run_s=r.stats["total_s"], share=share))
        print(f"area kernel in a {scheduler} run (max-planck-10k → 10 %): {spent[0]:.2f} s of "
              f"{r.stats['total_s']:.2f} s ({100 * share:.0f} %)", flush=True)
    pd.DataFrame(rows).to_csv(out_csv, index=False)


def picture(rows_by_key, bm, path):
    from qemjax import render

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 5.6), dpi=110)
    items = [("input", (bm.V, bm.F))] + list(rows_by_key.items())
    for i, (title, mesh) in enumerate(items):
        ax = fig.add_subplot(1, len(items), i + 1, projection="3d")
        render.render(mesh, ax=ax, title=title, edges=i > 0, view=(10, 110))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="parallel scheduler only, no λ sweep or kernel timing")
    ap.add_argument("--out", default=str(RESULTS / "area_paper.csv"))
    args = ap.parse_args()
    import pandas as pd

    import meshes as bench
    import qemjax

    schedulers = ("parallel",) if args.quick else ("greedy", "parallel")
    rows = []

    def add(mesh, table, **kw):
        bm = bench.load(mesh)
        row = dict(mesh=mesh, faces_in=len(bm.F), table=table, **run(bm.V, bm.F, **kw))
        rows.append(row)
        print(f"{mesh:16s} {row['scheduler']:8s} {label(row):12s} -{100 * row['reduction']:.0f}%: "
              f"area {100 * row['area_ratio']:.3f} %  H {row['hausdorff_rel']:.2e}  "
              f"(dV/V)² {row['volume_error_sq']:.2e}  {row['run_s']:.2f} s  {row['branches']}", flush=True)

    for mesh in TABLE1_MESHES:
        for reduction in (0.8, 0.9):
            for scheduler in schedulers:
                for method in ("qem", "area"):
                    add(mesh, "1,3,4", reduction=reduction, scheduler=scheduler, method=method)
    for reduction in (0.2, 0.4, 0.6, 0.8):
        for scheduler in schedulers:
            for method in ("qem", "area"):
                add(SMALL, "2", reduction=reduction, scheduler=scheduler, method=method)
    if not args.quick:
        for mesh in TABLE1_MESHES + (SMALL,):
            for lam in LAMBDAS:
                add(mesh, "λ", reduction=0.9, scheduler="parallel", method="qem", area_weight=lam)
    df = pd.DataFrame(rows)
    RESULTS.mkdir(exist_ok=True)
    df.to_csv(args.out, index=False)
    summary(df)
    bm = bench.load("max-planck-10k")
    shown = {}
    for method in ("qem", "area"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = qemjax.simplify((bm.V, bm.F), ratio=0.1, method=method)
        shown[f"{method}, 10 % ({len(r.faces)} faces)"] = (r.vertices, r.faces)
    picture(shown, bm, RESULTS / "area_vs_qem_max_planck.png")
    if not args.quick:
        kernel_throughput(RESULTS / "area_kernel.csv")


def summary(df):
    df = df.assign(label=[label(r) for r in df.to_dict("records")])
    for table, cols, fmt in (
            ("1,3,4", ["area_ratio", "retention", "hausdorff_rel", "volume_error_sq", "run_s", "compile_s"],
             ["{:.4%}", "{:.4%}", "{:.2e}", "{:.2e}", "{:.2f}", "{:.2f}"]),
            ("2", ["area_ratio", "retention", "hausdorff_rel", "run_s"], ["{:.4%}", "{:.4%}", "{:.2e}", "{:.2f}"]),
            ("λ", ["area_ratio", "retention", "hausdorff_rel", "rms_rel", "volume_error_sq"],
             ["{:.4%}", "{:.4%}", "{:.2e}", "{:.2e}", "{:.2e}"])):
        g = df[df.table == table]
        if g.empty:
            continue
        print("\n| mesh | reduction | scheduler | method | " + " | ".join(cols) + " |")
        print("|---|---|---|---|" + "---|" * len(cols))
        for r in g.sort_values(["mesh", "reduction", "scheduler", "area_weight"]).to_dict("records"):
            vals = " | ".join(f.format(r[c]) for c, f in zip(cols, fmt))
            print(f"| {r['mesh']} | {100 * r['reduction']:.0f} % | {r['scheduler']} | {r['label']} | {vals} |")


if __name__ == "__main__":
    main()
