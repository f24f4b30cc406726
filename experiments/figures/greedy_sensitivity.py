"""How much does the greedy reference itself move under a perturbation far below any modelling error?

For each mesh x ratio: run ``scheduler="greedy"`` on the mesh and on copies whose vertices are moved by
independent uniform noise of ``--jitter`` × the bounding-box diagonal (1e-6 by default: below float32
resolution of the normalised coordinates' last digits), and report the spread of the RMS distance
(``qemjax.metrics.evaluate`` against the *unperturbed* input). The spread is the noise floor of any
"within x % of greedy" comparison: two runs of the same algorithm differ by this much for no reason.

    python experiments/figures/greedy_sensitivity.py --meshes cow spot --ratios 0.1 0.01 --seeds 4
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))

from figures import bench_peers  # noqa: E402
import meshes as bench_meshes  # noqa: E402


def rms_after(V, F, Vin, target, scheduler):
    out = bench_peers.run_qemjax(scheduler, Vin, F, target, repeats=1)
    return bench_peers.evaluate(V, F, out["V2"], out["F2"], target)["rms_rel"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["bumpy-cube", "face", "rocker-arm", "spot", "beetle", "suzanne",
                                                    "rocker-arm-small", "cow", "fertility"],
                   help="default: the meshes of results/greedy_sensitivity.md")
    p.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.01])
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--jitter", type=float, default=1e-6)
    p.add_argument("--scheduler", default="greedy")
    args = p.parse_args(argv)
    print("| mesh | ratio | target | rms unperturbed | rms perturbed (min .. max) | spread % |")
    print("|---|---|---|---|---|---|")
    for name in args.meshes:
        mesh = bench_meshes.load(name)
        diag = float(np.linalg.norm(mesh.V.max(0) - mesh.V.min(0)))
        for ratio in args.ratios:
            target = max(4, round(ratio * mesh.n_faces))
            base = rms_after(mesh.V, mesh.F, mesh.V, target, args.scheduler)
            runs = []
            for seed in range(args.seeds):
                noise = np.random.default_rng(seed).uniform(-1, 1, mesh.V.shape) * args.jitter * diag
                runs.append(rms_after(mesh.V, mesh.F, mesh.V + noise, target, args.scheduler))
            lo, hi = min(runs + [base]), max(runs + [base])
            print(f"| {name} | {ratio:g} | {target} | {base:.4e} | {min(runs):.4e} .. {max(runs):.4e} | "
                  f"{100 * (hi / lo - 1):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
