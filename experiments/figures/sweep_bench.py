"""Many configurations → 10 %: `qemjax.sweep` (batched: `simplify_batch`) against the same sweep with every
cell alone, looping `simplify`, meshoptimizer and pymeshlab over the same cells, as a multiple of one warm
configuration's time (issue 19's goal: 64 configurations of the cow in ≤ 8×).

Everything is warm: untimed sweeps first compile every kernel the grid needs. The `simplify` loop is the
naive one, from the path each time. The peers have no such parameters: each cell is their default call
to the same face target. Metrics are off (timing only). Wall and CPU time (this process) are both
recorded: on a shared machine the CPU time moves less. Each repeat runs every method, in alternating
order; the baseline (one warm configuration) is, in each repeat, the median of 5 runs. ``--meshes small``: the 8 small shared meshes of SMALL in one sweep (8 × 8 = 64 cells); the
baseline is then one warm default configuration per mesh, averaged. For one mesh, the design's bound is
also timed: one `simplify` of a single mesh made of as many disjoint copies as there are configurations
(what a batch computes, without any per-copy bookkeeping), with the seconds of its re-fit and its measured
distance (the default's passes over every input sample, which batching cannot share). Cells that would run exactly alike run once
(`simplify_cells`); the header gives the distinct results and runs (``--grid distinct``: 64 configurations
that all differ on the cow; ``--grid crossed``: boundary weight, regularisation, flip angle, area weighting
and placement crossed). The default sweep runs on every core (``workers=None``: this process and a helper
process per other core, `qemjax._sweep.pool`); the warm-up sweeps start its helpers, so the timed sweeps
find them warm; CPU times count the helpers' too. ``workers=1`` is the sweep in this process alone.
``--pool N`` adds the sweep on N warm worker processes (a `ProcessPoolExecutor` as ``executor=``, the cells
cut into N batches; the workers' start and first compilations are not timed).
The rows "x loop" divide each sweep's median by the `simplify` loop's, same run.

``--fresh N``: instead, the first sweep in a fresh process, N times each, alternating: ``python -c`` runs
the default sweep, the sweep with ``workers=1`` or the `simplify` loop over the same cells, from the
interpreter's start to its exit (helpers included: their start, imports and kernels loaded from the caches
on disk count), timed from here. Appends to ``results/sweep_batch.csv`` (``results/sweep_bench.csv``: the
first measurements, before batching, in an older layout).

    python experiments/figures/sweep_bench.py --meshes cow --grid qem --repeats 3
    python experiments/figures/sweep_bench.py --meshes cow --grid distinct --repeats 5
    python experiments/figures/sweep_bench.py --meshes cow --grid crossed --repeats 5
    python experiments/figures/sweep_bench.py --meshes cow --grid distinct --fresh 3
    python experiments/figures/sweep_bench.py --meshes cow --grid distinct --repeats 3 --pool 2
    python experiments/figures/sweep_bench.py --meshes cow stanford-bunny small --repeats 3
"""
from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

import meshes as bench_meshes  # noqa: E402
import peers  # noqa: E402

import qemjax  # noqa: E402
from qemjax._io import mesh as _io  # noqa: E402
from qemjax._sweep.pool import HELPERS  # noqa: E402
from qemjax._sweep.run import expand_grid  # noqa: E402

RESULTS = EXPERIMENTS / "results"
GRIDS = {
    # the first grid measured: 3/4 of its cells pay the ring term of `regularize` (per-pair work a batch
    # cannot share); two batches (with and without the term)
    "issue": {"regularize": [0.0, 0.01, 0.03, 0.1], "boundary_weight": [0.5, 1.0, 2.0, 4.0],
              "placement": ["optimal", "endpoints"], "area_weighted": [True, False]},
    # QEM settings only: one batch of 64 copies
    "qem": {"boundary_weight": [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 100.0], "placement": ["optimal", "endpoints"],
            "area_weighted": [True, False], "area_power": [1.0, 0.5]},
    # 64 configurations that all give different meshes of the cow (on a closed mesh the 'qem' grid's
    # boundary weights change nothing, nor does area_power without area weighting: 6 distinct results)
    "distinct": {"area_power": [round(2 * (i + 1) / 32, 4) for i in range(32)], "placement": ["optimal", "endpoints"]},
    # the five settings the sweeps issue crosses: 64 cells, 32 distinct runs on the closed cow (boundary weight
    # changes nothing there); four batches (the flip angle and whether the ring term of `regularize` is on
    # split the cells)
    "crossed": {"boundary_weight": [1.0, 10.0], "regularize": [0.0, 0.01, 0.03, 0.1], "flip_angle": [60.0, 90.0],
                "area_weighted": [True, False], "placement": ["optimal", "endpoints"]},
    # 8 configurations, for the batch of many small meshes (8 meshes x 8 = 64 cells)
    "small": {"boundary_weight": [1.0, 100.0], "placement": ["optimal", "endpoints"], "area_weighted": [True, False]},
}
SMALL = ("cow", "fandisk", "max-planck-10k", "rocker-arm-small", "suzanne", "teapot", "3holes", "beetle")
PEERS = ("meshoptimizer", "pymeshlab")  # the peers looped, where installed
FIELDS = ("date", "mesh", "faces_in", "ratio", "grid", "configs", "method", "repeats", "median_s", "per_config_s",
          "vs_one_warm", "median_cpu_s", "cpu_vs_one_warm", "load_avg", "times_s", "distinct_results", "runs",
          "vs_loop", "cores", "load_avg_end")
