"""Where the parallel scheduler's time goes, and how much each round removes.

Runs ``qemjax.simplify`` twice on one mesh (the first call compiles; the second is reported) and prints the
stage times from its stats (topology, kernels, selection with validation inside it, contraction, compile)
and the fraction of faces each round removed. Appends one row per round to ``results/round_profile.csv``.

    python experiments/probes/round_profile.py --mesh armadillo-x16 --ratio 0.01

``--grid NAME`` profiles a batch instead: `simplify_batch` of sweep_bench's grid NAME on the mesh (warm, the
median of ``--repeats`` by wall time), with the batch's stage times as shares of its wall time, beside
one warm default `simplify`'s; prints only (no CSV).

    python experiments/probes/round_profile.py --mesh cow --ratio 0.1 --grid distinct --repeats 5
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402

STAGES = ("topology_s", "kernels_s", "select_s", "validity_s", "contract_s")


def main(argv=None) -> int:
    import pandas as pd

    import qemjax

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", default="armadillo-x16")
    p.add_argument("--ratio", type=float, default=0.01)
    p.add_argument("--out", type=Path, default=EXPERIMENTS / "results" / "round_profile.csv")
    p.add_argument("--grid", default=None, help="profile a batch of this sweep_bench grid instead")
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    mesh = bench_meshes.load(args.mesh)
    if args.grid:
        return batch_profile(mesh, args.mesh, args.ratio, args.grid, args.repeats)
    target = max(4, round(args.ratio * mesh.n_faces))
    cold = qemjax.simplify((mesh.V, mesh.F), target_faces=target)
    t0 = time.perf_counter()
    res = qemjax.simplify((mesh.V, mesh.F), target_faces=target)
    wall = time.perf_counter() - t0
    s = res.stats
    faces = np.array([mesh.n_faces] + list(s["faces_per_round"]))
    removed = 1 - faces[1:] / faces[:-1]
    print(f"{args.mesh} -> {args.ratio:g}: {len(res.faces)} faces, {s['rounds']} rounds, warm wall {wall:.2f} s "
          f"(run_s {s['run_s']:.2f}); cold call: {cold.stats['compilations']} compilations, "
          f"compile_s {cold.stats['compile_s']:.2f}")
    other = s["run_s"] - sum(s.get(k, 0.0) for k in STAGES if k != "validity_s")
    for k in STAGES:
        print(f"  {k:12s} {s.get(k, 0.0):6.2f} s" + ("  (inside select_s)" if k == "validity_s" else ""))
    print(f"  {'other':12s} {other:6.2f} s  (input clean-up, quadrics, output)")
    print("  removed per round: " + " ".join(f"{100 * r:.1f}" for r in removed) + " (% of faces)")
    rows = pd.DataFrame({"mesh": args.mesh, "ratio": args.ratio, "round": np.arange(1, len(removed) + 1),
                         "faces_after": faces[1:], "removed_fraction": removed})
    for k in STAGES:
        rows[k + "_total"] = s.get(k, 0.0)
    rows["run_s"], rows["compile_s_cold"] = s["run_s"], cold.stats["compile_s"]
    rows["compilations_cold"] = cold.stats["compilations"]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows.to_csv(args.out, index=False)
    print(f"wrote {args.out}")
    return 0


def batch_profile(mesh, name: str, ratio: float, grid: str, repeats: int) -> int:
    """Stage times of a warm batch (the median run of ``repeats``) and of one warm default run."""
    import qemjax
    from qemjax._sweep.run import expand_grid
    from figures.sweep_bench import GRIDS

    configs = [dict(c, ratio=ratio) for c in expand_grid(GRIDS[grid])]
    qemjax.simplify_batch((mesh.V, mesh.F), configs)
    qemjax.simplify((mesh.V, mesh.F), ratio=ratio)
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        one = qemjax.simplify((mesh.V, mesh.F), ratio=ratio)
        t1 = time.perf_counter()
        out = qemjax.simplify_batch((mesh.V, mesh.F), configs)
        runs.append((time.perf_counter() - t1, out[0].stats, t1 - t0, one.stats))
    wall, s, wall1, s1 = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
    b = s["batch"]
    print(f"{name} -> {ratio:g}, grid {grid!r}: {b['size']} cells, {b['copies']} copies in the rounds, "
          f"{max(r.stats['rounds'] for r in out)} rounds; batch {wall:.3f} s, one default run {wall1:.3f} s "
          f"({wall / wall1:.1f}x); median of {repeats}")
    print(f"  {'stage':12s} {'batch s':>8s} {'share':>6s} {'one run s':>10s} {'share':>6s}")
    for k in STAGES:
        print(f"  {k:12s} {s.get(k, 0.0):8.3f} {s.get(k, 0.0) / wall:6.1%} {s1.get(k, 0.0):10.3f} "
              f"{s1.get(k, 0.0) / wall1:6.1%}" + ("  (inside select_s)" if k == "validity_s" else ""))
    rest, rest1 = (w - sum(st.get(k, 0.0) for k in STAGES if k != "validity_s") for w, st in ((wall, s), (wall1, s1)))
    print(f"  {'other':12s} {rest:8.3f} {rest / wall:6.1%} {rest1:10.3f} {rest1 / wall1:6.1%}  "
          "(set-up, quadrics, outputs, results)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
