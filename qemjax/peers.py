"""Peer simplifiers (meshoptimizer, MeshLab, fast-simplification, libigl, pyfqmr) behind one call.

``pip install 'qemjax[bench]'`` installs them; each is imported lazily, inside its adapter, so this module
(and ``qemjax``) imports without any of them.

- `available()`: the peer names whose package imports here.
- `simplify(name, mesh, target_faces)`: a `PeerResult` with ``.vertices`` (n, 3) float64, ``.faces``
  (m, 3) int64 (unreferenced vertices dropped), ``.stop_reason`` (``"peer"``) and ``.stats`` (the keys
  `qemjax.sweep` writes: ``faces_in``, ``faces_out``, ``target_faces``, ``run_s`` = ``total_s`` = the
  simplification call's wall time, ``compile_s`` 0, ``rounds`` NaN). Before the first call of a peer in a
  process it runs once on a small icosphere (library loading, first-call setup), so times are warm.
- `qemjax.sweep` runs a peer for a cell whose ``method`` names one (``{"method": ["qem", "pymeshlab"]}``).

A missing peer raises ValueError naming it and the extra. Every adapter has the signature
``simplify_<peer>(V, F, target_faces, *, timings=None) -> (V2, F2)``; only the simplification call itself
is timed (``timings["call_s"]``), not converting arrays to the peer's types or compacting its output.
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from collections.abc import Callable

import numpy as np

__all__ = [
    "PEERS",
    "PeerResult",
    "available",
    "compact",
    "is_peer",
    "run_peer",
    "simplify",
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


def _valid(V, F) -> tuple[np.ndarray, np.ndarray]:
    """(V, F) checked as `simplify` checks a mesh (`metrics._common.as_mesh`), polygons refused: the peers' C
    code crashed the interpreter on an index out of range or faces that are not triangles, so every adapter
    checks first."""
    from .metrics._common import as_mesh

    checked = as_mesh((V, F), "mesh", polygons=False)
    return checked.vertices, checked.faces


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
    V, F = _valid(V, F)
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
    V, F = _valid(V, F)
    import fast_simplification

    points = np.ascontiguousarray(V, dtype=np.float64)
    triangles = np.ascontiguousarray(F, dtype=np.int32)
    # a target at or above the faces there are keeps them all (a negative reduction is refused by the package)
    reduction = max(0.0, 1.0 - float(target_faces) / max(len(triangles), 1))
    with _Clock(timings):
        V2, F2 = fast_simplification.simplify(points, triangles, target_reduction=reduction)
    return compact(V2, F2)


def simplify_pyfqmr(V, F, target_faces, *, timings=None):
    """pyfqmr (another Fast-Quadric-Mesh-Simplification wrapper), aggressiveness 7, borders preserved."""
    V, F = _valid(V, F)
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
    V, F = _valid(V, F)
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
    V, F = _valid(V, F)
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

# distribution names (for version reports) and the modules each adapter imports
_MODULES = {"meshoptimizer": "meshoptimizer", "fast-simplification": "fast_simplification", "pyfqmr": "pyfqmr",
            "pymeshlab": "pymeshlab", "libigl": "igl"}
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


# the extents and offsets a peer computes in as given; outside them it gets the mesh in a frame of its own
# (`_frame`): their squared lengths and quadrics, in float32 or float64, would overflow, underflow or lose the
# detail to the offset (some peers then return the input unchanged)
_EXTENT = (2.0 ** -30, 2.0 ** 30)
_OFFSET = 2.0 ** 16  # a centre this many extents from the origin


def _frame(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(centre (3,), scale) that take the vertices the faces F use into a frame a peer computes in, the scale
    a power of two; None for a mesh of ordinary extent near the origin (what every peer was measured on: run
    as it is, the same bits). A vertex no face uses is not measured: one far away would shrink the mesh."""
    V = V[np.unique(F)]  # (a mesh `_valid` passed: faces in range, the vertices they use finite)
    lo, hi = V.min(0), V.max(0)
    extent = float(np.max(hi - lo))
    if not extent > 0:
        return None
    centre = 0.5 * (lo + hi)
    if _EXTENT[0] <= extent <= _EXTENT[1] and float(np.max(np.abs(centre))) <= _OFFSET * extent:
        return None
    return centre, float(2.0 ** np.round(np.log2(extent)))


