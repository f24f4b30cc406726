"""Adapters for the peer simplifiers that qemjax is benchmarked against.

Every adapter has the same signature::

    simplify_<peer>(V, F, target_faces, *, timings=None) -> (V2, F2)

``V`` is (n, 3) float64, ``F`` is (m, 3) integer; the result is (n2, 3) float64 and (m2, 3) int64 with
unreferenced vertices removed. Each peer is imported lazily, inside its adapter, so that this module imports
without any of them installed.

Only the simplification call itself is timed: converting arrays to the peer's dtypes or containers beforehand,
and compacting its output afterwards, are left out. When ``timings`` (a dict) is given, ``timings["call_s"]``
receives that time in seconds.

``run_peer(name, V, F, target_faces)`` does one cheap warm-up per process and peer (on a small icosphere, to
pay library loading and first-call setup) and returns ``(V2, F2, call_s)``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

__all__ = [
    "PEERS",
    "compact",
    "run_peer",
    "simplify_fast_simplification",
    "simplify_libigl",
    "simplify_meshoptimizer",
    "simplify_pyfqmr",
    "simplify_pymeshlab",
]

# meshoptimizer's error limit is relative to the mesh extent; 1e10 means "no limit": stop only at the target.
MESHOPT_ERROR_LIMIT = 1e10


def compact(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face references; returns (n2, 3) float64 and (m, 3) int64."""
    V = np.asarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    used, inverse = np.unique(F.ravel(), return_inverse=True)
    return V[used], inverse.reshape(-1, 3).astype(np.int64)


class _Clock:
    """Context manager that writes the elapsed wall time into ``timings["call_s"]``."""

    def __init__(self, timings: dict | None):
        self.timings = timings

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        if self.timings is not None:
            self.timings["call_s"] = time.perf_counter() - self.t0
        return False


def simplify_meshoptimizer(V, F, target_faces, *, timings=None):
    """meshoptimizer's quadric simplifier (``meshopt_simplify``, not the sloppy one).

    Target index count is ``3 * target_faces``; the error limit is effectively unbounded so that it stops only
    at the target (or when no collapse is left). Options are the defaults (borders may only slide along
    themselves; no vertex locking).
    """
    import meshoptimizer

    indices = np.ascontiguousarray(np.asarray(F).reshape(-1), dtype=np.uint32)
    positions = np.ascontiguousarray(V, dtype=np.float32)
    destination = np.empty(indices.size, dtype=np.uint32)
    with _Clock(timings):
        n_indices = meshoptimizer.simplify(
            destination,
            indices,
            positions,
            target_index_count=3 * int(target_faces),
            target_error=MESHOPT_ERROR_LIMIT,
        )
    return compact(V, destination[:n_indices].reshape(-1, 3))


def simplify_fast_simplification(V, F, target_faces, *, timings=None):
    """fast-simplification (a wrapper of Fast-Quadric-Mesh-Simplification), via ``target_reduction``."""
    import fast_simplification

    points = np.ascontiguousarray(V, dtype=np.float64)
    triangles = np.ascontiguousarray(F, dtype=np.int32)
    reduction = 1.0 - float(target_faces) / max(len(triangles), 1)
    with _Clock(timings):
        V2, F2 = fast_simplification.simplify(points, triangles, target_reduction=reduction)
    return compact(V2, F2)


def simplify_pyfqmr(V, F, target_faces, *, timings=None):
    """pyfqmr (another Fast-Quadric-Mesh-Simplification wrapper), aggressiveness 7, borders preserved."""
    import pyfqmr

    simplifier = pyfqmr.Simplify()
    simplifier.setMesh(np.ascontiguousarray(V, dtype=np.float64), np.ascontiguousarray(F, dtype=np.int32))
    with _Clock(timings):
        simplifier.simplify_mesh(
            target_count=int(target_faces), aggressiveness=7, preserve_border=True, verbose=False
        )
    V2, F2, _normals = simplifier.getMesh()
    return compact(V2, F2)


def simplify_pymeshlab(V, F, target_faces, *, timings=None):
    """MeshLab's quadric edge collapse (Garland-Heckbert), optimal placement, normal flips prevented."""
    import pymeshlab

    meshset = pymeshlab.MeshSet()
    meshset.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.ascontiguousarray(V, dtype=np.float64),
            face_matrix=np.ascontiguousarray(F, dtype=np.int32),
        )
    )
    with _Clock(timings):
        meshset.meshing_decimation_quadric_edge_collapse(
            targetfacenum=int(target_faces), optimalplacement=True, preservenormal=True
        )
    out = meshset.current_mesh()
    return compact(out.vertex_matrix(), out.face_matrix())


def simplify_libigl(V, F, target_faces, *, timings=None):
    """libigl's ``igl.qslim`` (QSlim: quadric cost, optimal placement); assumes an edge-manifold input.

    Depending on the libigl version it returns ``(U, G, J, I)`` or ``(ok, U, G, J, I)``: the first two 2-D
    arrays are taken as the vertices and faces.
    """
    import igl

    Vf = np.asfortranarray(V, dtype=np.float64)
    Ff = np.asfortranarray(F, dtype=np.int32)
    with _Clock(timings):
        out = igl.qslim(Vf, Ff, int(target_faces))
    arrays = [a for a in out if isinstance(a, np.ndarray) and a.ndim == 2]
    U, G = arrays[0], arrays[1]
    return compact(U, G)


PEERS: dict[str, Callable] = {
    "meshoptimizer": simplify_meshoptimizer,
    "fast-simplification": simplify_fast_simplification,
    "pyfqmr": simplify_pyfqmr,
    "pymeshlab": simplify_pymeshlab,
    "libigl": simplify_libigl,
}

# distribution names, for version reports
PEER_PACKAGES = {
    "meshoptimizer": "meshoptimizer",
    "fast-simplification": "fast-simplification",
    "pyfqmr": "pyfqmr",
    "pymeshlab": "pymeshlab",
    "libigl": "libigl",
}

_warmed: set[str] = set()


def _warmup_mesh() -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3)  # 1280 faces
    return np.asarray(sphere.vertices, dtype=np.float64), np.asarray(sphere.faces, dtype=np.int64)


def run_peer(name: str, V, F, target_faces: int, *, warmup: bool = True):
    """Run peer ``name``; returns ``(V2, F2, call_s)`` with ``call_s`` the time of the simplification call."""
    fn = PEERS[name]
    if warmup and name not in _warmed:
        Vw, Fw = _warmup_mesh()
        fn(Vw, Fw, len(Fw) // 4)
        _warmed.add(name)
    timings: dict = {}
    V2, F2 = fn(V, F, int(target_faces), timings=timings)
    return V2, F2, timings["call_s"]
