"""Plane-and-line quadrics (``method="line"``, `qemjax._costs.line`) against plane quadrics (the default),
re-measuring CGAL's claim that the line term "improves the speed and the quality of the result".

For each shared mesh (../shared/meshes) at 10 % and 1 %: two-way rms and Hausdorff (relative to the
diagonal, `qemjax.metrics.surface_distance`), the sliver fraction (`metrics.triangle_quality`: min angle
under 10°) and warm time, for QEM and for the line model at each ``--weights`` value
(``qemjax.LineQEM(line_weight=W)``, labelled "line-W").

A run with the default options writes ``experiments/results/line_quadrics.md`` (the table docs/papers.md
cites); any other run writes ``line_quadrics_custom.md`` beside it unless ``--out`` names a file.

    python experiments/figures/line_quadrics.py --meshes cow stanford-bunny
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import qemjax  # noqa: E402
from qemjax import metrics  # noqa: E402

SHARED = ROOT.parent / "shared" / "meshes"
OUT = ROOT / "experiments" / "results"


def measure(orig, ratio: float, method, repeats: int):
    """(result, rms_rel, hausdorff_rel, sliver fraction, warm median seconds) of one method on one mesh: one
    warm-up run, then ``repeats`` timed runs."""
    qemjax.simplify(orig, ratio=ratio, method=method)  # warm
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        res = qemjax.simplify(orig, ratio=ratio, method=method)
        ts.append(time.perf_counter() - t)
    d = metrics.surface_distance(orig, res, n_samples=50000)
    q = metrics.triangle_quality(res)
    return res, d["rms_rel"], d["hausdorff_rel"], q["sliver_fraction"], statistics.median(ts)


def out_path(parser, args, name: str) -> Path:
    """The results file of a run without ``--out``: ``name`` (the file the docs cite) when every option has
    its default, else ``name`` with ``_custom`` before the suffix, so that a quick run leaves the cited file
    alone."""
    custom = {k: v for k, v in vars(args).items() if k != "out"} != {
        k: v for k, v in vars(parser.parse_args([])).items() if k != "out"}
    return OUT / (name.replace(".", "_custom.", 1) if custom else name)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny", "fandisk", "rocker-arm",
                                                     "max-planck-10k", "bumpy-cube"])
    ap.add_argument("--weights", nargs="+", type=float, default=[0.0001, 0.001, 0.01, 0.05])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", type=Path, help="the table's file (default: results/line_quadrics.md for the default "
                                             "options, else results/line_quadrics_custom.md)")
    args = ap.parse_args(argv)
    args.out = args.out or out_path(ap, args, "line_quadrics.md")
    return args


def main(argv=None):
    args = parse_args(argv)
    out = args.out
    methods = {"qem": qemjax.QEM(), **{f"line-{w:g}": qemjax.LineQEM(line_weight=w) for w in args.weights}}
    lines = ["| mesh | ratio | method | faces | rms_rel | hausdorff_rel | slivers | time_s | rms / qem | time / qem |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    warnings.simplefilter("ignore")
    for name in args.meshes:
        path = next(iter(SHARED.glob(name + ".*")), None)
        if path is None:
            print(f"{name}: not in {SHARED}, skipped")
            continue
        orig = qemjax.load(path)
        for ratio in args.ratios:
            base = None
            for label, method in methods.items():
                res, *row = measure(orig, ratio, method, args.repeats)
                base = base or row
                lines.append(f"| {name} | {ratio} | {label} | {len(res.faces)} | {row[0]:.3g} | {row[1]:.3g} | "
                             f"{row[2]:.3f} | {row[3]:.3f} | {row[0] / base[0]:.3f} | {row[3] / base[3]:.2f} |")
                print(lines[-1], flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# `python experiments/figures/line_quadrics.py {' '.join(argv or sys.argv[1:])}`\n\n"
                   + "\n".join(lines) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
