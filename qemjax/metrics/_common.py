"""Input checking and per-mesh arrays shared by the metric modules.

Everything here is plain numpy in float64: metrics are measured on the host, once per evaluation, and must be
exact enough to compare simplifiers whose errors differ by less than float32 resolution.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .._io.mesh import _triangulate
from .._mesh.arrays import box_diagonal, nonfinite, whole_numbers

# Triangles with twice-area <= _DEGENERATE_REL * (longest edge)^2 count as degenerate (numerically zero area).
_DEGENERATE_REL = 1e-12


def as_mesh(mesh, name: str = "mesh", polygons: bool = True) -> MeshArrays:
    """Validate a mesh given as a `trimesh.Trimesh` (or a `trimesh.Scene`, concatenated), a ``(vertices,
    faces)`` pair, any object with ``.vertices`` and ``.faces``, or a file's path (read as `qemjax.load`
    reads it, without its warning); return float64 vertices (n, 3) and int64 faces (m, 3). Polygon faces
    (m, k > 3) are fan-triangulated as `simplify` triangulates them; ``polygons=False`` refuses them (the
    peers take triangles only). A trimesh or file carrying per-vertex UVs, colours or normals comes marked
    ``seams``: its topology reads `MeshArrays.welded`.

    Raises ValueError on wrong shapes, an empty mesh, non-finite coordinates of a vertex a face uses,
    non-integer or out-of-range face indices. A vertex no face uses may hold NaN or inf (`simplify` drops
    it): its position is replaced by that of a vertex a face uses, on which no measure of the surface
    depends (counts of vertices still count it).
    """
    if isinstance(mesh, MeshArrays):
        return mesh
    seams = False
    if isinstance(mesh, (str, os.PathLike)):  # as `attribute_deviation` takes it
        from .._io.mesh import _read_trimesh

        mesh = _read_trimesh(mesh)
    if type(mesh).__module__.startswith("trimesh"):  # a Scene (a glTF's), concatenated as simplify takes it
        from .._io.mesh import _as_trimesh
        from .._mesh.wedges import from_trimesh

        try:
            mesh = _as_trimesh(mesh)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
        # per-vertex UVs, colours or normals, as simplify reads them: trimesh splits the vertices where they
        # differ (a textured file, a textured result's to_trimesh), which is no cut in the surface
        seams = bool(from_trimesh(mesh)[0])
    if isinstance(mesh, (tuple, list)):
        if len(mesh) != 2:
            raise ValueError(f"{name}: a tuple mesh must be (vertices, faces), got {len(mesh)} items")
        vertices, faces = mesh
    elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        vertices, faces = mesh.vertices, mesh.faces
    else:
        raise ValueError(
            f"{name}: expected a trimesh.Trimesh, a (vertices, faces) tuple, an object with .vertices and "
            f".faces or a file's path, got {type(mesh).__name__}"
        )
    v, f = _rectangular(name, "vertices", vertices), _rectangular(name, "faces", faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{name}: vertices must have shape (n, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] < 3 or (f.shape[1] != 3 and not polygons):
        polygonal = " (or (m, k>=3) polygons)" if polygons else " (triangles only)"
        raise ValueError(f"{name}: faces must have shape (m, 3){polygonal}, got {f.shape}")
    if len(v) == 0 or len(f) == 0:
        raise ValueError(f"{name}: empty mesh ({len(v)} vertices, {len(f)} faces)")
    if not np.issubdtype(v.dtype, np.number) or np.iscomplexobj(v):
        raise ValueError(f"{name}: vertices must be real numbers, got dtype {v.dtype}")
    v = np.ascontiguousarray(v, dtype=np.float64)
    if not whole_numbers(f):
        raise ValueError(f"{name}: faces must hold integer vertex indices, got dtype {f.dtype}")
    # triangles as simplify makes them of polygons, so that a result is measured against the input it ran on
    f = np.ascontiguousarray(_triangulate(f.astype(np.int64, copy=False)))
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"{name}: face indices must lie in [0, {len(v)}), got [{f.min()}, {f.max()}]")
    bad, used = nonfinite(v, f)
    if used.size:
        raise ValueError(f"{name}: vertices contain NaN or infinite values")
    if bad.any():
        # an unused vertex's junk (simplify drops it) is no part of the surface: it takes the place of a
        # vertex a face uses, so that what reads every vertex (signed_volume's mean, in_frame's check of the
        # scaled positions) reads finite values near the mesh
        v = v.copy()
        v[bad] = v[f[0, 0]]
    return MeshArrays(v, f, seams)


def _rectangular(name: str, what: str, x) -> np.ndarray:
    """np.asarray(x); ValueError naming the mesh and ``what`` for a ragged nested list (numpy's own message
    named neither)."""
    try:
        return np.asarray(x)
    except (ValueError, TypeError):
        raise ValueError(f"{name}: {what} must be a rectangular array, got a ragged list") from None


def frame_exponent(V: np.ndarray) -> int:
    """k, the binary exponent of the largest side of V's bounding box (0 for no extent, or none float64
    holds): V·2^-k has its largest side in [0.5, 1)."""
    if len(V) == 0:
        return 0
    with np.errstate(over="ignore", invalid="ignore"):
        side = float(np.max(V.max(axis=0) - V.min(axis=0)))
    return math.frexp(side)[1] if math.isfinite(side) and side > 0 else 0


def scaled(reference: np.ndarray, *Vs: np.ndarray) -> tuple[int, list]:
    """(k, the positions Vs times 2^-k), k the `frame_exponent` of the positions ``reference``; k is 0 and Vs
    are as given where a scaled position would not be finite (a tiny mesh far from the origin)."""
    k = frame_exponent(reference)
    if k == 0:
        return 0, list(Vs)
    with np.errstate(over="ignore", under="ignore"):
        out = [np.ldexp(V, -k) for V in Vs]
    if not all(np.isfinite(V).all() for V in out):
        return 0, list(Vs)
    return k, out


def in_frame(first: MeshArrays, *others: MeshArrays) -> tuple[int, list]:
    """(k, the meshes with their positions times 2^-k), k the `frame_exponent` of ``first``'s referenced
    vertices (`scaled`). The metrics measure there, where the extent is about 1, so that squared distances,
    areas and products of normals (a length to the fourth) stay within float64's range at any scale (1e-100
    or 1e100 mesh units, as the simplifier's unit frame does), and report lengths in mesh units times 2^k
    (areas 2^2k, volumes 2^3k). Scaling by a power of two is exact, and so is the arithmetic on the scaled
    values barring underflow: at ordinary scales the results are the bits measured in mesh units."""
    meshes = [first, *others]
    k, Vs = scaled(first.vertices[first.referenced], *(m.vertices for m in meshes))
    if k == 0:
        return 0, meshes
    return k, [MeshArrays(V, m.faces, m.seams) for V, m in zip(Vs, meshes)]


def to_mesh_units(value: float, power: int, k: int) -> float:
    """A value measured in the frame of `in_frame` (a length to ``power``) in mesh units: value·2^(power·k),
    inf or 0 where float64 cannot hold it."""
    with np.errstate(over="ignore", under="ignore"):
        return float(np.ldexp(value, power * k))


@dataclass(frozen=True, eq=False)
class MeshArrays:
    """A validated mesh, with derived arrays computed once on first use.

    vertices: (n, 3) float64; faces: (m, 3) int64. Lengths are in the mesh's own units. seams: the vertices
    are split where per-vertex attributes differ (a trimesh or file carrying UVs, colours or normals), so
    the connectivity is that of `welded`.
    """

    vertices: np.ndarray
    faces: np.ndarray
    seams: bool = False

    @cached_property
    def welded(self) -> MeshArrays:
        """The mesh whose connectivity the topology measures: with ``seams``, exactly coincident vertices
        joined (as `simplify` welds them), so that a seam is no border; otherwise this mesh."""
        if not self.seams:
            return self
        from .._io.mesh import weld

        V, F, merged = weld(self.vertices, self.faces)
        return MeshArrays(V, F) if merged else self

    @cached_property
    def corners(self) -> np.ndarray:
        """(3, 3, m) float64: corners[k, axis, face], component-first so each row is contiguous."""
        vt = np.ascontiguousarray(self.vertices.T)
        return np.stack([np.take(vt, np.ascontiguousarray(self.faces[:, k]), axis=1) for k in range(3)])

    @cached_property
    def cross(self) -> np.ndarray:
        """(3, m) float64: (b - a) x (c - a), twice the area times the unit normal (component-first)."""
        c = self.corners
        ab, ac = c[1] - c[0], c[2] - c[0]
        return np.stack([ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]])

    @cached_property
    def double_areas(self) -> np.ndarray:
        """(m,) float64: twice each face's area."""
        n = self.cross
        return np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])

    @cached_property
    def referenced(self) -> np.ndarray:
        """(n,) bool: vertices used by at least one face."""
        used = np.zeros(len(self.vertices), dtype=bool)
        used[self.faces.ravel()] = True
        return used

    @cached_property
    def bbox_diagonal(self) -> float:
        """Length of the bounding-box diagonal of the referenced vertices (mesh units)."""
        v = self.vertices[self.referenced]
        return box_diagonal(v.min(axis=0), v.max(axis=0))

    @cached_property
    def edges(self) -> EdgeTable:
        return EdgeTable.build(self.faces, len(self.vertices))