def run_peer(name: str, V, F, target_faces: int, *, warmup: bool = True):
    """Run peer ``name``; returns ``(V2, F2, call_s)`` with ``call_s`` the time of the simplification call.
    A mesh far from the extents and offsets peers compute in (`_frame`) runs centred and scaled by a power of
    two, and its output is taken back to the input's units."""
    _require(name)  # an unknown name: the ValueError naming the peers, not PEERS' KeyError
    V, F = _valid(V, F)  # (as the adapter would, before the frame reads the faces)
    fn = PEERS[name]
    if warmup and name not in _warmed:
        Vw, Fw = _warmup_mesh()
        fn(Vw, Fw, len(Fw) // 4)
        _warmed.add(name)
    timings: dict = {}
    frame = _frame(V, F)
    if frame is None:
        V2, F2 = fn(V, F, int(target_faces), timings=timings)
    else:
        centre, scale = frame
        V2, F2 = fn((V - centre) / scale, F, int(target_faces), timings=timings)
        V2 = np.asarray(V2, np.float64) * scale + centre
    return V2, F2, timings["call_s"]


def is_peer(method) -> bool:
    """Whether ``method`` (a `simplify` method value) names a peer."""
    return isinstance(method, str) and method in PEERS


def _require(name: str) -> None:
    if name not in PEERS:
        raise ValueError(f"unknown peer {name!r}; peers are {list(PEERS)}")
    try:
        importlib.import_module(_MODULES[name])
    except ImportError as exc:
        raise ValueError(f"peer {name!r} needs the package {PEER_PACKAGES[name]!r}, which is not installed "
                         f"(pip install 'qemjax[bench]'): {exc}") from None


def available() -> list[str]:
    """The peers whose package imports in this environment, in `PEERS` order."""
    out = []
    for name in PEERS:
        try:
            importlib.import_module(_MODULES[name])
        except ImportError:
            continue
        out.append(name)
    return out


@dataclasses.dataclass(eq=False)  # arrays: `==` is identity (an elementwise == has no one truth value)
class PeerResult:
    """A peer's output: ``vertices`` (n, 3) float64, ``faces`` (m, 3) int64, ``stop_reason`` and ``stats``
    (see the module docstring). Compares and hashes by identity (``a == b`` is ``a is b``)."""

    vertices: np.ndarray
    faces: np.ndarray
    stats: dict
    stop_reason: str = "peer"


def simplify(name: str, mesh, target_faces: int) -> PeerResult:
    """Simplify ``mesh`` (``(V, F)``, a `qemjax.Mesh`, trimesh, anything with ``.vertices``/``.faces``, or
    a file's path) with peer ``name`` to ``target_faces`` faces (a peer may stop elsewhere:
    ``stats["faces_out"]``). Raises ValueError for an unknown or uninstalled peer, a malformed mesh (checked
    here: the peers' C code would crash the process on an index out of range or faces that are not
    triangles), a target below 1, or an empty output."""
    from .metrics._common import as_mesh

    checked = as_mesh(mesh, "mesh", polygons=False)
    V, F = checked.vertices, checked.faces
    # a number only (inf, None or text raised float's or int's own error)
    if isinstance(target_faces, bool) or not isinstance(target_faces, (int, float, np.integer, np.floating)) \
            or not 1 <= target_faces < float("inf") or target_faces != int(target_faces):
        raise ValueError(f"target_faces must be a whole number of at least 1, got {target_faces!r}")
    _require(name)
    target = min(int(target_faces), len(F))  # as `qemjax.simplify` takes a target above the faces there are
    t0 = time.perf_counter()
    V2, F2, call_s = run_peer(name, V, F, target)
    if len(F2) == 0:
        raise ValueError(f"peer {name!r} returned an empty mesh (target {target} of {len(F)} faces)")
    stats = {"faces_in": int(len(F)), "faces_out": int(len(F2)), "target_faces": target,
             "rounds": float("nan"), "compile_s": 0.0, "run_s": call_s, "total_s": call_s,
             "wall_s": time.perf_counter() - t0}
    return PeerResult(V2, F2, stats)
