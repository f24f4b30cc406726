"""Issue 33's gap, stage by stage: where a warm run's time goes beside meshoptimizer's, in one process.

For each case ``MESH:RATIO`` (target ``max(4, round(ratio * faces))``), qemjax's methods (``--methods``,
default: the package default and ``classic``) and meshoptimizer run warm (one untimed call each first),
``--repeats`` times in alternating order. For each qemjax method the table gives the median of each
part of the run, from the result's stats:

- selection: the independent-set passes (``select_s`` less the validation inside it);
- validation: flip kernel, link and coincidence tests (``validity_s``);
- contraction (``contract_s``), topology update (``topology_s``), kernels: pricing waits (``kernels_s``);
- re-fit: the post-pass (``refit_s``; 0 for a method without it);
- the rest: input checks, welding, normalisation, the scheduler's set-up and the output (``total_s`` less
  all of the above);

each in seconds, per round (ms) and as a share, and the run's total over meshoptimizer's in the same run
beside the goal (``--goals MESH:X ...``, default issue 33's cow:20 stanford-bunny:5 armadillo-x16:2.5;
a mesh without a goal gets none). The last column says what each stage would
have to become for the run to meet the goal if only that stage shrank (a negative value: no single stage
is enough).

    python experiments/figures/gap_stages.py --cases cow:0.1 stanford-bunny:0.1 armadillo-x16:0.01 --repeats 5

``--schedule FIELD=VALUE`` (repeatable) also times each method with the parallel scheduler's
`qemjax.Schedule` of those fields (labelled ``METHOD+schedule``): the rounds and time a schedule saves, in
the same run (its quality: ``rank_peers.py --variant NAME:schedule.FIELD=VALUE``)::

    python experiments/figures/gap_stages.py --cases cow:0.1 stanford-bunny:0.1 --methods default \
        --schedule gate=2 --schedule gate_fraction=0.2 --schedule tail=5
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
import peers  # noqa: E402

GOALS = {"cow": 20.0, "stanford-bunny": 5.0, "armadillo-x16": 2.5}  # issue 33: qemjax / meshoptimizer
PARTS = ("selection", "validation", "contraction", "topology", "kernels", "re-fit", "the rest")


def parts_of(stats: dict) -> dict:
    """The run's seconds by part (module docstring), from a result's stats."""
    g = stats.get
    sel, val = g("select_s", 0.0), g("validity_s", 0.0)
    p = {"selection": sel - val, "validation": val, "contraction": g("contract_s", 0.0),
         "topology": g("topology_s", 0.0), "kernels": g("kernels_s", 0.0), "re-fit": g("refit_s", 0.0)}
    p["the rest"] = stats["total_s"] - sum(p.values())
    return p


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["cow:0.1", "stanford-bunny:0.1", "armadillo-x16:0.01"])
    ap.add_argument("--methods", nargs="+", default=["default", "classic"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--schedule", action="append", default=[], metavar="FIELD=VALUE")
    ap.add_argument("--goals", nargs="+", default=[f"{k}:{v:g}" for k, v in GOALS.items()], metavar="MESH:X",
                    help="the goal of each mesh, as qemjax's time over meshoptimizer's (default: %(default)s)")
    args = ap.parse_args(argv)
    try:
        goals = {m: float(x) for m, _, x in (g.rpartition(":") for g in args.goals)}
    except ValueError:
        ap.error(f"--goals: each is MESH:X with X a number, got {' '.join(args.goals)}")

    import qemjax

    variants = {f"qemjax-{m}": dict(method=m) for m in args.methods}
    if args.schedule:
        fields = {k: float(v) for k, _, v in (x.partition("=") for x in args.schedule)}
        sch = qemjax.Schedule(**{k: int(v) if k in ("tail", "max_passes") else v for k, v in fields.items()})
        variants.update({f"qemjax-{m}+schedule": dict(method=m, scheduler=sch) for m in args.methods})

    for case in args.cases:
        name, _, ratio = case.partition(":")
        mesh = bench_meshes.load(name)
        target = max(4, round(float(ratio or 0.1) * mesh.n_faces))
        runners = {k: (lambda kw=kw: qemjax.simplify((mesh.V, mesh.F), target_faces=target, **kw))
                   for k, kw in variants.items()}
        runners["meshoptimizer"] = lambda: peers.run_peer("meshoptimizer", mesh.V, mesh.F, target)
        for run in runners.values():  # compile / warm up, untimed
            run()
        wall = {k: [] for k in runners}
        parts = {k: [] for k in runners if k.startswith("qemjax")}
        rounds = {}
        for i in range(args.repeats):
            for k in (list(runners) if i % 2 == 0 else list(reversed(list(runners)))):
                t0 = time.perf_counter()
                out = runners[k]()
                wall[k].append(time.perf_counter() - t0)
                if k in parts:
                    parts[k].append(parts_of(out.stats))
                    rounds[k] = out.stats.get("rounds", 0)
        mo = float(np.median(wall["meshoptimizer"]))
        goal = goals.get(name)
        print(f"\n### {name} ({mesh.n_faces} faces) -> {target}, {args.repeats} warm repeats, one process; "
              f"meshoptimizer {mo * 1e3:.1f} ms" + (f", goal {goal:g}x = {goal * mo * 1e3:.1f} ms" if goal else ""))
        for k, ps in parts.items():
            med = {p: float(np.median([x[p] for x in ps])) for p in PARTS}
            total = float(np.median(wall[k]))
            r = max(rounds[k], 1)
            print(f"\n{k}: {total * 1e3:.1f} ms = {total / mo:.1f}x meshoptimizer, {rounds[k]} rounds "
                  f"({(total - med['re-fit'] - med['the rest']) / r * 1e3:.2f} ms per round in the scheduler)")
            print("| part | ms | ms per round | share | this part alone would have to be (ms) |")
            print("|---|---|---|---|---|")
            over = total - goal * mo if goal else float("nan")
            for p in PARTS:
                need = med[p] - over
                print(f"| {p} | {med[p] * 1e3:.1f} | {med[p] / r * 1e3:.2f} | {med[p] / total:.0%} | "
                      f"{need * 1e3:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
