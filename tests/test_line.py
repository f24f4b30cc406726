"""method='line' (plane-and-line quadrics, `qemjax._costs.line`): float64 references and valid runs."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import qemjax
from qemjax import _costs, shapes
from qemjax._costs.base import MeshInput
from qemjax._costs.line import LineQEM, line_quadrics, vertex_normals


def quadric_at(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Q(u) for packed quadrics q (n,10) at offsets u (n,3) from each vertex (its frame)."""
    A = q[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    return np.einsum("ni,nij,nj->n", u, A, u) + 2 * np.einsum("ni,ni->n", q[:, 6:9], u) + q[:, 9]


def test_line_quadric_is_the_squared_distance_to_the_normal_line():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    w, u = rng.random(200), rng.normal(size=(200, 3))
    along = np.einsum("ni,ni->n", u, n)[:, None] * n  # the foot of u on the line through 0 along n
    want = w * np.sum((u - along) ** 2, 1)
    np.testing.assert_allclose(quadric_at(line_quadrics(n, w), u), want, rtol=1e-12, atol=1e-15)


def test_init_state_adds_the_weighted_line_term_to_the_planes():
    """The model's vertex quadric = QEM's plane quadric + line_weight · trace(plane A) · d²(line), float64
    reference at random points (state in float32: relative tolerance 1e-5)."""
    V, F = shapes.bumpy_sphere(2)
    V = (V - V.min(0)) / np.ptp(V, 0).max()
    mesh = MeshInput(V.astype(np.float32), F, (np.zeros((0, 2), np.int64), np.zeros(0, np.int64)), None)
    plane = _costs.QEM().init_state(mesh).astype(np.float64)
    line = LineQEM(line_weight=0.3).init_state(mesh).astype(np.float64)
    N = vertex_normals(V.astype(np.float64), F)
    u = np.random.default_rng(1).normal(size=(len(V), 3)) * 0.05
    tr = plane[:, 0] + plane[:, 3] + plane[:, 5]
    d2 = np.sum((u - np.einsum("ni,ni->n", u, N)[:, None] * N) ** 2, 1)
    want = quadric_at(plane, u) + 0.3 * tr * d2
    np.testing.assert_allclose(quadric_at(line, u), want, rtol=1e-5, atol=1e-9)
    zero = LineQEM(line_weight=0.0).init_state(mesh)
    assert np.array_equal(zero, _costs.QEM().init_state(mesh))  # weight 0: plane QEM exactly


@pytest.mark.parametrize("mesh", [shapes.bumpy_sphere(3), shapes.grid(12, hole=True)], ids=["sphere", "sheet"])
def test_line_runs_valid_exact_and_deterministic(mesh):
    a = qemjax.simplify(mesh, ratio=0.2, method="line")
    b = qemjax.simplify(mesh, ratio=0.2, method="line")
    assert a.stats["model"]["line_weight"] == LineQEM.line_weight
    assert len(a.faces) == a.stats["target_faces"] and a.stop_reason == "target"
    F = a.faces
    assert F.min() >= 0 and F.max() < len(a.vertices)
    assert np.all((F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2]))
    assert len(np.unique(np.sort(F, 1), axis=0)) == len(F)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    plane = qemjax.simplify(mesh, ratio=0.2)
    assert not np.array_equal(a.vertices, plane.vertices)  # the line term changes the result


def test_line_weight_is_a_state_value_not_a_kernel_constant(monkeypatch):
    """Another weight changes the result and compiles nothing new (the term lives in the summed quadric)."""
    mesh = shapes.bumpy_sphere(3)

    @dataclasses.dataclass(frozen=True)
    class Heavy(LineQEM):
        name = "line-heavy-test"
        line_weight: float = 0.05

    monkeypatch.setitem(_costs.REGISTRY, Heavy.name, Heavy)  # registered for this test only
    a = qemjax.simplify(mesh, ratio=0.2, method="line")
    b = qemjax.simplify(mesh, ratio=0.2, method=Heavy.name)
    assert b.stats["compilations"] == 0 and not np.array_equal(a.vertices, b.vertices)
    with pytest.raises(ValueError, match="line_weight"):
        LineQEM(line_weight=-1.0)
