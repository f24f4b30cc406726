"""Probabilistic plane quadrics (Trettner & Kobbelt, "Fast and Robust QEF Minimization using Probabilistic
Quadrics", Eurographics 2020; CGAL's ``GarlandHeckbert_probabilistic_plane_policies``):
``method="probabilistic"``.

Each plane (point p, unit normal n) is uncertain: p ~ N(p̄, σp² I) and n ~ N(n̄, σn² I), independent. The
quadric is the *expected* squared distance, which is again a quadric, in closed form. With d = x − p and
first the expectation over n (E[n nᵀ] = n̄ n̄ᵀ + σn² I =: M), then over p (E[d dᵀ] = (x − p̄)(x − p̄)ᵀ + σp² I):

    E[(nᵀ(x − p))²] = (x − p̄)ᵀ M (x − p̄) + σp² tr M
                    = (x − p̄)ᵀ (n̄ n̄ᵀ + σn² I)(x − p̄) + σp² (|n̄|² + 3σn²).

In each vertex's frame (u = x − v, every face plane of QEM passes through its corner v, so p̄ = v):
A = n̄ n̄ᵀ + σn² I, b = 0, c = σp² (1 + 3σn²). A weighted sum of such planes (QEM's face planes with their
area weights, and its boundary and feature planes) is therefore QEM's plane quadric A₀ plus W·σn² I on the
diagonal and W·σp²(1 + 3σn²) in c, where W = tr A₀ is the sum of the planes' weights (each unit normal adds
1 to the trace). So `init_state` takes QEM's summed quadric and adds those two terms; placement, merge and
the kernels stay QEM's, and σ are state values: new ones never recompile.

σn > 0 makes every A positive definite (an isotropic pull towards the vertices, of relative strength σn²),
so the 3×3 solve is always well posed and QEM's fall-backs (segment, endpoints) are not needed. σp adds a
constant per unit of plane weight: merging vertices that carry much surface costs more (an expected
distance, not zero, even on a plane), which orders flat regions by the area they already represent.

Units: ``sigma_normal`` is dimensionless (a normal is a unit vector); ``sigma_position`` is a fraction of
the mesh's root-mean-square edge length (``MeshInput.means``), so both follow the mesh's resolution, as the
boundary planes' weights do. The cost and ``vertex_error`` are expected squared distances (mesh units²).
Degenerate faces (zero normal) add nothing, as in QEM (with ``area_weighted=False`` their weight is not in W).
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._mesh.arrays import face_stats
from .._kernels.batching import DTYPE
from .base import MeshInput, require_nonnegative
from .qem import QEM


def plane_quadric(normal: np.ndarray, point: np.ndarray, sigma_normal, sigma_position) -> np.ndarray:
    """(k,10) float64 probabilistic plane quadrics in the world frame (x = u, frame origin 0):
    E[(nᵀ(x − p))²] = xᵀAx + 2bᵀx + c with A = n̄n̄ᵀ + σn²I, b = −A p̄, c = p̄ᵀAp̄ + σp²(|n̄|² + 3σn²).

    normal (k,3), point (k,3) float64: n̄ and p̄ (n̄ need not be unit); sigma_normal, sigma_position: σn, σp
    (scalars or (k,)). Packed as `qemjax._kernels.quadrics`: A (00, 01, 02, 11, 12, 22), b (3), c."""
    n, p = np.asarray(normal, np.float64), np.asarray(point, np.float64)
    sn2 = np.broadcast_to(np.asarray(sigma_normal, np.float64) ** 2, (len(n),))
    sp2 = np.broadcast_to(np.asarray(sigma_position, np.float64) ** 2, (len(n),))
    A = n[:, :, None] * n[:, None, :] + sn2[:, None, None] * np.eye(3)
    Ap = np.einsum("kij,kj->ki", A, p)
    c = np.einsum("ki,ki->k", p, Ap) + sp2 * (np.einsum("ki,ki->k", n, n) + 3.0 * sn2)
    idx = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    return np.concatenate([np.stack([A[:, i, j] for i, j in idx], 1), -Ap, c[:, None]], 1)


def add_uncertainty(Q: np.ndarray, sigma_normal: float, sigma_position: float) -> np.ndarray:
    """(n,10) float64: summed plane quadrics Q (n,10), every plane through its vertex (b = c = 0), made
    probabilistic: A += W σn² I, c += W σp² (1 + 3σn²), W = tr A (the planes' total weight). σp in the
    units of Q's frame."""
    Q = np.array(Q, np.float64)
    W = Q[:, 0] + Q[:, 3] + Q[:, 5]
    sn2 = float(sigma_normal) ** 2
    for col in (0, 3, 5):
        Q[:, col] += W * sn2
    Q[:, 9] += W * float(sigma_position) ** 2 * (1.0 + 3.0 * sn2)
    return Q


@dataclasses.dataclass(frozen=True)
class ProbabilisticQEM(QEM):
    """QEM whose planes carry Gaussian uncertainty: the cost is the expected squared distance (module
    docstring).

    sigma_normal: σn ≥ 0, the standard deviation of each plane's normal components (dimensionless).
    sigma_position: σp ≥ 0, the standard deviation of each plane's point, as a fraction of the mesh's
        root-mean-square edge length. Both 0: plane QEM exactly.
    """

    name: ClassVar[str] = "probabilistic"
    memoryless_refused: ClassVar[str] = "method='probabilistic' sums its quadrics"

    sigma_normal: float = 0.1
    sigma_position: float = 0.0

    @property
    def error_measure(self) -> str:
        return "expected squared distance to uncertain planes"

    def __post_init__(self):
        super().__post_init__()
        require_nonnegative(self, "sigma_normal", "sigma_position")

    def init_state(self, mesh: MeshInput) -> np.ndarray:
        Q = super().init_state(mesh)
        if self.sigma_normal == 0 and self.sigma_position == 0:
            return Q  # plane QEM, to the bit
        mean_e2 = (face_stats(mesh.V, mesh.F) if mesh.means is None else (None, *mesh.means))[2]
        sigma_p = self.sigma_position * float(np.sqrt(mean_e2))
        return add_uncertainty(Q, self.sigma_normal, sigma_p).astype(DTYPE)

    def state_key(self):
        return self
