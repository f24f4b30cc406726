"""The nearest-face search's grid (`qemjax._mesh.grid_nearest.grid`) on a generated torus: seconds and peak
memory of its build, the sizes of its arrays, and the time of many one-point queries on it (what the polish
and the sliver moves ask of the input's grid), for this checkout or the package at a git revision, each in
a fresh process (the peak is the process's).

    python experiments/probes/grid_memory.py --faces 5445000
    python experiments/probes/grid_memory.py --faces 5445000 --rev REV     # the same, the code at REV
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

CHILD = r"""
import json, resource, sys, time
import numpy as np
from qemjax import shapes
from qemjax._mesh import grid_nearest as gn
n = int(sys.argv[1])
m = shapes.torus(n_major=n, n_minor=max(3, n // 4))
V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
gn.nearest(V[:100], F[:10] % 100, V[:5])  # compiled code loaded before the peak is read
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
index = gn.grid(V, F)
t1 = time.perf_counter()
r1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
rng = np.random.default_rng(0)
P = V[rng.integers(0, len(V), 500)] + rng.normal(0, 1e-3, (500, 3))
t2 = time.perf_counter()
for i in range(len(P)):
    gn.search(V, F, index, P[i:i + 1], np.zeros(0, np.int32))
t3 = time.perf_counter()
arrays = {k: (str(a.dtype), a.nbytes / 2**20) for k, a in zip(["start", "faces"], index[5:7])}
print(json.dumps(dict(package=gn.__file__, faces=len(F), build_s=t1 - t0, build_peak_gib=(r1 - r0) / 2**20, arrays_mib=arrays,
                      cubes_per_face=float(np.prod(index[4]) / len(F)), one_point_query_ms=1e3 * (t3 - t2) / len(P))))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--faces", type=int, default=5_445_000, help="about this many faces (a torus)")
    ap.add_argument("--rev", default=None, help="the package at this git revision (default: this checkout)")
    args = ap.parse_args()
    n = max(8, int(round((args.faces / 2) ** 0.5 * 2)))  # n_major = n, n_minor = n / 4: n²/2 faces
    env = dict(os.environ)
    if args.rev:
        import ab_compare

        env["PYTHONPATH"] = str(ab_compare.package_at(args.rev))
    else:
        env["PYTHONPATH"] = str(EXPERIMENTS.parent)
    # from a folder of its own: `python -c` puts the working folder first on the path, where a checkout's
    # qemjax would be imported instead of the revision's
    with tempfile.TemporaryDirectory() as cwd:
        out = subprocess.run([sys.executable, "-c", CHILD, str(n)], env=env, capture_output=True, text=True,
                             check=True, cwd=cwd)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"code: {args.rev or 'this checkout'}")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
