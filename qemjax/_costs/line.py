"""Plane-and-line quadrics (Liu, Rahimzadeh & Zordan, SGP 2025; CGAL 6.2's
``GarlandHeckbert_plane_and_line_policies``): ``method="line"``.

Each vertex's plane quadric (QEM's, `qem.initial_quadrics`) also holds the squared distance to the line
through the vertex along its normal n (area-weighted, unit):

    d²(x) = |(I − n nᵀ)(x − p)|²,   so, in the vertex's own frame (u = x − p):   A += w (I − n nᵀ),  b, c += 0.

The plane quadrics measure how far x leaves the surface; the line term adds a small price for sliding along
it, which keeps the placement near the vertices and regularises flat and nearly flat regions, where the
plane quadric alone is singular (CGAL: "improves the speed and the quality of the result"). The weight is
``line_weight`` times the trace of the vertex's plane quadric (the sum of its planes' weights, boundary and
feature planes included), so it is dimensionless, follows the mesh's resolution, and is larger across
discontinuities, where the boundary planes (``boundary_weight``) are. Everything else (placement, merge,
the kernels) is QEM's: the line term is part of the summed quadric, so ``line_weight`` changes the state
only and never recompiles.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._kernels.batching import DTYPE
from .base import MeshInput, require_nonnegative
from .qem import QEM


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n,3) float64 unit area-weighted vertex normals ((0,0,0) where the faces' normals cancel)."""
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.stack([np.bincount(F.T.reshape(-1), np.tile(cross[:, k], 3), minlength=len(V)) for k in range(3)], 1)
    length = np.linalg.norm(N, axis=1, keepdims=True)
    return np.where(length > 0, N / np.where(length > 0, length, 1.0), 0.0)


def line_quadrics(normals: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n,10) float64 quadrics w·|(I − n nᵀ)u|² in each vertex's frame: A packed (00, 01, 02, 11, 12, 22),
    then b (3) and c, both 0 (the line passes through the vertex)."""
    n, w = normals, weights
    out = np.zeros((len(n), 10))
    for col, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        out[:, col] = w * ((1.0 if i == j else 0.0) - n[:, i] * n[:, j])
    return out


@dataclasses.dataclass(frozen=True)
class LineQEM(QEM):
    """QEM whose vertex quadrics also hold the distance to each vertex's normal line (module docstring).

    line_weight: λ ≥ 0, the line term's weight relative to the vertex's plane weights (0: plane QEM).
    """

    name: ClassVar[str] = "line"
    memoryless_refused: ClassVar[str] = "method='line' sums its quadrics"

    line_weight: float = 0.001

    @property
    def error_measure(self) -> str:
        return "quadric error (a sum of squared distances to planes) plus λ·squared distances to normal lines"

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "line_weight")

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        Q = super().init_state(mesh).astype(np.float64)
        V, F = np.asarray(mesh.V, np.float64), np.asarray(mesh.F, np.int64)
        trace = Q[:, 0] + Q[:, 3] + Q[:, 5]  # the sum of the vertex's plane weights
        return (Q + line_quadrics(vertex_normals(V, F), self.line_weight * trace)).astype(DTYPE)

    def state_key(self):
        return self

