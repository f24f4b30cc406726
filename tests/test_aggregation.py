"""Pair contraction beyond edges (aggregation), non-manifold input and manifold mode."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh
from conftest import assert_valid, shared_mesh

import qemjax
from qemjax import shapes
from qemjax._mesh import topology as topo

SCHEDULERS = ["parallel", "greedy"]


def boxes(centers, size=1.0):
    b = trimesh.creation.box(extents=(size,) * 3)
    V = np.concatenate([b.vertices + c for c in centers])
    F = np.concatenate([b.faces + 8 * i for i in range(len(centers))])
    return V, F.astype(np.int64)


def components(F, n):
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    E, _ = topo.edges(F, n)
    used = np.unique(F)
    g = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    return len(np.unique(lab[used]))


def test_close_pairs_match_brute_force():
    rng = np.random.default_rng(1)
    V, F = shapes.icosphere(2)
    V = V + rng.normal(scale=0.05, size=V.shape)
    t = 0.5
    got = topo.close_pairs(V, F, t)
    E, _ = topo.edges(F, len(V))
    edges = set(map(tuple, E.tolist()))
    ref = {(i, j) for i, j in itertools.combinations(range(len(V)), 2)
           if np.linalg.norm(V[i] - V[j]) <= t and (i, j) not in edges}
    assert set(map(tuple, got.tolist())) == ref and len(ref) > 0
    assert len(topo.close_pairs(V, F, 0.0)) == 0


def test_threshold_that_would_explode_is_refused():
    V, F = shapes.icosphere(3)
    with pytest.raises(ValueError, match="smaller threshold"):
        qemjax.simplify((V, F), target_faces=100, pair_threshold=10.0)
    with pytest.raises(ValueError, match="pair_threshold"):
        qemjax.simplify((V, F), target_faces=100, pair_threshold=-1.0)
    with pytest.raises(ValueError, match="preserve_topology=False"):
        qemjax.simplify((V, F), target_faces=100, pair_threshold=0.1, preserve_topology=True)


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_separate_parts_join_only_with_threshold(scheduler):
    """Three boxes in a row, 0.2 apart: with t = 0.3 they end as one piece (the middle box's pairs are
    inherited as its vertices merge), with t = 0 they stay apart."""
    V, F = boxes([[0, 0, 0], [1.2, 0, 0], [2.4, 0, 0]])
    joined = qemjax.simplify((V, F), target_faces=12, pair_threshold=0.3, scheduler=scheduler)
    assert joined.stats["close_pairs"] > 0
    assert components(joined.faces, len(joined.vertices)) == 1
    assert_valid(joined, None, V, F)
    apart = qemjax.simplify((V, F), target_faces=24, pair_threshold=0.0, preserve_topology=False,
                            scheduler=scheduler)
    assert components(apart.faces, len(apart.vertices)) >= 2


@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_parts_vanish_without_threshold_in_non_manifold_mode(scheduler):
    V, F = boxes([[2.0 * i, 0, 0] for i in range(6)])
    r = qemjax.simplify((V, F), target_faces=8, preserve_topology=False, scheduler=scheduler)
    assert_valid(r, None, V, F)
    assert len(r.faces) <= 10 and components(r.faces, len(r.vertices)) < 6


def fins():
    """Three triangles sharing one edge (a non-manifold edge), on a grid so there is something to do."""
    V, F = shapes.grid(6)
    n = len(V)
    e = F[0, :2]
    extra_v = np.array([[0.1, 0.1, 0.5], [0.1, 0.1, -0.5]])
    F2 = np.concatenate([F, [[e[0], e[1], n], [e[1], e[0], n + 1]]])
    return np.concatenate([V, extra_v]), F2


def bowtie():
    """Two grids touching at one corner vertex."""
    V1, F1 = shapes.grid(5)
    V2, F2 = shapes.grid(5)
    V2 = V2 + [1.0, 1.0, 0.0]
    # vertex (0,0) of the second grid coincides with (1,1) of the first; welding joins them
    return np.concatenate([V1, V2]), np.concatenate([F1, F2 + len(V1)])


def mixed_orientation():
    V, F = shapes.bumpy_sphere(3)
    F = F.copy()
    F[::7] = F[::7, ::-1]
    return V, F


@pytest.mark.parametrize("make", [pytest.param(fins, marks=pytest.mark.slow), bowtie, mixed_orientation])
@pytest.mark.parametrize("scheduler", SCHEDULERS)
@pytest.mark.parametrize("manifold", [True, False])
def test_non_manifold_input_is_simplified(make, scheduler, manifold):
    V, F = make()
    target = len(F) // 3
    r = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, preserve_topology=manifold)
    assert r.stats["contractions"] > 0
    assert_valid(r, None, r.input_vertices, r.input_faces)
    assert len(r.faces) <= target + 2


@pytest.mark.slow  # real meshes
@pytest.mark.parametrize("name,genus", [("3holes.off", 3), ("fertility.off", 4)])
@pytest.mark.parametrize("scheduler", SCHEDULERS)
def test_genus_survives_in_manifold_mode(name, genus, scheduler):
    p = shared_mesh(name)
    r = qemjax.simplify(p, ratio=0.05, scheduler=scheduler)
    E, cnt = topo.edges(r.faces, len(r.vertices))
    assert np.all(cnt == 2), "output must stay closed and manifold"
    chi = len(r.vertices) - len(E) + len(r.faces)
    assert chi == 2 - 2 * genus
    assert components(r.faces, len(r.vertices)) == 1
    assert_valid(r, r.stats["target_faces"], r.input_vertices, r.input_faces)
