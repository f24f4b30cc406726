"""Memoryless quadrics for the last stretch of a run, keeping the memory: quality and time of a switch
inside the parallel scheduler.

The parallel scheduler's run is wrapped (monkeypatched: nothing in the package changes): the default's
rounds run to K × the target; then the vertex rows become memoryless rows (`memoryless.state_rows`: the
summed quadrics so far as the history, the current quadrics rebuilt from the faces, weight
``memory_weight=0.3``), the pairs are priced again and the rounds go on to the target with the memoryless
model (a new round implementation, `driver.choose`). The re-fit and everything after the scheduler run as
in the default. For each benchmark mesh at 10 % and 1 %: rms and Hausdorff over the best peer's (as
`late_memoryless.py`), and warm times (the median of ``--repeats``) against the default's::

    python experiments/probes/memoryless_switch.py --switch 2 4 10
    python experiments/probes/memoryless_switch.py --switch 1.5 2 2:refit=0 2:memory_weight=1   # other settings

A switch is ``K`` or ``K:key=value,...``: ``memory_weight`` sets the memoryless model's weight (0.3 unless
given), other keys are keywords of ``simplify`` for that variant (``refit=0``).
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

from figures.rank_peers import distances  # noqa: E402
from probes.late_memoryless import best_peers, cases  # noqa: E402

SWITCH = {"k": None, "memory_weight": 0.3}  # the factor K of the target at which the run switches (None: no
# switch) and the memoryless model's weight


def patch():
    import jax.numpy as jnp

    from qemjax._costs import memoryless as ml
    from qemjax._kernels.batching import DTYPE, bucket
    from qemjax._mesh.arrays import face_normals, face_stats
    from qemjax._schedulers import parallel
    from qemjax._schedulers.device import on_device
    from qemjax._schedulers.parallel import driver
    from qemjax._schedulers.parallel.state import Run

    def run(V, S, F, extra_pairs, target_faces, model, options, progress=None, edges=None, part_scale=None,
            wedges=None, locks=None):
        k = SWITCH["k"]
        if k is None or getattr(model, "memoryless", True) or len(F) <= k * target_faces:
            return driver.run(V, S, F, extra_pairs, target_faces, model, options, progress, edges, part_scale,
                              wedges, locks)
        r = Run(V, S, F, extra_pairs, int(k * target_faces), model, options, progress, edges, part_scale,
                wedges=wedges, locks=locks)
        stop, blocked = driver.rounds(r, driver.choose(r))
        if r.faces.count > target_faces:  # (an odd K × target on a closed mesh stops one face above it)
            m2 = dataclasses.replace(model, memoryless=True, memory_weight=SWITCH["memory_weight"], refit=0)
            n = r.n
            means = face_stats(np.asarray(V, np.float64), np.asarray(F, np.int64))[1:]
            rows = ml.state_rows(m2, r.VQ[:n, :3].astype(np.float64), r.faces, np.arange(n), means,
                                 history=r.VQ[:n, 3:13])
            VQ = np.zeros((bucket(n + 1), 3 + m2.width), DTYPE)
            VQ[:n, :3], VQ[:n, 3:] = r.VQ[:n, :3], rows
            r.VQ, r.VQd, r.model = VQ, jnp.asarray(VQ), m2
            r.params = on_device(m2.kernel_params())
            r.normals = face_normals(np.asarray(V, DTYPE), F)
            r.target = target_faces
            stop, blocked = driver.rounds(r, driver.choose(r))
            r.VQ = np.ascontiguousarray(r.VQ[:, :13])  # the history where the default keeps its quadrics
        return driver.result(r, stop, blocked)

    parallel.run = run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--switch", nargs="+", default=["4"])
    ap.add_argument("--meshes", nargs="*", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--peers", default=str(EXPERIMENTS / "results" / "rank_min_angle.csv"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    import qemjax

    patch()
    best = best_peers(Path(args.peers))
    labels = ["default"] + [f"switch {k}" for k in args.switch]
    variants = [(None, 0.3, {})]
    for spec in args.switch:
        k, _, rest = spec.partition(":")
        kw = {a: float(b) if "." in b else int(b) for a, b in (x.split("=") for x in filter(None, rest.split(",")))}
        variants.append((float(k), float(kw.pop("memory_weight", 0.3)), kw))
    rows = []
    for name, m, ratio, target, ref in cases(args.meshes, best):
        row = []
        for k, mw, kw in variants:
            SWITCH["k"], SWITCH["memory_weight"] = k, mw
            kw = {"late_memoryless": 0, **kw}  # the probe's own switch on the summed default
            qemjax.simplify((m.V, m.F), target_faces=target, **kw)  # warm
            secs = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                res = qemjax.simplify((m.V, m.F), target_faces=target, **kw)
                secs.append(time.perf_counter() - t0)
            d = distances(m.V, m.F, np.asarray(res.vertices, np.float64), np.asarray(res.faces, np.int64))
            row.append((d["rms_rel"] / ref["rms_rel"], d["hausdorff_rel"] / ref["hausdorff_rel"],
                        statistics.median(secs), len(res.faces)))
        rows.append(row)
        print(f"{name:18s} {ratio:5g} " + "  ".join(
            f"{lab}: rms {a:.3f} H {b:.3f} t/default {s / row[0][2]:.2f} faces {f}"
            for lab, (a, b, s, f) in zip(labels, row)), flush=True)
    print()
    for i, lab in enumerate(labels):
        print(f"{lab}: rms <= best peer in {sum(r[i][0] <= 1 for r in rows)}/{len(rows)}; Hausdorff <= best peer in "
              f"{sum(r[i][1] <= 1 for r in rows)}/{len(rows)}; time / default median "
              f"{statistics.median(r[i][2] / r[0][2] for r in rows):.2f}")


if __name__ == "__main__":
    main()
