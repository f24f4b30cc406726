"""Where a warm `simplify`'s time goes, function by function: one untimed call (compiles), then one under
cProfile; prints the run's stats (total and re-fit seconds, polish and sliver moves) and the functions with
the most time of their own (``--sort cumulative``: qemjax's functions with the most time under them).

    python experiments/probes/profile_run.py --mesh armadillo-x16 --ratio 0.01 [--top 25] [--option KEY=VALUE ...]
    python experiments/probes/profile_run.py --mesh cow fertility homer teapot --ratio 0.1 0.01   # summed over the cases
    python experiments/probes/profile_run.py --mesh armadillo-x16 --ratio 0.01 --partition   # partitioned, in this process
    python experiments/probes/profile_run.py --mesh armadillo-x16 --ratio 0.01 --partition --sort cumulative   # by stage

With several meshes and ratios, every case runs once untimed, then all of them under one profile.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: the shared modules

import meshes as bench_meshes  # noqa: E402


def _value(text: str):
    try:
        return float(text)
    except ValueError:
        return {"true": True, "false": False}.get(text.lower(), text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", nargs="+", default=["armadillo-x16"])
    ap.add_argument("--ratio", nargs="+", type=float, default=[0.01])
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--sort", default="tottime", choices=["tottime", "cumulative"],
                    help="the functions by their own time, or by the time under them (the stages' shares)")
    ap.add_argument("--option", nargs="*", default=[], help="KEY=VALUE settings of simplify")
    ap.add_argument("--partition", action="store_true",
                    help="a partitioned run with its tasks in this process (Partition(workers=1))")
    args = ap.parse_args()
    import warnings

    import qemjax

    warnings.simplefilter("ignore")
    options = {k: _value(v) for k, v in (o.split("=", 1) for o in args.option)}
    if args.partition:
        options["partition"] = qemjax.Partition(workers=1)
    cases = []
    for name in args.mesh:
        m = bench_meshes.load(name)
        cases += [(name, r, (m.V, m.F), max(1, int(round(r * m.n_faces)))) for r in args.ratio]
    for _, _, mesh, target in cases:
        qemjax.simplify(mesh, target_faces=target, measure=False, **options)
    results = []
    profile = cProfile.Profile()
    profile.enable()
    for _, _, mesh, target in cases:
        results.append(qemjax.simplify(mesh, target_faces=target, measure=False, **options))
    profile.disable()
    for (name, r, _, _), res in zip(cases, results):
        s = res.stats
        print(f"{name} @ {r:g}: {s['faces_in']} -> {s['faces_out']} faces, {s['total_s']:.3f} s, re-fit "
              f"{s.get('refit_s') or 0.0:.3f} s, polish moves {s.get('polish_moves')}, sliver moves "
              f"{s.get('sliver_moves')}, rounds {s.get('rounds')}"
              + (f", seconds per level {[round(x, 2) for x in s['partition']['seconds_per_level']]}"
                 if "partition" in s else ""))
    stats = pstats.Stats(profile).sort_stats(args.sort)
    if args.sort == "cumulative":
        stats.print_stats("qemjax", args.top)  # (a stage's share: its callers' lines are the stages)
    else:
        stats.print_stats(args.top)


if __name__ == "__main__":
    main()
