"""Mesh files with stored appearance attributes, written from generated meshes (no files needed).

For the tests and `experiments/figures/attribute_defaults.py`: each writer takes a `Mesh` and a path and writes the
file an exporter would (PLY with ``nx ny nz`` or ``red green blue``, OBJ with ``vn`` or ``vt`` per corner).
"""
from __future__ import annotations

import math

import numpy as np

from .._mesh import fixed_order
from .mesh import Mesh


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """(n,3) unit area-weighted vertex normals."""
    V, F = mesh
    P = V[F]
    cross = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], cross)
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def scaled_normals(mesh: Mesh, lo: float = 0.05, hi: float = 13.0, seed: int = 0) -> np.ndarray:
    """(n,3) unit normals times random lengths in [lo, hi] (log-uniform): what some exporters store."""
    rng = np.random.default_rng(seed)
    return vertex_normals(mesh) * fixed_order.exp(rng.uniform(math.log(lo), math.log(hi), len(mesh.vertices)))[:, None]


def area_sum_normals(mesh: Mesh) -> np.ndarray:
    """(n,3) unnormalised sums of the faces' area vectors at each vertex, as MeshLab / VCG store them."""
    V, F = mesh
    P = V[F]
    cross = 0.5 * np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], cross)
    return N


def write_ply(path, mesh: Mesh, normals: np.ndarray | None = None, colors: np.ndarray | None = None) -> None:
    """An ASCII PLY with per-vertex ``nx ny nz`` and/or ``red green blue`` (colours (n,3) in [0, 1])."""
    V, F = mesh
    props = ["property float x", "property float y", "property float z"]
    cols = [np.asarray(V, np.float64)]
    fmt = ["%.9g"] * 3
    if normals is not None:
        props += ["property float nx", "property float ny", "property float nz"]
        cols.append(np.asarray(normals, np.float64))
        fmt += ["%.9g"] * 3
    if colors is not None:
        props += ["property uchar red", "property uchar green", "property uchar blue"]
        cols.append(np.round(np.clip(colors, 0, 1) * 255))
        fmt += ["%d"] * 3
    head = "\n".join(["ply", "format ascii 1.0", f"element vertex {len(V)}", *props,
                      f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"])
    with open(path, "w") as fh:
        fh.write(head + "\n")
        np.savetxt(fh, np.concatenate(cols, 1), fmt=" ".join(fmt))
        np.savetxt(fh, np.concatenate([np.full((len(F), 1), 3), F], 1), fmt="%d")


def crease_normals(mesh: Mesh, angle: float = 60.0) -> np.ndarray:
    """(m,3,3) per-corner unit normals, smooth except across edges sharper than ``angle`` degrees: each
    corner averages the (area-weighted) normals of the faces at its vertex within ``angle`` of its own
    face's, as modelling tools' smoothing groups do. Hard creases then split a vertex into wedges."""
    V, F = mesh
    P = V[F]
    cross = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    unit = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    cos = math.cos(math.radians(angle))
    order = np.argsort(F.reshape(-1), kind="stable")
    corner_face = np.repeat(np.arange(len(F)), 3)[order]
    verts = F.reshape(-1)[order]
    start = np.searchsorted(verts, np.arange(len(V) + 1))
    out = np.zeros((len(F), 3, 3))
    for v in range(len(V)):
        fs = corner_face[start[v]:start[v + 1]]
        near = fixed_order.dot(unit[fs][:, None], unit[fs][None]) >= cos  # (k,k): which faces smooth with which
        acc = fixed_order.dot(near.astype(np.float64)[:, None], cross[fs].T[None])  # near @ cross[fs]
        acc /= np.linalg.norm(acc, axis=1, keepdims=True)
        k = np.argmax(F[fs] == v, axis=1)
        out[fs, k] = acc
    return out


def write_obj(path, mesh: Mesh, corner_normals: np.ndarray | None = None, uv: np.ndarray | None = None,
              corner_uv: np.ndarray | None = None) -> None:
    """An OBJ with per-corner normals (``corner_normals`` (m,3,3): one ``vn`` per distinct value) and/or
    UVs (``uv`` (t,2) with ``corner_uv`` (m,3) indices into it)."""
    V, F = mesh
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V]
    ni = None
    if corner_normals is not None:
        vals, ni = np.unique(np.round(corner_normals.reshape(-1, 3), 9), axis=0, return_inverse=True)
        ni = ni.reshape(-1, 3)
        lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vals]
    if uv is not None:
        lines += [f"vt {u:.9g} {v:.9g}" for u, v in uv]
    for i, f in enumerate(F + 1):
        if ni is not None and uv is not None:
            c = [f"{f[k]}/{corner_uv[i, k] + 1}/{ni[i, k] + 1}" for k in range(3)]
        elif ni is not None:
            c = [f"{f[k]}//{ni[i, k] + 1}" for k in range(3)]
        elif uv is not None:
            c = [f"{f[k]}/{corner_uv[i, k] + 1}" for k in range(3)]
        else:
            c = [str(x) for x in f]
        lines.append("f " + " ".join(c))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def smooth_colors(mesh: Mesh) -> np.ndarray:
    """(n,3) colours in [0, 1] that vary smoothly over the surface."""
    V = mesh.vertices
    return 0.5 + 0.5 * np.stack([fixed_order.sin(3 * V[:, 0]), fixed_order.sin(3 * V[:, 1] + 1),
                                 fixed_order.cos(2 * V[:, 2])], 1)


def spherical_uv(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(uv (t,2), corner_uv (m,3)): a longitude/latitude map of a closed mesh around the origin, cut along
    the meridian at u = 0 / 1 (faces that cross it take u + 1 at their low corners): one UV seam."""
    V, F = mesh
    d = V / np.linalg.norm(V, axis=1, keepdims=True)
    u = (fixed_order.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi)) % 1.0
    v = fixed_order.arccos(np.clip(d[:, 2], -1, 1)) / np.pi
    cu = u[F]
    wrap = (cu.max(1) - cu.min(1)) > 0.5
    cu = np.where(wrap[:, None] & (cu < 0.5), cu + 1.0, cu)
    corner = np.stack([cu.reshape(-1), v[F].reshape(-1)], 1)
    uv, idx = np.unique(np.round(corner, 9), axis=0, return_inverse=True)
    return uv, idx.reshape(-1, 3)