LOOP = "loop simplify"
# --fresh: what each fresh process runs (after `import qemjax`), timed from the interpreter's start to its exit
FRESH = {"qemjax.sweep (default: every core)":
             "qemjax.sweep({'m': path}, grid, [ratio], metrics=False, progress=False)",
         "qemjax.sweep workers=1 (this process)":
             "qemjax.sweep({'m': path}, grid, [ratio], metrics=False, progress=False, workers=1)",
         LOOP: "[qemjax.simplify(path, ratio=ratio, **dict(p)) for p in expand_grid(grid)]"}


def _helpers_cpu() -> float:
    """The CPU seconds the sweep's helper processes have used so far (Linux: /proc; else 0)."""
    total = 0.0
    with HELPERS.lock:
        pids = [h.proc.pid for h in HELPERS.helpers]
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, IndexError, ValueError):
            pass
    return total


def wait_for_helpers(limit_s: float = 120.0) -> None:
    """Until every helper process the default sweeps started is ready (at most ``limit_s``), so that the timed
    sweeps find them warm."""
    t0 = time.monotonic()
    while HELPERS.ready() < HELPERS.size() and time.monotonic() - t0 < limit_s:
        time.sleep(0.1)


def _clock(fn):
    """(wall, CPU) seconds of fn(): the CPU of this process and of the sweep's helper processes."""
    w, c, h = time.perf_counter(), time.process_time(), _helpers_cpu()
    fn()
    return time.perf_counter() - w, time.process_time() - c + _helpers_cpu() - h


