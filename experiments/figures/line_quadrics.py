"""Plane-and-line quadrics (``method="line"``, `qemjax._costs.line`) against plane quadrics (the default),
re-measuring CGAL's claim that the line term "improves the speed and the quality of the result".

For each shared mesh (../shared/meshes) at 10 % and 1 %: two-way rms and Hausdorff (relative to the
diagonal, `qemjax.metrics.surface_distance`), the sliver fraction (`metrics.triangle_quality`: min angle
under 10°) and warm time, for QEM and for the line model at each ``--weights`` value
(``qemjax.LineQEM(line_weight=W)``, labelled "line-W").

    python experiments/figures/line_quadrics.py --meshes cow stanford-bunny fandisk rocker-arm max-planck-10k
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny", "fandisk", "rocker-arm",
                                                     "max-planck-10k", "bumpy-cube"])
    ap.add_argument("--weights", nargs="+", type=float, default=[0.01, 0.05, 0.2])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
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
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "line_quadrics.md").write_text(f"# `python experiments/figures/line_quadrics.py {' '.join(argv or sys.argv[1:])}`\n\n"
                                           + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