@dataclass(frozen=True, eq=False)
class EdgeTable:
    """Undirected edges of a triangle mesh and how its half-edges attach to them.

    Half-edge h = 3 * face + k runs from faces[face, k] to faces[face, (k + 1) % 3].
    A face that repeats a vertex, (a, a, b), has one half-edge on its edge (the first that runs a -> b or b -> a).

    lo, hi:     (E,) int64 endpoints of each undirected edge, lo < hi. Half-edges from a vertex to itself
                (faces that repeat a vertex) belong to no edge.
    count:      (E,) int64 number of half-edges (faces) on each edge.
    order:      (<= 3m,) int64 half-edge ids sorted by edge; edge e owns order[start[e] : start[e] + count[e]].
    start:      (E,) int64.
    forward:    (3m,) bool, per half-edge: True when it runs lo -> hi.
    points:     number of faces on no edge, (a, a, a): a point, no surface.
    """

    lo: np.ndarray
    hi: np.ndarray
    count: np.ndarray
    order: np.ndarray
    start: np.ndarray
    forward: np.ndarray
    points: int = 0

    @staticmethod
    def build(faces: np.ndarray, n_vertices: int) -> EdgeTable:
        a = faces.ravel()
        b = np.roll(faces, -1, axis=1).ravel()
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        key = lo * np.int64(n_vertices) + hi
        # Half-edges of faces that repeat a vertex (a == b) join no edge, and such a face (a, a, b) runs along
        # its one edge both ways: it is one face on it, its first half-edge there (counted twice, a lone
        # degenerate face read as a closed surface)
        ok = (a != b).reshape(-1, 3)
        repeats = ~ok.all(axis=1)
        if repeats.any():
            ok[repeats] &= np.cumsum(ok[repeats], axis=1) == 1
        proper = np.flatnonzero(ok.ravel())
        bits_h = max(len(a).bit_length(), 1)
        if int(key.max(initial=0)).bit_length() + bits_h <= 63:
            # Sort (key, half-edge) packed in one int64: a plain sort is several times faster than argsort.
            packed = np.sort((key[proper] << bits_h) | proper)
            sorted_key = packed >> bits_h
            order = packed & ((1 << bits_h) - 1)
        else:
            order = proper[np.argsort(key[proper])]
            sorted_key = key[order]
        first = np.ones(len(sorted_key), dtype=bool)
        first[1:] = sorted_key[1:] != sorted_key[:-1]
        start = np.flatnonzero(first)
        count = np.diff(np.append(start, len(sorted_key)))
        head = order[start]
        points = int((~ok.any(axis=1)).sum()) if repeats.any() else 0
        return EdgeTable(lo[head], hi[head], count, order, start, a < b, points)

    @cached_property
    def manifold_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The two half-edges of every edge shared by exactly two faces: two (E2,) int64 arrays."""
        s = self.start[self.count == 2]
        return self.order[s], self.order[s + 1]

    @cached_property
    def watertight(self) -> bool:
        """Every edge is shared by exactly two faces, and every face lies on an edge: a face (a, a, a) bounds
        nothing and has no surface, so a mesh with one (or of nothing else) is not closed."""
        return bool((self.count == 2).all()) and self.points == 0

    @cached_property
    def consistent(self) -> bool:
        """The two faces of every two-face edge traverse it in opposite directions."""
        h1, h2 = self.manifold_pairs
        return bool((self.forward[h1] != self.forward[h2]).all())

    @property
    def closed(self) -> bool:
        """Watertight and consistently oriented: the signed volume is meaningful."""
        return self.watertight and self.consistent
