"""A sweep's piece size: the same default sweep (every core, helpers warm) cut into pieces of at most N
distinct runs and F faces, for each (N, F) given, alternating in one process, with the loop of `simplify`
over the same cells for the ratio (``x loop``). Only the cut differs between the sizes (`qemjax._sweep.run`'s
``PIECE_RUNS`` and ``PIECE_FACES``, set in this process, which cuts the pieces); every size must give the
same rows, bit for bit (checked). Wall and CPU seconds (this process and the helpers), medians. A piece of
more faces than `selection.MAX_FACES` takes the numpy stages (the same rows): the figures in docs/sweeps.md
were measured with that limit raised to 262,144 in the package.

    python experiments/figures/sweep_pieces.py --grid distinct --repeats 10 --sizes 16:131072 32:262144
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS), str(EXPERIMENTS / "figures")]

import machine  # noqa: E402
import meshes as bench_meshes  # noqa: E402
from sweep_bench import GRIDS, _clock, wait_for_helpers  # noqa: E402

import qemjax  # noqa: E402
import qemjax._sweep.run as sweep_run  # noqa: E402
from qemjax._sweep.pool import HELPERS  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="cow")
    ap.add_argument("--grid", default="distinct", choices=sorted(GRIDS))
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--sizes", nargs="+", default=["16:131072", "32:262144"], help="RUNS:FACES per piece")
    args = ap.parse_args()
    sizes = {s: tuple(int(x) for x in s.split(":")) for s in args.sizes}
    path = bench_meshes.shared_files()[args.mesh]
    meshes = {args.mesh: qemjax.load(path)}
    grid = GRIDS[args.grid]

    def cut(size):
        sweep_run.PIECE_RUNS, sweep_run.PIECE_FACES = sizes[size]

    def one():
        return qemjax.sweep(meshes, grid, [args.ratio], metrics=False, progress=False)

    def loop():
        for params in sweep_run.expand_grid(grid):
            qemjax.simplify(path, ratio=args.ratio, **dict(params))

    rows, pieces = {}, {}
    for _ in range(3):  # warm: the kernels, then the helpers (started by the second default sweep)
        for size in sizes:
            cut(size)
            df = one()
            rows[size], pieces[size] = df["result_sha256"].tolist(), int(df["batch_size"].max())
        wait_for_helpers()
    if any(r != rows[args.sizes[0]] for r in rows.values()):
        raise AssertionError("the piece sizes gave different rows")
    times = {size: [] for size in [*sizes, "loop simplify"]}
    for rep in range(args.repeats):  # alternating; the order reversed every other repeat
        order = list(times) if rep % 2 == 0 else list(times)[::-1]
        for key in order:
            if key == "loop simplify":
                times[key].append(_clock(loop))
            else:
                cut(key)
                times[key].append(_clock(one))
    loop_s = statistics.median(w for w, _ in times["loop simplify"])
    print(f"# python experiments/figures/sweep_pieces.py --mesh {args.mesh} --grid {args.grid} --ratio {args.ratio} "
          f"--repeats {args.repeats} --sizes {' '.join(args.sizes)} ({machine.cpu_model()}, "
          f"{1 + HELPERS.size()} processes; the rows the same bits at every size)")
    print("| pieces of at most (runs:faces) | largest batch | wall s | CPU s | x loop |")
    print("|---|---|---|---|---|")
    for key, ts in times.items():
        w, c = statistics.median(t[0] for t in ts), statistics.median(t[1] for t in ts)
        batch = pieces.get(key, "-")
        print(f"| {key} | {batch} | {w:.3f} | {c:.3f} | {w / loop_s:.3f} |")


if __name__ == "__main__":
    main()
