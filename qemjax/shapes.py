"""Meshes generated in code (no files needed): for tests, the demo and experiments.

Every function returns a `Mesh` (vertices (n,3) float64, faces (m,3) int64), consistently oriented.
"""
from __future__ import annotations

import numpy as np

from ._io import Mesh


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> Mesh:
    """Geodesic sphere with 20·4^subdivisions faces."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return Mesh(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))


def torus(major: float = 1.0, minor: float = 0.35, n_major: int = 48, n_minor: int = 24) -> Mesh:
    """Closed genus-1 torus with 2·n_major·n_minor faces."""
    u, v = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a, b = 2 * np.pi * u / n_major, 2 * np.pi * v / n_minor
    V = np.stack([(major + minor * np.cos(b)) * np.cos(a), (major + minor * np.cos(b)) * np.sin(a),
                  minor * np.sin(b)], -1).reshape(-1, 3)
    i0 = (u * n_minor + v).reshape(-1)
    i1 = (((u + 1) % n_major) * n_minor + v).reshape(-1)
    i2 = (((u + 1) % n_major) * n_minor + (v + 1) % n_minor).reshape(-1)
    i3 = (u * n_minor + (v + 1) % n_minor).reshape(-1)
    F = np.concatenate([np.stack([i0, i1, i2], 1), np.stack([i0, i2, i3], 1)])
    return Mesh(V, F.astype(np.int64))


def grid(n: int = 20, size: float = 1.0, hole: bool = False) -> Mesh:
    """Flat open square [0,size]² in the z=0 plane, n×n cells of two triangles, normals +z.

    hole=True removes the cells of the middle third, leaving a square hole (a second boundary loop).
    """
    x = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    V = np.stack([X.reshape(-1), Y.reshape(-1), np.zeros(X.size)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = np.ones_like(i, bool)
    if hole:
        lo, hi = n // 3, n - n // 3
        keep = ~((i >= lo) & (i < hi) & (j >= lo) & (j < hi))
    i, j = i[keep], j[keep]
    a = i * (n + 1) + j
    b, c, d = a + (n + 1), a + (n + 2), a + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    used = np.zeros(len(V), bool)
    used[F.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    return Mesh(V[used], remap[F].astype(np.int64))


def cube(subdivisions: int = 2) -> Mesh:
    """Closed unit cube (sharp creases and corners), each face split by midpoint subdivision."""
    import trimesh

    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    for _ in range(subdivisions):
        V, F = trimesh.remesh.subdivide(V, F)
    return Mesh(np.asarray(V, float), np.asarray(F, np.int64))


def bumpy_sphere(subdivisions: int = 6, amplitude: float = 0.08, seed: int = 0) -> Mesh:
    """Icosphere whose radius varies with a few smooth random bumps: detail worth simplifying.
    subdivisions=6 gives 81,920 faces, 7 gives 327,680."""
    V, F = icosphere(subdivisions)
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(12, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    r = 1.0 + amplitude * np.sum(np.exp(8.0 * (V @ dirs.T - 1.0)) * rng.uniform(-1, 1, 12), 1)
    r += 0.25 * amplitude * np.sin(9 * V[:, 0]) * np.sin(7 * V[:, 1]) * np.sin(8 * V[:, 2])
    return Mesh(V * r[:, None], F)
