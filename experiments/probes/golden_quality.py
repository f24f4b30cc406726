"""Old code against new code on the golden cases whose hashes a change moved: rms, Hausdorff, slivers and time
per case.

For a deliberate golden regeneration: the table shows what the new bits cost or gain in quality. The package
at ``--rev`` is loaded beside this checkout's (`ab_compare.load_old`), both run each case in turn (warm), and
`qemjax.metrics.surface_distance` measures both outputs against the input with the same samples; the sliver
fraction (faces whose smallest angle is under 10°) is `qemjax.metrics.triangle_quality`'s.

    python experiments/probes/golden_quality.py --rev db766be --match default/     # the default's cases
    python experiments/probes/golden_quality.py --rev db766be --match default/ --out results/golden_quality_refit_cg.txt
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS.parent / "tests"), str(EXPERIMENTS)]

import golden_cases as gc  # noqa: E402
from ab_compare import load_old  # noqa: E402


def _timed(fn, repeats: int):
    best, res = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t)
    return res, best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", required=True, help="the old revision (git)")
    p.add_argument("--match", default="default/", help="cases whose id contains this")
    p.add_argument("--samples", type=int, default=200_000, help="surface samples per mesh for the distances")
    p.add_argument("--repeats", type=int, default=3, help="runs per case and version (the fastest counts)")
    p.add_argument("--out", type=Path, help="also write the table here")
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax

    old = load_old(args.rev)
    rows, lines = [], []
    head = (f"{'case':42s} {'rms old':>10s} {'rms new':>10s} {'Δ rms':>8s} {'haus old':>10s} {'haus new':>10s} "
            f"{'Δ haus':>8s} {'sliv old':>8s} {'sliv new':>8s} {'t old':>7s} {'t new':>7s}")
    lines.append(head)
    for case in gc.cases():
        if args.match not in case.id or (case.shared and not (gc.SHARED / case.mesh).exists()):
            continue
        kw = {"attributes": None, "method": "classic"} | case.kwargs
        mesh = gc.mesh_input(case)
        r_old, t_old = _timed(lambda: old.simplify(mesh, **kw), args.repeats)
        r_new, t_new = _timed(lambda: qemjax.simplify(mesh, **kw), args.repeats)
        src = (r_new.input_vertices, r_new.input_faces)
        d_old = qemjax.metrics.surface_distance(src, r_old, n_samples=args.samples)
        d_new = qemjax.metrics.surface_distance(src, r_new, n_samples=args.samples)
        drms = d_new["rms"] / d_old["rms"] - 1
        dh = d_new["hausdorff"] / d_old["hausdorff"] - 1
        s_old = qemjax.metrics.triangle_quality(r_old)["sliver_fraction"]
        s_new = qemjax.metrics.triangle_quality(r_new)["sliver_fraction"]
        rows.append((drms, dh, s_new - s_old, t_new / t_old))
        lines.append(f"{case.id:42s} {d_old['rms']:10.4g} {d_new['rms']:10.4g} {100 * drms:+7.3f}% "
                     f"{d_old['hausdorff']:10.4g} {d_new['hausdorff']:10.4g} {100 * dh:+7.3f}% "
                     f"{s_old:8.4f} {s_new:8.4f} {t_old:7.3f} {t_new:7.3f}")
        print(lines[-1], flush=True)
    if rows:
        lines.append(f"median Δ rms {100 * statistics.median(r[0] for r in rows):+.3f}%, median Δ Hausdorff "
                     f"{100 * statistics.median(r[1] for r in rows):+.3f}%, worst Δ rms "
                     f"{100 * max(r[0] for r in rows):+.3f}%, worst Δ Hausdorff {100 * max(r[1] for r in rows):+.3f}%; "
                     f"rms lower in {sum(r[0] < 0 for r in rows)}, Hausdorff lower in {sum(r[1] < 0 for r in rows)}, "
                     f"fewer slivers in {sum(r[2] < 0 for r in rows)} (more in {sum(r[2] > 0 for r in rows)}); "
                     f"median time new / old {statistics.median(r[3] for r in rows):.2f} over {len(rows)} cases")
    print("\n".join([head] + lines[1:]))
    if args.out:
        args.out.write_text(f"# python experiments/probes/golden_quality.py --rev {args.rev} --match {args.match} "
                            f"--samples {args.samples} --repeats {args.repeats}\n" + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
