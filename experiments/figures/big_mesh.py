"""Writes a large closed mesh made in code to a binary PLY, band by band, never holding it: a torus on an
n×m parametric grid (2nm faces) whose tube radius carries bumps at several scales, from a few waves
around the ring down to ripples a few cells wide, plus some round bumps, so that simplification has
detail to keep and flat stretches to remove. For the partitioned stages' memory and time checks.

    python experiments/figures/big_mesh.py --faces 100000000 --out /tmp/big.ply
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from qemjax._partition.write import write_binary_ply  # noqa: E402

MAJOR, MINOR = 1.0, 0.35
# (amplitude, waves around the ring, waves around the tube): whole numbers, so the surface closes
WAVES = [(0.12, 3, 2), (0.05, 17, 5), (0.02, 61, 23), (0.006, 233, 89), (0.002, 997, 331)]


def grid(faces: int) -> tuple[int, int]:
    """n (around the ring) and m (around the tube), n/m near MAJOR/MINOR, 2nm near ``faces``."""
    m = max(3, round(np.sqrt(faces / 2 * MINOR / MAJOR)))
    return max(3, round(faces / 2 / m)), m


def _bumps(seed: int = 0, count: int = 12):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 2 * np.pi, (count, 2)), rng.uniform(0.05, 0.4, count), rng.uniform(-0.15, 0.15, count)


def band_vertices(u0: int, u1: int, n: int, m: int, bumps) -> np.ndarray:
    """Vertices of rows u0..u1 (row-major, m per row) as float32 (k,3)."""
    a = (2 * np.pi * np.arange(u0, u1) / n)[:, None]
    b = (2 * np.pi * np.arange(m) / m)[None, :]
    r = np.ones((u1 - u0, m))
    for amp, i, j in WAVES:
        r += amp * np.sin(i * a + 0.3 * j) * np.sin(j * b + 0.7 * i)
    centres, widths, heights = bumps
    for (ca, cb), w, h in zip(centres, widths, heights):
        da = np.angle(np.exp(1j * (a - ca)))  # wrapped angle differences: the bumps close too
        db = np.angle(np.exp(1j * (b - cb)))
        r += h * np.exp(-(da ** 2 * (MAJOR / MINOR) ** 2 + db ** 2) / (2 * w ** 2))
    r *= MINOR
    ring = MAJOR + r * np.cos(b)
    V = np.stack([ring * np.cos(a), ring * np.sin(a), r * np.sin(b)], -1)
    return V.reshape(-1, 3).astype(np.float32)


def band_faces(u0: int, u1: int, n: int, m: int) -> np.ndarray:
    """The two triangles of each grid cell of rows u0..u1, cell by cell (neighbours stay near in the file)."""
    u, v = np.meshgrid(np.arange(u0, u1), np.arange(m), indexing="ij")
    i0, i1 = u * m + v, (u + 1) % n * m + v
    i2, i3 = (u + 1) % n * m + (v + 1) % m, u * m + (v + 1) % m
    return np.stack([np.stack([i0, i1, i2], -1), np.stack([i0, i2, i3], -1)], 2).reshape(-1, 3).astype(np.int32)


def write(out, faces: int, band_cells: int = 1 << 21) -> tuple[int, int]:
    n, m = grid(faces)
    rows = max(1, band_cells // m)
    bumps = _bumps()
    vertices = (band_vertices(u, min(u + rows, n), n, m, bumps) for u in range(0, n, rows))
    tris = (band_faces(u, min(u + rows, n), n, m) for u in range(0, n, rows))
    return write_binary_ply(out, vertices, tris, n_vertices=n * m, n_faces=2 * n * m)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--faces", type=int, default=10_000_000)
    p.add_argument("--out", default="/tmp/big.ply")
    args = p.parse_args(argv)
    t = time.perf_counter()
    nv, nf = write(args.out, args.faces)
    print(f"{nf} faces, {nv} vertices, {time.perf_counter() - t:.1f} s, {os.path.getsize(args.out) / 2**20:.0f} MiB "
          f"-> {args.out}")


if __name__ == "__main__":
    main()
