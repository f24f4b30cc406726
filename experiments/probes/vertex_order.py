"""Does the order of a mesh's vertices and faces change the scheduler's speed? (Its loops read each pair's
faces and neighbours from memory one pair after another: on a large mesh those reads miss the caches.)

For each case ``MESH:RATIO`` the same mesh runs in three orders, warm, alternating in one process:

- ``as given``: the file's (or the generator's) order;
- ``spatial``: vertices sorted along a Morton (Z-order) curve of their positions, faces by their vertices'
  new numbers: neighbours in space are near in memory;
- ``shuffled``: vertices and faces in a random order (seed 0): the worst case.

Prints the medians of the whole call and of the stats' stage times (selection, contraction, topology,
kernels, re-fit), the rounds, and the measured rms (``distance_rms``): a different order changes which of
equal-cost pairs go first, so the outputs differ; their quality should not.

    python experiments/probes/vertex_order.py --cases stanford-bunny:0.1 armadillo-x16:0.01 --repeats 5
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path.insert(0, str(EXPERIMENTS))
import meshes as bench_meshes  # noqa: E402

STAGES = ("select_s", "contract_s", "topology_s", "kernels_s", "refit_s")


def morton_order(V: np.ndarray) -> np.ndarray:
    """The vertices' order along a Z-order curve of their positions quantised to 2^21 steps per axis."""
    lo, hi = V.min(0), V.max(0)
    q = ((V - lo) / np.maximum(hi - lo, 1e-300) * ((1 << 21) - 1)).astype(np.uint64)

    def spread(x):
        x = x & np.uint64(0x1FFFFF)
        for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                            (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
            x = (x | (x << np.uint64(shift))) & np.uint64(mask)
        return x
    code = spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")


def reordered(V: np.ndarray, F: np.ndarray, order: np.ndarray, face_order: str, rng=None):
    """(V, F) with vertex i of the result = vertex order[i] of the input; faces sorted by their smallest new
    vertex number (``face_order="sorted"``) or shuffled (``"shuffled"``)."""
    new = np.empty(len(order), np.int64)
    new[order] = np.arange(len(order))
    G = new[F]
    if face_order == "sorted":
        G = G[np.lexsort((G.max(1), G.min(1)))]
    else:
        G = G[rng.permutation(len(G))]
    return np.ascontiguousarray(V[order]), np.ascontiguousarray(G)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["stanford-bunny:0.1"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--method", default="default")
    args = ap.parse_args()
    import qemjax

    warnings.simplefilter("ignore")
    for case in args.cases:
        name, ratio = case.split(":")
        mesh = bench_meshes.load(name)
        V, F = np.asarray(mesh.V, np.float64), np.asarray(mesh.F, np.int64)
        target = max(4, round(float(ratio) * len(F)))
        rng = np.random.default_rng(0)
        orders = {"as given": (V, F), "spatial": reordered(V, F, morton_order(V), "sorted"),
                  "shuffled": reordered(V, F, rng.permutation(len(V)), "shuffled", rng)}
        runs = {k: [] for k in orders}
        for k, m in orders.items():  # warm: compile once per shape
            qemjax.simplify(m, target_faces=target, method=args.method)
        for r in range(args.repeats):
            for k in (list(orders) if r % 2 == 0 else list(orders)[::-1]):
                t = time.perf_counter()
                res = qemjax.simplify(orders[k], target_faces=target, method=args.method)
                runs[k].append((time.perf_counter() - t, res.stats))
        print(f"\n### {name} ({len(F)} faces) -> {target}, {args.method}, medians of {args.repeats} warm runs, "
              "alternating in one process\n")
        print("| order | whole ms | " + " | ".join(s[:-2] + " ms" for s in STAGES) + " | rounds | rms (mesh units) |")
        print("|---|---|" + "---|" * len(STAGES) + "---|---|")
        base = statistics.median(t for t, _ in runs["as given"])
        for k, rs in runs.items():
            whole = statistics.median(t for t, _ in rs)
            parts = [statistics.median(float(s.get(st) or 0.0) for _, s in rs) * 1e3 for st in STAGES]
            st = rs[0][1]
            print(f"| {k} | {whole * 1e3:.1f} ({whole / base:.2f}x) | " + " | ".join(f"{p:.1f}" for p in parts)
                  + f" | {st.get('rounds')} | {st.get('distance_rms'):.4g} |")


if __name__ == "__main__":
    main()
