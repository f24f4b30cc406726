"""Probabilistic plane quadrics (``method="probabilistic"``, `qemjax._costs.probabilistic`) against plane
quadrics (the default), re-measuring Trettner & Kobbelt's (2020) claims: the uncertainty makes every solve
well posed (no rank fall-back), robustly, at a quality close to plane quadrics.

For each shared mesh (../shared/meshes) at 10 % and 1 %: two-way rms and Hausdorff (relative to the
diagonal, `qemjax.metrics.surface_distance`), the sliver fraction (`metrics.triangle_quality`: min angle
under 10°), the share of contractions that left the 3×3 solve (``stats["branches"]``: segment, endpoint or
truncated) and warm time, for QEM and for the probabilistic model at each ``--sigmas`` pair σn:σp
(``qemjax.ProbabilisticQEM(sigma_normal=σn, sigma_position=σp)``, labelled "prob-σn-σp"; σp is a fraction
of the mesh's rms edge length).

A run with the default options writes ``experiments/results/probabilistic_quadrics.md`` (the table
docs/papers.md cites); any other run writes ``probabilistic_quadrics_custom.md`` beside it unless ``--out``
names a file.

    python experiments/figures/probabilistic_quadrics.py --meshes cow stanford-bunny
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "experiments")]
import qemjax  # noqa: E402
from figures.line_quadrics import measure, out_path  # noqa: E402

SHARED = ROOT.parent / "shared" / "meshes"


def prob_method(sn: float, sp: float) -> tuple[str, qemjax.ProbabilisticQEM]:
    return f"prob-{sn:g}-{sp:g}", qemjax.ProbabilisticQEM(sigma_normal=sn, sigma_position=sp)


def summary(rows: list[tuple], methods: list[str]) -> list[str]:
    """Per method: median and range of rms, Hausdorff and time over QEM's, mean slivers and fall-backs."""
    out = ["| method | rms / qem: median (range) | Hausdorff / qem: median (range) | time / qem: median (range) "
           "| slivers (mean) | fall-back share (mean) |", "|---|---|---|---|---|---|"]
    for m in methods:
        r = [x for x in rows if x[0] == m]
        cols = [np.array([x[k] for x in r]) for k in range(1, 6)]

        def med(a):
            return f"{np.median(a):.3f}× ({a.min():.2f}–{a.max():.2f}×)"
        out.append(f"| {m} | {med(cols[0])} | {med(cols[1])} | {med(cols[2])} | {cols[3].mean():.3f} | "
                   f"{cols[4].mean():.3f} |")
    return out


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["cow", "stanford-bunny", "fandisk", "rocker-arm",
                                                     "max-planck-10k", "bumpy-cube"])
    ap.add_argument("--sigmas", nargs="+", default=["0.01:0", "0.03:0", "0.1:0", "0.3:0", "0.03:1", "0.1:1"],
                    help="σn:σp pairs (σp: fraction of the rms edge length)")
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, help="the table's file (default: results/probabilistic_quadrics.md for the "
                                             "default options, else results/probabilistic_quadrics_custom.md)")
    args = ap.parse_args(argv)
    args.out = args.out or out_path(ap, args, "probabilistic_quadrics.md")
    return args


def main(argv=None):
    args = parse_args(argv)
    out = args.out
    methods = {"qem": qemjax.QEM(), **dict(prob_method(*map(float, s.split(":"))) for s in args.sigmas)}
    lines = ["| mesh | ratio | method | faces | rms_rel | hausdorff_rel | slivers | fall-back | time_s | rms / qem "
             "| hd / qem | time / qem |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = []
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
                res, rms, hd, slivers, t = measure(orig, ratio, method, args.repeats)
                br = res.stats["branches"]
                fall = (sum(br.values()) - br["solve"]) / max(sum(br.values()), 1)
                row = (rms, hd, slivers, t, fall)
                base = base or row
                rows.append((label, row[0] / base[0], row[1] / base[1], row[3] / base[3], row[2], row[4]))
                lines.append(f"| {name} | {ratio} | {label} | {len(res.faces)} | {row[0]:.3g} | {row[1]:.3g} | "
                             f"{row[2]:.3f} | {row[4]:.3f} | {row[3]:.3f} | {row[0] / base[0]:.3f} | "
                             f"{row[1] / base[1]:.3f} | {row[3] / base[3]:.2f} |")
                print(lines[-1], flush=True)
    text = "\n".join(summary(rows, methods)) + "\n\n" + "\n".join(lines) + "\n"
    print(text)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        f"# `python experiments/figures/probabilistic_quadrics.py {' '.join(argv or sys.argv[1:])}`\n\n"
        "Shared 2-core machine (other jobs running): times are same-run ratios (median of --repeats runs per cell), rough.\n\n" + text)
    print("wrote", out)


if __name__ == "__main__":
    main()
