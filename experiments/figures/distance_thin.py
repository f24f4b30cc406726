"""`qemjax.metrics.evaluate` on a mesh of long thin triangles against a torus of the same size: the two-way
distance's nearest-triangle queries (`qemjax._mesh.nearest`) should cost about the same on both.

The capsule is a cylinder of one band of long quads between two hemispherical caps, midpoint-subdivided
four times (131,072 faces; the band's triangles stay about 40 times longer than wide); the torus has
256 × 256 quads (131,072 faces). Each is simplified to 10 % with the default method, then evaluated
(warm: the first evaluation is not timed; medians of ``--repeats``). ``--tube`` adds an open tube of
1,024 × 64 quads (aspect ratio ~50, whose simplified faces span the whole tube: a harder case), timed
once. With
``--rev REV`` the package at that git revision evaluates the same pairs in the same process, alternating
with this checkout's, and the script checks that both give the same values.

    python experiments/figures/distance_thin.py
    python experiments/figures/distance_thin.py --rev 6bc3faf --repeats 3 --tube
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

EXPERIMENTS = Path(__file__).resolve().parents[1]  # the shared modules and results/
sys.path[:0] = [str(EXPERIMENTS.parent), str(EXPERIMENTS)]  # this checkout's qemjax

import qemjax  # noqa: E402
from machine import cpu_model, median_time  # noqa: E402


def subdivide(V, F):
    """Midpoint subdivision: each triangle into four similar ones (aspect ratios kept)."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    uk, inv = np.unique(E, axis=0, return_inverse=True)
    inv = inv.reshape(3, -1).T + len(V)
    V = np.concatenate([V, 0.5 * (V[uk[:, 0]] + V[uk[:, 1]])])
    a, b, c = F.T
    ab, bc, ca = inv.T
    return V, np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])


def capsule(n_around=32, n_cap=4, length=4.0, radius=0.5, levels=4):
    """(V, F): a capsule whose cylinder is one band of long quads (two triangles each) between two
    hemispherical caps of n_cap rings, then midpoint-subdivided ``levels`` times."""
    t = np.arange(n_around) * 2 * np.pi / n_around
    phi = np.pi / 2 * np.arange(n_cap - 1, -1, -1) / n_cap  # from near the pole to the equator
    rings = [(radius * np.cos(p), -radius * np.sin(p)) for p in phi]
    rings += [(r, length - z) for r, z in rings[::-1]]
    n = n_around
    V = [[0.0, 0.0, -radius]] + [[r * np.cos(x), r * np.sin(x), z] for r, z in rings for x in t]
    V.append([0.0, 0.0, length + radius])
    F = [[0, 1 + (j + 1) % n, 1 + j] for j in range(n)]
    for i in range(len(rings) - 1):
        s0, s1 = 1 + i * n, 1 + (i + 1) * n
        for j in range(n):
            a, b, c, d = s0 + j, s0 + (j + 1) % n, s1 + j, s1 + (j + 1) % n
            F += [[a, b, d], [a, d, c]]
    top, s = len(V) - 1, 1 + (len(rings) - 1) * n
    F += [[top, s + j, s + (j + 1) % n] for j in range(n)]
    V, F = np.array(V), np.array(F, np.int64)
    for _ in range(levels):
        V, F = subdivide(V, F)
    return V, F


def tube(n_around=1024, n_along=64, length=10.0, radius=0.5):
    """(V, F): an open tube of n_around × n_along quads, each split in two."""
    t = np.arange(n_around) * 2 * np.pi / n_around
    z = np.linspace(0.0, length, n_along + 1)
    V = np.stack([np.tile(radius * np.cos(t), n_along + 1), np.tile(radius * np.sin(t), n_along + 1),
                  np.repeat(z, n_around)], axis=1)
    i, j = np.meshgrid(np.arange(n_along), np.arange(n_around), indexing="ij")
    a = (i * n_around + j).ravel()
    b = (i * n_around + (j + 1) % n_around).ravel()
    return V, np.concatenate([np.stack([a, b, b + n_around], 1), np.stack([a, b + n_around, a + n_around], 1)])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tube", action="store_true", help="also the 1,024 x 64 tube")
    ap.add_argument("--rev", default=None, help="also time the package at this git revision")
    args = ap.parse_args(argv)
    versions = [("this checkout", qemjax)]
    if args.rev:
        from ab_compare import load_old
        versions.append((args.rev, load_old(args.rev)))
    tor = qemjax.shapes.torus(n_major=256, n_minor=256)
    cases = [("torus 256x256", (np.asarray(tor.vertices), np.asarray(tor.faces))), ("capsule", capsule())]
    if args.tube:
        cases.append(("tube 1024x64", tube()))
    print(f"cpu: {cpu_model()}; evaluate after simplify(ratio=0.1), warm, median of {args.repeats}")
    times = {}
    for name, mesh in cases:
        res = qemjax.simplify(mesh, ratio=0.1)
        values = []
        for label, pkg in versions:
            slow = name.startswith("tube")  # minutes a call before the fix: timed once, cold (no compilation)
            times[name, label] = median_time(lambda: pkg.metrics.evaluate(mesh, res), 1 if slow else args.repeats,
                                             warm=not slow)
            e = pkg.metrics.evaluate(mesh, res)
            values.append({k: v for k, v in e.items() if not k.endswith("_s")})
            print(f"{name:14s} {len(mesh[1]):7d} faces  {label:14s} evaluate {times[name, label]:7.2f} s", flush=True)
        if len(values) > 1:
            same = all(repr(values[0][k]) == repr(values[1][k]) for k in values[0])
            print(f"{'':14s} same values in both versions: {same}")
    for label, _ in versions:
        base = times["torus 256x256", label]
        for name, _ in cases[1:]:
            print(f"{label}: {name} / torus = {times[name, label] / base:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