def bench(names: list[str], ratio: float, repeats: int, grid_name: str, pool: int = 0) -> list[dict]:
    files = bench_meshes.shared_files()
    paths = {n: files[n] for n in names}
    grid = GRIDS[grid_name]
    configs = expand_grid(grid)
    cleaned = {n: _io.prepare(qemjax.load(p))[0] for n, p in paths.items()}  # the peers get the cleaned input
    meshes = {n: qemjax.load(p) for n, p in paths.items()}
    warm = qemjax.sweep(meshes, grid, [ratio], metrics=False, progress=False, workers=1)  # compiles every kernel
    qemjax.sweep(meshes, grid, [ratio], metrics=False, progress=False, batch_size=1, workers=1)
    for _ in range(3):  # the default starts its helpers in the second (after a sweep of this much work)
        if not qemjax.sweep(meshes, grid, [ratio], metrics=False, progress=False)["result_sha256"].equals(
                warm["result_sha256"]):
            raise AssertionError("the default sweep (every core) differs from the one in this process")
        wait_for_helpers()
    targets = {n: int(warm.loc[warm["mesh"] == n, "target_faces"].iloc[0]) for n in names}
    # distinct output meshes, and distinct runs (cells that would run alike run once: `simplify_cells`)
    distinct, runs = warm["result_sha256"].nunique(), int((1 / warm["same_run"]).sum().round())
    cells = len(configs) * len(names)
    have = set(peers.available())  # a peer not installed here has no row

    def loop_simplify():
        for n in names:
            for params in configs:
                qemjax.simplify(paths[n], ratio=ratio, **dict(params))

    def loop_peer(peer):
        return lambda: [peers.run_peer(peer, *cleaned[n], targets[n]) for n in names for _ in configs]

    inside = []  # Σ share_s within each timed sweep (the pieces' wall times): the rest is the sweep's own overhead

    def timed_sweep(**kw):
        def go():
            df = qemjax.sweep(meshes, grid, [ratio], metrics=False, progress=False, **kw)
            if kw == {"workers": 1}:
                inside.append(float(df["share_s"].sum()))
        return go

    def one_warm():  # the median of 5 runs: one run of a small mesh is short and varies most
        ts = sorted(_clock(lambda: [qemjax.simplify(meshes[n], ratio=ratio) for n in names]) for _ in range(5))
        return ts[2]

    methods = {
        # the baseline: one warm default configuration of each mesh, averaged over the meshes
        "one warm config (default simplify)": one_warm,
        "qemjax.sweep (default: every core)": timed_sweep(),
        "qemjax.sweep workers=1 (this process)": timed_sweep(workers=1),
        "qemjax.sweep batch_size=1 workers=1 (cells alone)": timed_sweep(batch_size=1, workers=1),
        "loop simplify": loop_simplify,
        **{f"loop {peer}": loop_peer(peer) for peer in PEERS if peer in have},
        "load + clean (once per mesh)": lambda: [_io.prepare(qemjax.load(p)) for p in paths.values()],
    }
    if pool:  # the same sweep on warm worker processes, one batch of cells / pool cells each
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        workers = ProcessPoolExecutor(pool, mp_context=multiprocessing.get_context("spawn"))
        per = -(-cells // pool)
        pooled = lambda: qemjax.sweep(meshes, grid, [ratio], metrics=False, progress=False,  # noqa: E731
                                      executor=workers, batch_size=per)
        for _ in range(2):  # every worker compiles (which worker takes which batch is up to the pool)
            if not pooled()["result_sha256"].equals(warm["result_sha256"]):
                raise AssertionError("the pooled sweep differs from the in-process one")
        methods[f"qemjax.sweep, {pool} worker processes, {per} cells each"] = pooled
    if len(names) == 1:  # the design's bound: one run of a mesh made of len(configs) disjoint copies
        V0, F0 = cleaned[names[0]]
        shift = (V0.max(0) - V0.min(0)) * [1.5, 0, 0]
        union = (np.concatenate([V0 + i * shift for i in range(len(configs))]),
                 np.concatenate([F0 + i * len(V0) for i in range(len(configs))]))
        union_stats = []  # (re-fit s, measured distance s) of each timed run of the union

        def union_run():
            stats = qemjax.simplify(union, ratio=ratio).stats
            union_stats.append((stats["refit_s"], stats["distance_s"] or 0.0))
        methods["one simplify of the union of the copies"] = union_run
        union_run()
        union_stats.clear()
    for n in names:  # warm-ups
        for peer in PEERS:
            if peer in have:
                peers.run_peer(peer, *cleaned[n], targets[n])
    times = {method: [] for method in methods}
    load = os.getloadavg()[0]
    for rep in range(repeats):  # alternate the order: drift on a shared machine hits every method alike
        for method in (list(methods) if rep % 2 == 0 else list(methods)[::-1]):
            fn = methods[method]
            times[method].append(fn() if fn is one_warm else _clock(fn))
    if pool:
        workers.shutdown()
    one = statistics.median(t[0] for t in times["one warm config (default simplify)"]) / len(names)
    one_cpu = statistics.median(t[1] for t in times["one warm config (default simplify)"]) / len(names)
    times["sum of share_s in the sweep workers=1"] = [(t, float("nan")) for t in inside]
    if len(names) == 1:  # what no scheduling can save: the union's passes over every input sample
        times["  the union's re-fit (stats refit_s)"] = [(r, float("nan")) for r, _ in union_stats]
        times["  the union's measured distance"] = [(d, float("nan")) for _, d in union_stats]
    return _rows(names, cleaned, ratio, grid_name, cells, times, one, one_cpu, distinct, runs, load)


def _rows(names, cleaned, ratio, grid_name, cells, times, one, one_cpu, distinct, runs, load) -> list[dict]:
    rows = []
    loop = next((statistics.median(t[0] for t in ts) for m, ts in times.items() if m.endswith(LOOP)), float("nan"))
    for method, ts in times.items():
        med = statistics.median(t[0] for t in ts)
        cpu = statistics.median(t[1] for t in ts)
        n = len(names) if method.startswith(("one", "load")) else cells  # the rest cover every cell
        per_mesh = len(names) if n == len(names) else 1  # the baseline and load rows: per mesh
        sweep = "qemjax.sweep" in method
        rows.append(dict(vs_loop=round(med / loop, 3) if sweep else "", cores=len(os.sched_getaffinity(0)),
                         load_avg_end=round(os.getloadavg()[0], 2), date=time.strftime("%Y-%m-%d"),
                         mesh="+".join(names),
                         faces_in=sum(len(c[1]) for c in cleaned.values()), ratio=ratio, grid=grid_name,
                         configs=n, method=method, repeats=len(ts), median_s=round(med, 4),
                         per_config_s=round(med / n, 4), vs_one_warm=round(med / per_mesh / one, 2),
                         median_cpu_s=round(cpu, 4), cpu_vs_one_warm=round(cpu / per_mesh / one_cpu, 2),
                         load_avg=round(load, 2), times_s=" ".join(f"{w:.3f}/{c:.3f}" for w, c in ts),
                         distinct_results=distinct, runs=runs))
    return rows


def fresh(name: str, ratio: float, repeats: int, grid_name: str) -> list[dict]:
    """The first sweep (or loop) in a fresh process, `FRESH`, each ``repeats`` times in alternating order:
    the wall time from starting the interpreter to its exit, timed here."""
    import subprocess

    path = str(bench_meshes.shared_files()[name])
    grid = GRIDS[grid_name]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(EXPERIMENTS.parent), os.environ.get("PYTHONPATH", "")]))
    code = ("import warnings; warnings.filterwarnings('ignore', 'stopped at'); import qemjax; "
            "from qemjax._sweep.run import expand_grid; "
            f"path, grid, ratio = {path!r}, {grid!r}, {ratio!r}; ")
    times = {method: [] for method in FRESH}
    load = os.getloadavg()[0]
    for rep in range(repeats):
        for method in (list(FRESH) if rep % 2 == 0 else list(FRESH)[::-1]):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-c", code + FRESH[method]], check=True, env=env)
            times[method].append((time.perf_counter() - t, float("nan")))
            print(f"  {method}: {times[method][-1][0]:.2f} s", flush=True)
    V, F = _io.prepare(qemjax.load(path))[0]
    return _rows([name], {name: (V, F)}, ratio, grid_name, len(expand_grid(grid)),
                 {f"fresh process: {m}": t for m, t in times.items()}, float("nan"), float("nan"), "", "", load)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["cow"],
                   help="shared mesh names, each benchmarked on its own; 'small': the 8 meshes of SMALL together")
    p.add_argument("--grid", choices=sorted(GRIDS), default=None,
                   help="default: 'issue' for one mesh, 'small' for the small-mesh batch")
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--pool", type=int, default=0,
                   help="also time the sweep on this many warm worker processes (executor=, one batch each)")
    p.add_argument("--fresh", type=int, default=0,
                   help="instead: the first sweep in a fresh process, this many times each (default, workers=1, loop)")
    p.add_argument("--out", type=Path, default=RESULTS / "sweep_cores.csv")
    args = p.parse_args(argv)
    warnings.filterwarnings("ignore", "stopped at")  # cells that stop short (3holes): the table has their rows
    for name in args.meshes:
        names = list(SMALL) if name == "small" else [name]
        grid = args.grid or ("small" if name == "small" else "issue")
        if args.fresh:
            rows = fresh(name, args.ratio, args.fresh, grid)
        else:
            rows = bench(names, args.ratio, args.repeats, grid, args.pool)
        new = not args.out.exists()
        with open(args.out, "a", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            if new:
                w.writeheader()
            w.writerows(rows)
        print(f"\n{rows[0]['mesh']} ({rows[0]['faces_in']} faces) -> {args.ratio:g}, grid {grid!r}: "
              f"{len(expand_grid(GRIDS[grid]))} configurations per mesh, {rows[0]['distinct_results']} distinct "
              f"results, {rows[0]['runs']} runs (cells that run alike run once); {rows[0]['cores']} cores, "
              f"load average {rows[0]['load_avg']} at the start, {rows[0]['load_avg_end']} at the end; "
              f"{HELPERS.size()} helper processes")
        print(f"{'method':52s} {'median s':>9s} {'per cell':>9s} {'x one warm':>11s} {'cpu s':>8s} {'cpu x one':>10s} "
              f"{'x loop':>7s}")
        for r in rows:
            print(f"{r['method']:52s} {r['median_s']:9.3f} {r['per_config_s']:9.4f} {r['vs_one_warm']:11.1f} "
                  f"{r['median_cpu_s']:8.3f} {r['cpu_vs_one_warm']:10.1f} {r['vs_loop']!s:>7s}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
