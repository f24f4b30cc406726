"""method='probabilistic' (probabilistic plane quadrics, `qemjax._costs.probabilistic`): float64 and
Monte-Carlo references, QEM at σ = 0, valid and deterministic runs, no recompile for new σ, no fall-back."""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from conftest import assert_valid

import qemjax
from qemjax import _costs, shapes
from qemjax._mesh.arrays import face_stats
from qemjax._costs.base import MeshInput
from qemjax._costs.probabilistic import ProbabilisticQEM, plane_quadric


def quadric_at(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Q(u) for packed quadrics q (n,10) at points u (n,3) in each quadric's frame."""
    A = q[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    return np.einsum("ni,nij,nj->n", u, A, u) + 2 * np.einsum("ni,ni->n", q[:, 6:9], u) + q[:, 9]


def probabilistic(monkeypatch, sigma_normal: float, sigma_position: float) -> str:
    """A method name that runs ProbabilisticQEM with these σ (registered for the calling test only;
    `simplify` has no keyword for a model's fields)."""
    cls = dataclasses.make_dataclass(
        "P", [("sigma_normal", float, dataclasses.field(default=sigma_normal)),
              ("sigma_position", float, dataclasses.field(default=sigma_position))],
        bases=(ProbabilisticQEM,), frozen=True)
    cls.name = f"probabilistic-test-{sigma_normal:g}-{sigma_position:g}"
    monkeypatch.setitem(_costs.REGISTRY, cls.name, cls)
    return cls.name


def gauss_hermite_expectation(n, p, x, sn, sp):
    """E[(nᵀ(x − p))²] for n ~ N(n̄, sn² I), p ~ N(p̄, sp² I) by 3-point Gauss–Hermite cubature in the six
    noise variables: exact for this degree-4 polynomial (3 nodes integrate up to degree 5 per variable)."""
    t, w = np.polynomial.hermite_e.hermegauss(3)  # weight exp(-t²/2): standard-normal nodes
    w = w / w.sum()
    out = np.zeros(len(n))
    for idx in itertools.product(range(3), repeat=6):
        e = t[list(idx)]
        weight = np.prod(w[list(idx)])
        nn = n + sn[:, None] * e[:3]
        pp = p + sp[:, None] * e[3:]
        out += weight * np.einsum("ki,ki->k", nn, x - pp) ** 2
    return out


def random_planes(seed, k=300):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n, rng.normal(size=(k, 3)), rng.normal(size=(k, 3)), rng.random(k) * 0.5, rng.random(k) * 2.0


def test_closed_form_equals_the_exact_expectation():
    n, p, x, sn, sp = random_planes(0)
    want = gauss_hermite_expectation(n, p, x, sn, sp)
    got = quadric_at(plane_quadric(n, p, sn, sp), x)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # the uncertainty adds to the plain squared distance (σ = 0: the plane quadric)
    plain = quadric_at(plane_quadric(n, p, 0.0, 0.0), x)
    np.testing.assert_allclose(plain, np.einsum("ki,ki->k", n, x - p) ** 2, rtol=1e-12, atol=1e-12)
    assert np.all(got > plain)


def test_closed_form_equals_monte_carlo():
    """Sampled planes, 400 000 draws each: within 5 standard errors of the sample mean."""
    n, p, x, sn, sp = random_planes(1, k=8)
    rng = np.random.default_rng(2)
    got = quadric_at(plane_quadric(n, p, sn, sp), x)
    for k in range(len(n)):
        nn = n[k] + sn[k] * rng.normal(size=(400_000, 3))
        pp = p[k] + sp[k] * rng.normal(size=(400_000, 3))
        d2 = np.einsum("si,si->s", nn, x[k] - pp) ** 2
        assert abs(got[k] - d2.mean()) < 5 * d2.std() / np.sqrt(len(d2)), k


def closed_mesh_input():
    V, F = shapes.bumpy_sphere(2)
    V = (V - V.min(0)) / np.ptp(V, 0).max()
    none = (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    return V, F, MeshInput(V.astype(np.float32), F, none, None)


def test_init_state_sums_probabilistic_planes_of_the_faces():
    """Closed mesh (no boundary planes): each vertex's state equals Σ over its faces of the face's area weight
    times the expected squared distance to its plane through the vertex (float64 reference from the
    positions, not from QEM's state; the state is float32: rtol 1e-5)."""
    V, F, mesh = closed_mesh_input()
    sn, sp_rel = 0.2, 0.5
    state = ProbabilisticQEM(sigma_normal=sn, sigma_position=sp_rel).init_state(mesh).astype(np.float64)
    V32 = mesh.V.astype(np.float64)
    cross = np.cross(V32[F[:, 1]] - V32[F[:, 0]], V32[F[:, 2]] - V32[F[:, 0]])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / (2 * area[:, None])
    _, mean_area, mean_e2 = face_stats(mesh.V, F)
    sp = sp_rel * np.sqrt(mean_e2)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(len(V), 3)) * 0.05
    want = np.zeros(len(V))
    for j in range(3):  # corner j of every face: the plane through that vertex, in the vertex's frame
        q = plane_quadric(normal, np.zeros_like(normal), sn, sp) * (area / mean_area)[:, None]
        np.add.at(want, F[:, j], quadric_at(q, u[F[:, j]]))
    np.testing.assert_allclose(quadric_at(state, u), want, rtol=1e-5, atol=1e-9)


def test_zero_sigma_is_plane_qem_to_the_bit(monkeypatch):
    V, F, mesh = closed_mesh_input()
    assert np.array_equal(ProbabilisticQEM(sigma_normal=0.0, sigma_position=0.0).init_state(mesh),
                          _costs.QEM().init_state(mesh))
    m = shapes.grid(10, hole=True)
    a = qemjax.simplify(m, ratio=0.2, method=probabilistic(monkeypatch, 0.0, 0.0))
    b = qemjax.simplify(m, ratio=0.2, method="qem")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("make", [lambda: shapes.bumpy_sphere(3), lambda: shapes.grid(12, hole=True)],
                         ids=["sphere", "sheet"])
def test_probabilistic_runs_valid_exact_and_deterministic(make, scheduler):
    mesh = make()
    a = qemjax.simplify(mesh, ratio=0.2, method="probabilistic", scheduler=scheduler)
    b = qemjax.simplify(mesh, ratio=0.2, method="probabilistic", scheduler=scheduler)
    assert a.stats["model"]["sigma_normal"] == ProbabilisticQEM.sigma_normal
    assert a.stop_reason == "target"
    assert_valid(a, target=a.stats["target_faces"], V0=mesh.vertices, F0=mesh.faces)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    plane = qemjax.simplify(mesh, ratio=0.2, scheduler=scheduler)
    assert not np.array_equal(a.vertices, plane.vertices)  # the uncertainty changes the result


def test_new_sigma_changes_the_result_and_compiles_nothing(monkeypatch):
    mesh = shapes.bumpy_sphere(3)
    a = qemjax.simplify(mesh, ratio=0.2, method="probabilistic")
    b = qemjax.simplify(mesh, ratio=0.2, method=probabilistic(monkeypatch, 0.3, 0.0))
    c = qemjax.simplify(mesh, ratio=0.2, method=probabilistic(monkeypatch, 0.3, 0.7))
    assert b.stats["compilations"] == 0 and c.stats["compilations"] == 0
    assert not np.array_equal(a.vertices, b.vertices) and not np.array_equal(b.vertices, c.vertices)


def test_flat_patch_needs_no_fall_back(monkeypatch):
    """On a flat sheet every plane quadric is singular: QEM falls back to the segment or the endpoints; the
    uncertain normals make A positive definite, so every contraction takes the 3×3 solve."""
    mesh = shapes.grid(12, hole=True)
    plane = qemjax.simplify(mesh, ratio=0.1).stats["branches"]
    prob = qemjax.simplify(mesh, ratio=0.1, method="probabilistic").stats["branches"]
    assert plane["segment"] + plane["endpoint"] > 0
    assert prob["segment"] + prob["endpoint"] + prob["truncated"] == 0 and prob["solve"] > 0
    # σp alone does not regularise A: the fall-backs come back
    only_p = qemjax.simplify(mesh, ratio=0.1, method=probabilistic(monkeypatch, 0.0, 0.5)).stats["branches"]
    assert only_p["segment"] + only_p["endpoint"] > 0


@pytest.mark.parametrize("bad", [{"sigma_normal": -0.1}, {"sigma_position": float("nan")},
                                 {"sigma_normal": float("inf")}, {"memoryless": True}])
def test_bad_settings_raise_naming_them(bad):
    with pytest.raises(ValueError, match=next(iter(bad)) if "sigma" in next(iter(bad)) else "memoryless"):
        ProbabilisticQEM(**bad)
