"""64 configurations of one mesh → 10 %: `qemjax.sweep` against looping `simplify`, meshoptimizer and
pymeshlab over the same cells, as a multiple of one warm configuration's time (issue 19's goal: ≤ 8×).

Everything is warm: one untimed sweep first compiles every kernel the grid needs. `qemjax.sweep` reads
the mesh once and runs each cell as one `simplify` call (no batched union of configurations yet); the
`simplify` loop is the naive one, from the path each time. The peers have no such parameters: each of the
64 cells is their default call to the same face target. Metrics are off (timing only). Each repeat runs every method, in alternating order. Appends to
``results/sweep_bench.csv``.

    python experiments/sweep_bench.py --meshes cow --repeats 3
"""
from __future__ import annotations

import argparse
import csv
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import meshes as bench_meshes  # noqa: E402
import peers  # noqa: E402

import qemjax  # noqa: E402
from qemjax import _io  # noqa: E402
from qemjax._sweep import expand_grid  # noqa: E402

RESULTS = HERE / "results"
GRID = {"regularize": [0.0, 0.01, 0.03, 0.1], "boundary_weight": [0.5, 1.0, 2.0, 4.0],
        "placement": ["optimal", "endpoints"], "area_weighted": [True, False]}  # 4 × 4 × 2 × 2 = 64
FIELDS = ("date", "mesh", "faces_in", "ratio", "configs", "method", "repeats", "median_s", "per_config_s",
          "vs_one_warm", "times_s")


def bench(name: str, ratio: float, repeats: int) -> list[dict]:
    path = bench_meshes.shared_files()[name]
    configs = expand_grid(GRID)
    (V, F), _ = _io.prepare(qemjax.load(path))  # the peers get the cleaned input
    warm = qemjax.sweep(path, GRID, [ratio], metrics=False, progress=False)  # compiles every kernel
    target = int(warm["target_faces"].iloc[0])
    mesh = qemjax.load(path)

    def loop_simplify():
        for params in configs:
            qemjax.simplify(path, ratio=ratio, **dict(params))

    def loop_peer(peer):
        return lambda: [peers.run_peer(peer, V, F, target) for _ in configs]

    methods = {
        "one warm config (default simplify)": lambda: qemjax.simplify(mesh, ratio=ratio),
        "qemjax.sweep": lambda: qemjax.sweep(path, GRID, [ratio], metrics=False, progress=False),
        "loop simplify": loop_simplify,
        "loop meshoptimizer": loop_peer("meshoptimizer"),
        "loop pymeshlab": loop_peer("pymeshlab"),
        "load (once per mesh)": lambda: qemjax.load(path),
        "load + clean (once per mesh)": lambda: _io.prepare(qemjax.load(path)),
    }
    peers.run_peer("meshoptimizer", V, F, target)  # warm-ups
    peers.run_peer("pymeshlab", V, F, target)
    inside = []  # Σ simplify total_s within each timed sweep: the rest is the sweep's own overhead

    def timed_sweep():
        df = qemjax.sweep(path, GRID, [ratio], metrics=False, progress=False)
        inside.append(float(df["total_s"].sum()))

    methods["qemjax.sweep"] = timed_sweep
    times = {method: [] for method in methods}
    for rep in range(repeats):  # alternate the order: drift on a shared machine hits every method alike
        for method in (list(methods) if rep % 2 == 0 else list(methods)[::-1]):
            t0 = time.perf_counter()
            methods[method]()
            times[method].append(time.perf_counter() - t0)
    times["sum of simplify total_s in the sweep"] = inside
    one = statistics.median(times["one warm config (default simplify)"])
    rows = []
    for method, ts in times.items():
        med = statistics.median(ts)
        n = 1 if method.startswith(("one", "load")) else len(configs)  # the rest cover the 64 cells
        rows.append(dict(date=time.strftime("%Y-%m-%d"), mesh=name, faces_in=len(F), ratio=ratio,
                         configs=n, method=method, repeats=len(ts), median_s=round(med, 4),
                         per_config_s=round(med / n, 4), vs_one_warm=round(med / one, 2),
                         times_s=" ".join(f"{t:.3f}" for t in ts)))
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["cow"])
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", type=Path, default=RESULTS / "sweep_bench.csv")
    args = p.parse_args(argv)
    for name in args.meshes:
        rows = bench(name, args.ratio, args.repeats)
        new = not args.out.exists()
        with open(args.out, "a", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            if new:
                w.writeheader()
            w.writerows(rows)
        print(f"\n{name} ({rows[0]['faces_in']} faces) -> {args.ratio:g}, {len(expand_grid(GRID))} configurations")
        print(f"{'method':40s} {'median s':>9s} {'per config':>11s} {'x one warm':>11s}")
        for r in rows:
            print(f"{r['method']:40s} {r['median_s']:9.3f} {r['per_config_s']:11.4f} {r['vs_one_warm']:11.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
