"""The parallel round's two paths on the same meshes: the compiled loops (`parallel.selection`, which `fits` gives runs
on at most `selection.MAX_FACES` faces) against the numpy stages, in one process, alternating, warm medians
of wall and CPU time, and whether the outputs are the same bits (they must be: tests/test_round_loops.py).

Each path is forced for every run of this script (`selection.MAX_FACES` raised above the mesh, or `fits`
answering no), so a mesh on either side of the limit shows what the other path would cost there.

    python experiments/probes/round_paths.py --meshes cow stanford-bunny armadillo --ratio 0.1 --repeats 7
    python experiments/probes/round_paths.py --meshes armadillo-x16 --ratio 0.01 --repeats 3
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]

import meshes as bench_meshes  # noqa: E402
import round_choice  # noqa: E402
from ab_compare import digest  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny", "armadillo"])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    import qemjax
    from qemjax._schedulers.parallel.selection import fits

    print(f"# python experiments/probes/round_paths.py --meshes {' '.join(args.meshes)} --ratio {args.ratio} "
          f"--repeats {args.repeats}")
    print("| mesh | faces | path of its own | compiled s | numpy stages s | compiled CPU s | numpy CPU s | "
          "numpy / compiled | same bits |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.meshes:
        bm = bench_meshes.load(name)
        mesh = (bm.V, bm.F)
        wall = {"compiled": [], "numpy": []}
        cpu = {"compiled": [], "numpy": []}
        digests = {}
        with warnings.catch_warnings(), round_choice.recorded() as taken:
            warnings.simplefilter("ignore")
            for path in wall:  # warm: each path's compilations
                with round_choice.forced(path, len(bm.F)):
                    qemjax.simplify(mesh, ratio=args.ratio)
            taken.clear()
            for _ in range(args.repeats):
                for path in wall:
                    with round_choice.forced(path, len(bm.F)):
                        t, c = time.perf_counter(), time.process_time()
                        r = qemjax.simplify(mesh, ratio=args.ratio)
                        wall[path].append(time.perf_counter() - t)
                        cpu[path].append(time.process_time() - c)
                    digests.setdefault(path, digest(r))
        per_run = len(taken) // (2 * args.repeats)  # the default's memoryless last stretch: a second run
        assert per_run and taken == ([True] * per_run + [False] * per_run) * args.repeats, \
            "a run did not take the path it was given"
        own = "compiled" if fits(True, True, None, len(bm.F)) else "numpy stages"
        med = {p: statistics.median(v) for p, v in wall.items()}
        cmed = {p: statistics.median(v) for p, v in cpu.items()}
        print(f"| {name} | {len(bm.F)} | {own} | {med['compiled']:.3f} | {med['numpy']:.3f} | "
              f"{cmed['compiled']:.3f} | {cmed['numpy']:.3f} | {med['numpy'] / med['compiled']:.2f} | "
              f"{'yes' if digests['compiled'] == digests['numpy'] else 'NO'} |")


if __name__ == "__main__":
    main()
