"""What keeping a textured mesh's UVs costs in time: spot at 10 % with ``attributes="uv"`` against
``attributes=None``, warm medians in one process, optionally beside the package at a git revision (loaded
as ``qemjax_old``, `ab_compare.load_old`).

    python experiments/figures/texture_cost.py --rev db766be --repeats 7
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
SPOT = EXPERIMENTS.parent.parent / "shared" / "meshes" / "spot" / "spot.obj"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", help="also time the package at this git revision")
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--repeats", type=int, default=7)
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax

    packages = {"this checkout": qemjax}
    if args.rev:
        from ab_compare import load_old

        packages[args.rev] = load_old(args.rev)
    times = {(name, a): [] for name in packages for a in ("uv", None)}
    for pkg in packages.values():  # warm
        for a in ("uv", None):
            pkg.simplify(str(SPOT), ratio=args.ratio, attributes=a)
    for _ in range(args.repeats):  # interleaved, so the machine's state is shared
        for name, pkg in packages.items():
            for a in ("uv", None):
                t = time.perf_counter()
                pkg.simplify(str(SPOT), ratio=args.ratio, attributes=a)
                times[name, a].append(time.perf_counter() - t)
    print(f"spot -> {args.ratio:g}, {args.repeats} repeats, warm medians")
    for name in packages:
        uv, none = statistics.median(times[name, "uv"]), statistics.median(times[name, None])
        print(f"{name:14s} attributes='uv' {uv:.3f} s, attributes=None {none:.3f} s, ratio {uv / none:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
