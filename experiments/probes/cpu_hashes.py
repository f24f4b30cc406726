"""The output's hash under imitated CPUs: each OpenBLAS kernel, numpy without its AVX-512 functions, and XLA
limited to AVX2, each in a fresh process (`tests/test_cpu_independence.py` checks the same for golden cases).

    python experiments/probes/cpu_hashes.py                          # the default on the cow at 10 %, this checkout
    python experiments/probes/cpu_hashes.py --rev db766be            # the same with the package at a git revision
    python experiments/probes/cpu_hashes.py --mesh stanford-bunny --ratio 0.01 --method classic
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent / "tests")]

CODE = r"""
import hashlib, sys, warnings
sys.path[:0] = [sys.argv[1], sys.argv[2]]
warnings.simplefilter("ignore")
rev, mesh, ratio, method = sys.argv[3:7]
if rev:
    from ab_compare import load_old
    q = load_old(rev)
else:
    import qemjax as q
import numpy as np
r = q.simplify(q.load(mesh), ratio=float(ratio), method=method)
print(hashlib.sha256(np.ascontiguousarray(r.vertices).tobytes() + np.ascontiguousarray(r.faces).tobytes()).hexdigest()[:16])
"""


def main(argv=None) -> int:
    from test_cpu_independence import _avx512_features

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rev", default="", help="a git revision of the package (default: this checkout)")
    p.add_argument("--mesh", default="cow")
    p.add_argument("--ratio", type=float, default=0.1)
    p.add_argument("--method", default="default")
    args = p.parse_args(argv)
    path = next(q for q in (EXPERIMENTS.parent.parent / "shared" / "meshes" / f"{args.mesh}.{e}" for e in ("obj", "off"))
                if q.exists())
    variants = {f"OPENBLAS_CORETYPE={k}": {"OPENBLAS_CORETYPE": k}
                for k in ("Haswell", "Zen", "Sandybridge", "Prescott")}
    avx512 = _avx512_features()
    if avx512:
        variants["OPENBLAS_CORETYPE=SkylakeX"] = {"OPENBLAS_CORETYPE": "SkylakeX"}
        variants["numpy without AVX-512"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(avx512)}
    variants["XLA_FLAGS=--xla_cpu_max_isa=AVX2"] = {"XLA_FLAGS": "--xla_cpu_max_isa=AVX2"}
    seen = set()
    for name, env in variants.items():
        done = subprocess.run([sys.executable, "-c", CODE, str(EXPERIMENTS.parent), str(EXPERIMENTS), args.rev, str(path),
                               str(args.ratio), args.method], env=dict(os.environ, **env), capture_output=True,
                              text=True)
        h = done.stdout.strip().splitlines()[-1] if done.returncode == 0 else "failed: " + done.stderr[-200:]
        seen.add(h)
        print(f"{name:36s} {h}", flush=True)
    print(f"{len(seen)} distinct hash(es): {args.method} on {args.mesh} -> {args.ratio:g}"
          f"{' at ' + args.rev if args.rev else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
