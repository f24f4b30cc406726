"""End-to-end behaviour of `qemjax.simplify` on meshes generated in code."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import assert_valid, one_pair_per_round

import qemjax
from qemjax import shapes

SCHEDULERS = ["parallel", "greedy"]


@pytest.fixture(scope="module")
def sphere():
    return shapes.icosphere(3)  # 1280 faces


@pytest.fixture(scope="module")
def bumpy():
    return shapes.bumpy_sphere(4)  # 5120 faces


@pytest.mark.parametrize("scheduler", SCHEDULERS)
@pytest.mark.parametrize("make,target", [
    (lambda: shapes.bumpy_sphere(4), 500),
    (lambda: shapes.torus(), 300),
    (lambda: shapes.cube(2), 40),
    (lambda: shapes.grid(16, hole=True), 150),
])
def test_output_is_valid_with_exact_count(make, target, scheduler):
    V, F = make()
    r = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler)
    assert_valid(r, target, V, F)
    assert r.stats["faces_out"] == target and r.stats["contractions"] > 0


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_sphere_stays_a_sphere(sphere, scheduler):
    V, F = sphere
    r = qemjax.simplify((V, F), ratio=0.1, scheduler=scheduler)
    radius = np.linalg.norm(r.vertices, axis=1)
    assert np.all(np.abs(radius - 1) < 0.05)
    assert r.stats["branches"]["solve"] > 0.8 * r.stats["contractions"]


def test_parallel_quality_close_to_greedy(bumpy):
    """Same target: the parallel scheduler's quadric error stays within a small factor of greedy's."""
    V, F = bumpy
    err = {}
    for s in SCHEDULERS:
        r = qemjax.simplify((V, F), target_faces=400, scheduler=s)
        err[s] = float(np.mean(r.vertex_error))
    assert err["parallel"] < 1.5 * err["greedy"]


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_boundary_is_preserved_on_open_grid(scheduler):
    """A flat square's outline stays on the square's border: boundary vertices keep x or y at 0 or 1."""
    V, F = shapes.grid(20)
    r = qemjax.simplify((V, F), target_faces=60, scheduler=scheduler)
    assert_valid(r, 60, V, F)
    from qemjax._mesh import topology as topo

    be, _ = topo.boundary_edges(r.faces, len(r.vertices))
    bv = r.vertices[np.unique(be)]
    dist = np.min(np.abs(np.c_[bv[:, :2], 1 - bv[:, :2]]), axis=1)
    assert dist.max() < 1e-4
    # the four corners survive
    for c in ([0, 0], [0, 1], [1, 0], [1, 1]):
        assert np.min(np.linalg.norm(r.vertices[:, :2] - c, axis=1)) < 1e-4
    assert np.all(np.abs(r.vertices[:, 2]) < 1e-6)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_deterministic(bumpy, scheduler):
    a = qemjax.simplify(bumpy, target_faces=700, scheduler=scheduler)
    b = qemjax.simplify(bumpy, target_faces=700, scheduler=scheduler)
    assert np.array_equal(a.faces, b.faces) and np.array_equal(a.vertices, b.vertices)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_genus_preserved_in_manifold_mode(scheduler):
    V, F = shapes.torus()
    r = qemjax.simplify((V, F), target_faces=100, scheduler=scheduler)
    from qemjax._mesh import topology as topo

    E, cnt = topo.edges(r.faces, len(r.vertices))
    assert np.all(cnt == 2)
    assert len(r.vertices) - len(E) + len(r.faces) == 0  # Euler characteristic of a torus


def test_max_error_stops_before_exceeding():
    V, F = shapes.bumpy_sphere(4)
    full = qemjax.simplify((V, F), target_faces=100)
    limit = full.max_error / 20
    r = qemjax.simplify((V, F), max_error=limit)
    assert r.max_error <= limit
    assert 100 < len(r.faces) < len(F)
    assert np.all(r.history.costs <= limit)


def test_units_follow_the_input_scale(bumpy):
    """Scaling the mesh by s scales errors by s² and positions by s; topology is unchanged."""
    V, F = bumpy
    a = qemjax.simplify((V, F), target_faces=300)
    b = qemjax.simplify((V * 10.0, F), target_faces=300)
    assert np.array_equal(a.faces, b.faces)
    np.testing.assert_allclose(b.vertices, a.vertices * 10.0, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.max_error, a.max_error * 100.0, rtol=1e-4)


def test_endpoints_placement_uses_existing_points_or_midpoints():
    V, F = shapes.bumpy_sphere(3)
    r = qemjax.simplify((V, F), target_faces=200, placement="endpoints")
    assert r.stats["branches"]["solve"] == r.stats["branches"]["segment"] == r.stats["branches"]["truncated"] == 0
    assert_valid(r, 200, V, F)


def test_rank_placement_truncates_on_a_flat_grid_without_recompiling():
    """On a flat grid the quadrics are rank 1 inside and rank 2 along the border: placement='rank' takes
    the truncated solve and keeps the result flat and valid. The mode is its own kernel (compiled once);
    a new rank_eps is an array and compiles nothing."""
    V, F = shapes.grid(20)
    base = qemjax.simplify((V, F), target_faces=60)
    r = qemjax.simplify((V, F), target_faces=60, placement="rank")
    assert_valid(r, 60, V, F)
    assert r.stats["branches"]["truncated"] > 0 and base.stats["branches"]["truncated"] == 0
    assert np.all(np.abs(r.vertices[:, 2]) < 1e-6)
    from qemjax._kernels import compilation as _compilation
    from qemjax._costs.qem import QEM

    VS, pairs = np.zeros((64, 13), np.float32), np.zeros((256, 2), np.int32)
    QEM(placement="rank").price(VS, pairs, QEM(placement="rank").kernel_params())
    c0, _ = _compilation.snapshot()
    QEM(placement="rank", rank_eps=1e-2).price(VS, pairs, QEM(placement="rank", rank_eps=1e-2).kernel_params())
    assert _compilation.snapshot()[0] == c0


def test_history_and_result_fields(bumpy):
    V, F = bumpy
    r = qemjax.simplify(bumpy, target_faces=1000, quality_threshold=0.0)  # (the shape term: shaped-key order)
    k = r.stats["contractions"]
    assert len(r.history) == k == len(V) - len(r.vertices)
    assert r.history.positions.shape == (k, 3) and r.history.pairs.shape == (k, 2)
    # a round's contractions are recorded in cost order (a closed mesh: two faces per contraction)
    first = (len(F) - r.stats["faces_per_round"][0]) // 2
    assert first > 10 and np.all(np.diff(r.history.costs[:first]) >= 0)
    assert r.vertex_error.shape == (len(r.vertices),) and np.all(r.vertex_error >= 0)
    assert r.max_error == pytest.approx(r.history.costs.max())
    assert r.source_vertices.shape == (len(r.vertices),)
    tm = r.to_trimesh()
    assert len(tm.faces) == 1000
    assert set(["compile_s", "run_s", "total_s", "rounds", "compilations"]) <= set(r.stats)


def test_compilations_do_not_grow_with_rounds():
    """After a warm-up at the same targets, other meshes of similar size compile nothing new, however many
    rounds they take. (The warm-up takes the targets: the default's memoryless last stretch starts at twice
    the target, so its arrays' buckets follow the target; alone, one warm-up at another target compiled the
    buckets of the others.)"""
    for target in (2000, 60, 300):
        qemjax.simplify(shapes.bumpy_sphere(4), target_faces=target)
    for mesh, target in [(shapes.bumpy_sphere(4, seed=3), 2000), (shapes.bumpy_sphere(4, seed=5), 60),
                         (shapes.icosphere(4), 300)]:
        r = qemjax.simplify(mesh, target_faces=target)
        assert r.stats["rounds"] > 3
        assert r.stats["compilations"] == 0, r.stats


def test_target_larger_than_mesh_warns_and_returns_unchanged(sphere):
    V, F = sphere
    with pytest.warns(UserWarning, match="not below"):
        r = qemjax.simplify((V, F), target_faces=len(F) + 10)
    assert len(r.faces) == len(F)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = qemjax.simplify((V, F), ratio=1.0)
    assert len(r.faces) == len(F)


@pytest.mark.parametrize("kwargs,match", [
    (dict(target_faces=0), "at least 1"),
    (dict(target_faces=-5), "at least 1"),
    (dict(target_faces=2.5), "integer"),
    (dict(ratio=0.0), "ratio"),
    (dict(ratio=float("nan")), "ratio"),
    (dict(), "give a target"),
    (dict(target_faces=10, ratio=0.5), "at most one"),
    (dict(max_error=-1.0), "max_error"),
    (dict(target_faces=10, method="nope"), "unknown method"),
    (dict(target_faces=10, scheduler="nope"), "unknown scheduler"),
    (dict(target_faces=10, placement="nope"), "unknown placement"),
    (dict(target_faces=10, boundary_weight=-1.0), "boundary_weight"),
    (dict(target_faces=10, flip_angle=0.0), "flip_angle"),
])
def test_bad_options(sphere, kwargs, match):
    with pytest.raises(ValueError, match=match):
        qemjax.simplify(sphere, **kwargs)


@pytest.mark.parametrize("mesh,match", [
    ((np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]])), "NaN or inf"),
    ((np.array([[0.0, 0, 0], [1, 0, 0], [np.inf, 1, 0]]), np.array([[0, 1, 2]])), "NaN or inf"),
    ((np.eye(3), np.array([[0, 1, 3]])), "out of range"),
    ((np.eye(3), np.array([[0, -1, 2]])), "out of range"),
    ((np.zeros((3, 2)), np.array([[0, 1, 2]])), r"shape \(n, 3\)"),
    ((np.eye(3), np.array([0, 1, 2])), r"shape \(m, 3\)"),
    ((np.zeros((0, 3)), np.zeros((0, 3), int)), "empty mesh"),
    ((np.eye(3), np.zeros((0, 3), int)), "empty mesh"),
    ((np.eye(3), np.array([[0, 0, 1]])), "degenerate"),
    ((np.eye(3), np.array([[0.5, 1, 2]])), "integers"),
    ("/nonexistent/mesh.obj", "not found"),
    (42, "mesh must be"),
])
def test_bad_input(mesh, match):
    with pytest.raises(ValueError, match=match):
        qemjax.simplify(mesh, target_faces=1)


def test_feature_edges_are_kept_like_boundaries():
    """A line of feature edges across a flat grid survives: no output face straddles it, while the same
    simplification without features does cross it."""
    V, F = shapes.grid(16)
    on_line = np.isclose(V[:, 0], 0.5)
    from qemjax._mesh import topology as topo

    E, _ = topo.edges(F, len(V))
    feat = E[on_line[E[:, 0]] & on_line[E[:, 1]]]
    assert len(feat) == 16

    def straddling(r):
        x = r.vertices[r.faces][..., 0]
        return int(np.sum((x.min(1) < 0.5 - 1e-6) & (x.max(1) > 0.5 + 1e-6)))

    with_f = qemjax.simplify((V, F), target_faces=60, feature_edges=feat)
    without = qemjax.simplify((V, F), target_faces=60)
    assert_valid(with_f, 60, V, F)
    assert straddling(with_f) == 0 and straddling(without) > 0
    with pytest.raises(ValueError, match="not mesh edges"):
        qemjax.simplify((V, F), target_faces=60, feature_edges=np.array([[0, 100]]))


@pytest.mark.parametrize("seed", [0, 4])
def test_parallel_with_one_pair_per_round_is_greedy(seed):
    """Without cost ties (random bumps), the parallel scheduler gated to one pair per round makes the same
    contractions in the same order as the greedy queue: the two share their rules exactly."""
    mesh = shapes.bumpy_sphere(2, seed=seed)
    g = qemjax.simplify(mesh, target_faces=60, scheduler="greedy")
    p = qemjax.simplify(mesh, target_faces=60, schedule=one_pair_per_round(), quality_threshold=0.0)
    assert p.stats["rounds"] == len(p.history.pairs) == len(g.history.pairs)
    assert np.array_equal(np.sort(p.history.pairs, 1), np.sort(g.history.pairs, 1))
    np.testing.assert_allclose(p.history.costs, g.history.costs, rtol=1e-5, atol=1e-12)
