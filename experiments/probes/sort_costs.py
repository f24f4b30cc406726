"""The sorts that left the hot paths, each against what it replaced, on one mesh (the same answers checked
before any time is printed): the edge table's keys (`edge_lists.sorted_keys`, a counting sort by the smaller
vertex, against numpy's sort of all the keys, the keys' making left out of its time) on the whole mesh and on a part of ``--part`` faces; the moves'
samples by output face (`counting.counting_order`, against a stable argsort and a search of its runs); the measured
distance's stable order (`quantiles.stable_order`, a radix sort, against ``np.argsort(kind="stable")``); the
repeated hashes of a round's faces (`face_passes.repeated`, against a sort); and the input's search grid with
`FEW_QUERIES_CUBES_PER_FACE` against `CUBES_PER_FACE` cubes per face (its build, and the output's samples
queried on it). Best of ``--repeats`` each.

    python experiments/probes/sort_costs.py --mesh armadillo-x16
    python experiments/probes/sort_costs.py --mesh armadillo-x64 --repeats 3

numpy's sort of 64-bit integers is vectorised on some CPUs and not others (the probe prints the CPU).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(EXPERIMENTS))

import machine  # noqa: E402
import meshes  # noqa: E402


def best(fn, repeats: int) -> tuple[float, object]:
    out, times = None, []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def same(a, b) -> bool:
    if isinstance(a, tuple):
        return all(same(x, y) for x, y in zip(a, b))
    return np.array_equal(np.asarray(a), np.asarray(b))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", default="armadillo-x16")
    ap.add_argument("--part", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    from qemjax._mesh import edge_lists, grid_nearest as gn
    from qemjax._mesh.face_passes import repeated
    from qemjax._mesh.quantiles import stable_order
    from qemjax._mesh.counting import counting_order
    from qemjax._pipeline.refit import _in_frame, samples

    m = meshes.load(args.mesh)
    V, F = np.asarray(m.V, np.float64), np.ascontiguousarray(m.F, np.int64)
    _, _, Vn = _in_frame(V)
    rows = []

    def compare(what, old, new):
        t_old, a = best(old, args.repeats)
        t_new, b = best(new, args.repeats)
        if not same(a, b):
            raise AssertionError(f"{what}: the two differ")
        rows.append((what, t_old, t_new))

    part = np.ascontiguousarray(F[: args.part])
    used, inverse = np.unique(part, return_inverse=True)
    part = inverse.reshape(part.shape).astype(np.int64)  # a part numbered on its own, as a task's mesh is
    for name, G, n in ((f"edge table keys, {len(F):,} faces", F, len(V)),
                       (f"edge table keys, a part of {len(part):,} faces", part, len(used))):
        bits = int(3 * len(G)).bit_length()
        if n * n >= 1 << (63 - bits):  # too many vertices to pack the index: `topology.edge_table` sorts otherwise
            continue
        edge_lists.sorted_keys(G[:4], n, bits)  # compiled before the clock

        he = np.stack([G, np.roll(G, -1, axis=1)], 2).reshape(-1, 2)
        lo, hi = he.min(1), he.max(1)
        keys = ((lo * n + hi) << bits) | np.arange(len(he), dtype=np.int64)  # made untimed: the sort alone

        def by_sort(keys=keys):  # what `edge_table` did: its keys (compiled) sorted in place
            out = keys.copy()
            out.sort()
            return out
        compare(name, by_sort, lambda G=G, n=n, bits=bits: edge_lists.sorted_keys(G, n, bits))

    P, w, _ = samples(Vn, F, np.zeros(len(V), np.int32))
    # each sample's face on an output of about 1 %: the cell of a grid of about as many occupied cells, in
    # the samples' own order (spatially coherent, not sorted: as a nearest-face search labels them)
    cell = np.floor((P - P.min(0)) * np.sqrt(len(F) / 100 / 6)).astype(np.int64)
    _, keys = np.unique(cell[:, 0] * 1_000_003 ** 2 + cell[:, 1] * 1_000_003 + cell[:, 2], return_inverse=True)
    keys = keys.reshape(-1).astype(np.int64)
    k = int(keys.max()) + 1
    counting_order(keys[:4], k)
    compare(f"samples by face, {len(P):,} samples, {k:,} faces",
            lambda: (np.argsort(keys, kind="stable"),
                     np.searchsorted(keys[np.argsort(keys, kind="stable")], np.arange(k + 1))),
            lambda: counting_order(keys, k))

    d = np.linalg.norm(P - Vn[F[np.arange(len(P)) % len(F), 0]], axis=1)  # distances of the samples' scale
    stable_order(d[:4])
    compare(f"stable order of {len(d):,} distances", lambda: np.argsort(d, kind="stable"), lambda: stable_order(d))

    h = np.random.default_rng(1).integers(0, 2**63, 60_000, dtype=np.uint64)
    h[::1000] = h[1::1000]
    repeated(h[:4])

    def by_sort_h():
        hs = np.sort(h)
        return np.flatnonzero(np.isin(h, hs[1:][hs[1:] == hs[:-1]]))
    compare(f"repeated hashes of {len(h):,} faces (a round's)", by_sort_h, lambda: repeated(h))

    Vc, Fc = np.ascontiguousarray(Vn), F
    out_f = np.random.default_rng(2).integers(0, len(F), max(1000, len(F) // 100 * 8))  # ~ the output's samples
    Q = Vc[Fc[out_f]].mean(1)
    seed = out_f.astype(np.int32)
    grid_rows = []
    for cubes in (gn.CUBES_PER_FACE, gn.FEW_QUERIES_CUBES_PER_FACE):
        t_build, index = best(lambda cubes=cubes: gn.grid(Vc, Fc, cubes), max(1, args.repeats // 2))
        t_query, found = best(lambda index=index: gn.search(Vc, Fc, index, Q, seed), args.repeats)
        grid_rows.append((cubes, t_build, t_query, int(np.prod(index[4])), found))
        del index
    if not same(grid_rows[0][4], grid_rows[1][4]):
        raise AssertionError("the two grids' answers differ")

    print(f"{args.mesh}: {len(F):,} faces; {machine.cpu_model()}, "
          f"numpy {np.__version__}; best of {args.repeats}")
    print("| what | replaced (s) | now (s) | × faster |\n|---|---|---|---|")
    for what, a, b in rows:
        print(f"| {what} | {a:.4f} | {b:.4f} | {a / b:.1f} |")
    print(f"\n| input grid, {len(F):,} faces | cubes | build (s) | {len(Q):,} seeded queries (s) |\n|---|---|---|---|")
    for cubes, tb, tq, cells, _ in grid_rows:
        print(f"| {cubes} per face | {cells:,} | {tb:.3f} | {tq:.3f} |")


if __name__ == "__main__":
    main()
