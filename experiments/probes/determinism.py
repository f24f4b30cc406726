"""Does the output depend on how many cores the process may use? Runs the same `qemjax.simplify` in fresh
processes, with and without ``taskset -c 0`` (and optionally with XLA flags), and compares sha256 hashes
of the output and of the intermediate arrays, stage by stage:

  quadrics     initial vertex quadrics (`vertex_quadrics`, its reductions and scatter-adds)
  place        first-round placement of every edge by `placement.place` (arrays gathered on the host:
               the greedy scheduler's kernel)
  place_pairs  the same by `placement.place_pairs` (gathers on the device: the parallel scheduler's kernel)
  partitions   how many fusions of the compiled place_pairs XLA split for its threads
               (``outer_dimension_partitions`` in the optimised HLO)
  parallel / greedy   the simplified vertices and faces of each scheduler

    python experiments/probes/determinism.py                         # bumpy_sphere(4) -> 10 %
    python experiments/probes/determinism.py --subdivisions 6 --xla-flags --xla_cpu_use_fusion_emitters=false

Findings (2-core AMD EPYC, jax 0.10.2) are in results/determinism.md.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _h(a) -> str:
    import numpy as np

    return hashlib.sha256(np.ascontiguousarray(np.asarray(a)).tobytes()).hexdigest()[:16]


def child(subdivisions: int, ratio: float) -> dict:
    """The hashes of every stage, in this process."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import qemjax
    from qemjax._io import mesh as _io
    from qemjax._mesh import topology as topo, units as _units
    from qemjax import shapes
    from qemjax._kernels.batching import bucket, chunk_size, chunks
    from qemjax._costs.qem import initial_quadrics
    from qemjax._kernels import CPU_COMPILER_OPTIONS, placement

    mesh = shapes.bumpy_sphere(subdivisions)
    (V, F), _ = _io.prepare(mesh)
    Vn, _ = _units.normalize(V)
    E, _, be, bf = topo.edge_table(F, len(V))
    Q = initial_quadrics(Vn, F, area_weighted=True, boundary_weight=100.0, feature_edges=None,
                         boundary=(be, bf))
    out = {"cores": len(os.sched_getaffinity(0)), "quadrics": _h(Q)}
    n = len(V)
    VQ = np.zeros((bucket(n + 1), 13), np.float32)
    VQ[:n, :3], VQ[:n, 3:] = Vn, Q
    p = qemjax.QEM().kernel_params()
    args = (p["endpoints_only"], p["cond_eps"], p["max_shift"])
    P = E.astype(np.int32)
    xs = [np.asarray(placement.place_pairs(jnp.asarray(VQ), part, *args)) for _, part in chunks(P)]
    out["place_pairs"] = _h(np.concatenate(xs, 1)[:3, : len(P)])
    size = chunk_size(len(P))
    jitted = jax.jit(placement.place_pairs.__wrapped__, compiler_options=CPU_COMPILER_OPTIONS)
    hlo = jitted.lower(jnp.asarray(VQ), np.zeros((size, 2), np.int32), *args).compile().as_text()
    out["partitions"] = hlo.count("outer_dimension_partitions")
    for scheduler in ("parallel", "greedy"):
        r = qemjax.simplify(mesh, ratio=ratio, scheduler=scheduler)
        out[scheduler] = _h(r.vertices) + "/" + _h(r.faces)
    return out


def run(subdivisions, ratio, pin: bool, xla_flags: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if xla_flags:
        env["XLA_FLAGS"] = xla_flags
    cmd = [sys.executable, __file__, "--child", "--subdivisions", str(subdivisions), "--ratio", str(ratio)]
    if pin:
        cmd = ["taskset", "-c", "0", *cmd]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subdivisions", type=int, default=4)
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--xla-flags", default="", help="XLA_FLAGS for both runs")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.subdivisions, args.ratio)))
        return
    if shutil.which("taskset") is None:
        sys.exit("needs taskset (util-linux)")
    free, pinned = (run(args.subdivisions, args.ratio, pin, args.xla_flags) for pin in (False, True))
    print(f"bumpy_sphere({args.subdivisions}) -> {args.ratio}, XLA_FLAGS={args.xla_flags!r}")
    print(f"{'stage':12s} {free['cores']} cores{'':14s} {pinned['cores']} core (taskset -c 0)")
    for k in free:
        if k != "cores":
            same = "same" if free[k] == pinned[k] else "DIFFERENT"
            print(f"{k:12s} {str(free[k]):22s} {str(pinned[k]):22s} {same}")


if __name__ == "__main__":
    main()
