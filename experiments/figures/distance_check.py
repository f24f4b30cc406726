"""The measured distance a result carries (``res.stats["distance_max"]``, ``["distance_rms"]``) against a dense
reference, the quadric figure the summary used to call a squared distance, and what measuring costs.

Per case: the largest contraction cost (``res.max_error``, a quadric error), the measured distance from the
input's vertices and face centroids (`qemjax._pipeline.measure`), and the reference: the one-sided distance
from 200,000 random area-weighted samples of the input (plus its vertices) to the output
(`qemjax.metrics`, exact nearest points). Then the time of a warm run with ``measure=True`` and with
``measure=False``, for the default method and for ``method="classic"`` (medians of ``--repeats`` runs of
each, interleaved in alternating order).

    python experiments/figures/distance_check.py                       # the meshes of the table below, where present
    python experiments/figures/distance_check.py --meshes cow fandisk --ratios 0.1 0.02 --out results/distance_check.txt
"""
from __future__ import annotations

import argparse
import statistics
import sys
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]
from machine import median_time  # noqa: E402

SHARED = EXPERIMENTS.parent.parent / "shared" / "meshes"
CASES = [("stanford-bunny", 0.01), ("fandisk", 0.02), ("cow", 0.1), ("armadillo", 0.01), ("homer", 0.01)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", help="names under ../shared/meshes (with --ratios)")
    p.add_argument("--ratios", nargs="+", type=float)
    p.add_argument("--samples", type=int, default=200_000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    import qemjax
    from qemjax.metrics._common import as_mesh
    from qemjax.metrics._distance import two_way

    cases = list(zip(args.meshes, args.ratios)) if args.meshes else CASES
    lines = [f"{'case':24s} {'max cost':>10s} {'√max cost':>10s} {'dist max':>10s} {'ref max':>10s} "
             f"{'dist rms':>10s} {'ref rms':>10s} {'cost/ref²':>9s} | {'default s':>9s} {'+measure':>8s} "
             f"{'classic s':>9s} {'+measure':>8s}"]
    for name, ratio in cases:
        path = next((q for q in (SHARED / f"{name}.obj", SHARED / f"{name}.off") if q.exists()), None)
        if path is None:
            print(f"skip {name}: not in {SHARED}")
            continue
        mesh = qemjax.load(path)
        res = qemjax.simplify(mesh, ratio=ratio)
        o, s = as_mesh((res.input_vertices, res.input_faces)), as_mesh(res)
        fwd, _, _, _ = two_way(o, s, args.samples, 0)
        ref_max, ref_rms = float(fwd.max()), float(np.sqrt(np.mean(fwd * fwd)))
        st = res.stats
        t = {}
        for method in ("default", "classic"):
            runs = {m: [] for m in (False, True)}
            for measure in (False, True):
                qemjax.simplify(mesh, ratio=ratio, method=method, measure=measure)  # warm
            for i in range(args.repeats):  # interleaved, in alternating order: the machine's state is shared
                for measure in ((False, True) if i % 2 == 0 else (True, False)):
                    runs[measure].append(median_time(
                        lambda: qemjax.simplify(mesh, ratio=ratio, method=method, measure=measure), 1, warm=False))
            for measure in (False, True):
                t[method, measure] = statistics.median(runs[measure])
        lines.append(
            f"{name + ' ' + format(ratio, 'g'):24s} {res.max_error:10.4g} {np.sqrt(res.max_error):10.4g} "
            f"{st['distance_max']:10.4g} {ref_max:10.4g} {st['distance_rms']:10.4g} {ref_rms:10.4g} "
            f"{res.max_error / ref_max ** 2:9.3g} | {t['default', False]:9.3f} "
            f"{100 * (t['default', True] / t['default', False] - 1):+7.1f}% {t['classic', False]:9.3f} "
            f"{100 * (t['classic', True] / t['classic', False] - 1):+7.1f}%")
        print(lines[-1], flush=True)
    text = "\n".join(lines)
    print(text)
    if args.out:
        command = " ".join(sys.argv[1:] if argv is None else argv)
        args.out.write_text(f"# python experiments/figures/distance_check.py {command}\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
