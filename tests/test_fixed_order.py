"""The compiled, fixed-order kernels of the default's re-fit and measured distance, against float64
references on random inputs: the sparse solver (`_mesh.spd_solve`) against scipy's direct solver, the grid
nearest-triangle search (`_mesh.grid_nearest`) against the KD-tree search and brute force, and the numpy
helpers (`_mesh.fixed_order`) against numpy."""
from __future__ import annotations

import math
import threading

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from qemjax._mesh import fixed_order as fo
from qemjax._mesh.grid_nearest import nearest
from qemjax._mesh.nearest import Triangles
from qemjax._mesh.spd_solve import _diagonal, solve_csr, solve_spd
from test_metrics import _all_pairs_min


@pytest.mark.parametrize("seed", range(4))
def test_spd_solve_matches_a_direct_solve(seed):
    rng = np.random.default_rng(seed)
    n = 200
    A = sp.random(400, n, density=0.02, random_state=seed, format="csr")
    N = (A.T @ A + 1e-2 * sp.identity(n)).tocsr()
    B = rng.normal(size=(n, 3))
    X, ok = solve_spd(N, B, np.zeros((n, 3)), rtol=1e-13)
    want = np.stack([spla.spsolve(N.tocsc(), B[:, i]) for i in range(3)], 1)
    assert ok and np.allclose(X, want, rtol=1e-9, atol=1e-9)
    X2, _ = solve_spd(N, B, want + 1e-3, rtol=1e-13)  # from another start: the same solution
    assert np.allclose(X2, want, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_solve_csr_is_solve_spd_on_the_arrays(seed):
    """The re-fit's call on CSR arrays gives `solve_spd`'s bits, and its diagonal is scipy's (rows with no
    diagonal entry, explicit zeros kept)."""
    rng = np.random.default_rng(seed)
    n = 150
    A = sp.random(300, n, density=0.03, random_state=seed, format="csr")
    N = (A.T @ A + 1e-2 * sp.identity(n)).tocsr()
    N.sort_indices()
    B, X0 = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    X1, ok1 = solve_spd(N, B, X0, rtol=1e-12)
    X2, ok2 = solve_csr(N.indptr.astype(np.int64), N.indices.astype(np.int64), N.data, B, X0, rtol=1e-12)
    assert ok1 == ok2 and np.array_equal(X1.view(np.int64), X2.view(np.int64))
    M = sp.random(40, 40, density=0.2, random_state=seed, format="csr")
    M.data[::3] = 0.0
    M.sort_indices()
    assert np.array_equal(_diagonal(M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data), M.diagonal())
    D = sp.csr_matrix((np.array([2.0, -1.0]), np.array([0, 0]), np.array([0, 2])), shape=(1, 1))  # a duplicate
    X, ok = solve_spd(D, np.ones((1, 1)), np.zeros((1, 1)))  # summed, as scipy's diagonal sums it: N = [1]
    assert ok and X[0, 0] == 1.0
    with pytest.raises(ValueError, match="not positive"):
        solve_csr(np.array([0, 1, 1]), np.array([0]), np.array([1.0]), np.ones((2, 1)), np.zeros((2, 1)))


def test_spd_solve_reports_what_it_did_not_reach():
    n = 300  # a path graph's Laplacian, shifted: definite, far from diagonal
    N = sp.diags([-np.ones(n - 1), 2.001 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    _, ok = solve_spd(N, np.ones((n, 1)), np.zeros((n, 1)), rtol=1e-14, max_iter=3)
    assert not ok
    X, ok = solve_spd(N, np.ones((n, 1)), np.zeros((n, 1)), rtol=1e-12)
    assert ok and np.allclose(N @ X, 1.0, atol=1e-9)
    with pytest.raises(ValueError, match="not positive"):
        solve_spd(sp.identity(3, format="csr") * -1.0, np.ones((3, 1)), np.zeros((3, 1)))


def _brute(X, G, P):
    """Exact nearest distances by testing every triangle (the KD-tree search's kernel, all pairs: what
    `nearest_triangles` gives, tests/test_metrics.py)."""
    return np.sqrt(_all_pairs_min(Triangles(np.ascontiguousarray(np.transpose(X[G], (1, 2, 0)))), P))


def _to_named(X, G, P, f):
    """Each point's distance to the triangle ``f`` names for it (the same kernel)."""
    tris = Triangles(np.ascontiguousarray(np.transpose(X[G], (1, 2, 0))))
    return np.sqrt(tris.sq_dist(np.ascontiguousarray(P.T), np.asarray(f, np.int64)))


@pytest.mark.parametrize("shape", ["cloud", "flat", "degenerate", "far", "one"])
def test_grid_nearest_is_exact(shape):
    rng = np.random.default_rng(3)
    X = rng.normal(size=(120, 3))
    if shape == "flat":
        X[:, 2] *= 1e-9
    G = np.array([rng.choice(len(X), 3, replace=False) for _ in range(200 if shape != "one" else 1)])
    if shape == "degenerate":
        G[:40, 2] = G[:40, 1]  # segments
        X[G[40:60, 2]] = X[G[40:60, 1]]  # coincident corners
        G[60:80, 1] = G[60:80, 0]  # segments whose first two corners are one
        X[G[80:100, 1]] = X[G[80:100, 0]]  # ... or at one point
    P = rng.normal(size=(300, 3)) * (50.0 if shape == "far" else 2.0)
    f, d = nearest(X, G, P)
    want = _brute(X, G, P)
    assert np.allclose(d, want, rtol=1e-12, atol=1e-14)
    # the face it names lies at that distance
    assert np.allclose(_to_named(X, G, P, f), d, rtol=1e-12, atol=1e-14)


def test_grid_nearest_is_exact_on_slivers_and_segments():
    """Triangles whose corners are collinear or coincide (in any of their three positions): the distance
    to the set of points they are, as the float64 reference measures it (Ericson's regions alone do not)."""
    rng = np.random.default_rng(11)
    a, b = rng.normal(size=(2, 300, 3))
    c = rng.normal(size=(300, 3))
    c[:50] = a[:50] + 0.3 * (b[:50] - a[:50])  # collinear, the third corner between
    c[50:100] = a[50:100] + 1.7 * (b[50:100] - a[50:100])  # ... or beyond
    b[100:130] = a[100:130]  # two corners at one point
    c[130:160] = a[130:160]
    c[160:190] = b[160:190]
    X = np.concatenate([a, b, c])
    G = np.arange(900).reshape(3, 300).T
    for rows in (slice(0, 190), slice(0, 300)):  # the degenerate ones alone, then among ordinary ones
        P = rng.normal(size=(2000, 3)) * 1.5
        f, d = nearest(X, G[rows], P)
        assert np.allclose(d, _brute(X, G[rows], P), rtol=1e-12, atol=1e-12)
        assert np.allclose(_to_named(X, G[rows], P, f), d, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n,block", [(2, None), (4, None), (2, 700)])
def test_grid_nearest_threads_and_blocks_give_the_same_bits(monkeypatch, n, block):
    """One block on this thread against: a block per thread, the calling thread taking the first (2 and 4
    threads), and more blocks than threads on the pool (8 blocks of 700)."""
    from qemjax._mesh import grid_nearest, threads

    rng = np.random.default_rng(5)
    X, G = rng.normal(size=(500, 3)), rng.integers(0, 500, size=(800, 3))
    P = rng.normal(size=(5000, 3))
    monkeypatch.setattr(threads, "count", lambda: 1)
    f1, d1 = nearest(X, G, P)
    calls = []
    query = grid_nearest._query
    monkeypatch.setattr(grid_nearest, "_query", lambda *a: calls.append(threading.get_ident()) or query(*a))
    monkeypatch.setattr(threads, "count", lambda: n)
    monkeypatch.setattr(grid_nearest, "MIN_BLOCK", 1000)
    if block:
        monkeypatch.setattr(grid_nearest, "BLOCK", block)
    f2, d2 = nearest(X, G, P)
    assert np.array_equal(f1, f2) and np.array_equal(d1, d2)
    assert len(calls) == (n if block is None else 8)
    # a block a thread: this thread queries the first one itself
    assert (threading.get_ident() in calls) == (block is None)


@pytest.mark.parametrize("where", ["random", "none", "near", "threads"])
def test_grid_nearest_seeds_change_no_answer(where, monkeypatch):
    """Seeded searches (a face near each point, as the measured distance takes the re-fit's) give the same
    faces and bits as unseeded ones: with ties (points and corners on a coarse grid, repeated triangles,
    the lower index among equals), with seeds far off, missing (-1), or right."""
    from qemjax._mesh import grid_nearest

    rng = np.random.default_rng(len(where))
    X = rng.integers(-4, 5, size=(300, 3)).astype(np.float64) * 0.25  # many ties on a lattice
    G = rng.integers(0, 300, size=(600, 3))
    G[300:360] = G[:60]  # repeated triangles: equal distances, different indices
    G[360:380, 2] = G[360:380, 1]  # segments
    P = rng.integers(-5, 6, size=(4000, 3)).astype(np.float64) * 0.25
    P[::3] += rng.normal(0, 0.05, size=P[::3].shape)
    f0, d0 = nearest(X, G, P)
    if where == "random":
        seed = rng.integers(-1, len(G), len(P))
    elif where == "none":
        seed = np.full(len(P), -1)
    elif where == "near":  # the answers themselves, or the repeated triangle's twin
        seed = np.where(f0 < 60, f0 + 300, f0)
    else:  # blocks on threads, each with its own seeds
        monkeypatch.setattr(grid_nearest, "BLOCK", 700)
        seed = rng.integers(0, len(G), len(P))
    f1, d1 = nearest(X, G, P, seed)
    assert np.array_equal(f1, f0) and np.array_equal(d1, d0)
    with pytest.raises(ValueError, match="seeds for"):
        nearest(X, G, P, seed[:-1])
    with pytest.raises(ValueError, match="past the last"):
        nearest(X, G, P, np.full(len(P), len(G)))
    bad = G.copy()
    bad[5, 1] = len(X)
    with pytest.raises(ValueError, match="not one of the vertices"):
        nearest(X, bad, P)


def test_fixed_order_helpers_match_numpy():
    rng = np.random.default_rng(0)
    M, R = rng.normal(size=(50, 4, 4)), rng.normal(size=(50, 4, 2))
    X, det = fo.solve(M, R)
    assert np.allclose(X, np.linalg.solve(M, R), rtol=1e-9, atol=1e-9)
    assert np.allclose(det, np.linalg.det(M), rtol=1e-9)
    A = rng.normal(size=(7, 3, 3))
    assert np.allclose(fo.dot(A, A), np.einsum("...i,...i", A, A), rtol=1e-14)
    parts, w = rng.normal(size=(9, 3)), [0.5, 2.0, -1.0]
    assert np.array_equal(fo.weighted_sum(parts, w), parts[:, 0] * 0.5 + parts[:, 1] * 2.0 + parts[:, 2] * -1.0)
    v = rng.uniform(0.1, 3.0, size=20)
    assert fo.exp(v).tolist() == [math.exp(t) for t in v]
    assert fo.power(v, 0.6).tolist() == [math.pow(t, 0.6) for t in v]
    assert fo.arctan2(v, v[::-1]).shape == v.shape


@pytest.mark.parametrize("seed", range(3))
def test_grid_nearest_slivers_are_pointtris_flat_triangles(seed):
    """`grid_nearest.slivers` (per face, compiled) against `pointtri.flat_triangles` (whole arrays): the same
    flags, on random faces with repeated corners, collinear corners and corners a hair off a line."""
    from qemjax._mesh.grid_nearest import slivers
    from qemjax._mesh.pointtri import flat_triangles

    rng = np.random.default_rng(seed)
    X = rng.normal(size=(300, 3)) * 10.0 ** rng.uniform(-5, 5)
    X[:50] = X[50:100] + 0.25 * (X[100:150] - X[50:100])  # on the segment between two others
    X[150:200] = X[:50] + 10.0 ** rng.uniform(-12, -4, (50, 1)) * rng.normal(size=(50, 3)) * np.abs(X).max()
    G = rng.integers(0, 300, size=(4000, 3))
    G[:100] = np.stack([np.arange(50, 100), np.arange(100, 150), np.arange(50)], 1).repeat(2, 0)
    G[100:150] = np.stack([np.arange(50, 100), np.arange(100, 150), np.arange(150, 200)], 1)
    T = X[G]
    want = flat_triangles((T[:, 1] - T[:, 0]).T, (T[:, 2] - T[:, 0]).T)
    got = slivers(X, G)
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < len(G)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_bounds_are_numpys_min_and_max(dtype):
    """`box_bounds` against numpy's V.min(0)/V.max(0), X[np.unique(G)]'s and X[G].min(1)/max(1), bit for bit:
    rows full of ties between 0.0 and -0.0 (numpy keeps whichever its reduction order gives), NaNs, one
    row, random values."""
    from qemjax._mesh import box_bounds

    def same(a, b):
        return np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b)) \
            and a.dtype == b.dtype

    for trial in range(400):
        rng = np.random.default_rng(trial)
        pool = [[0.0, -0.0, 1.0, -1.0, np.nan], [0.0, -0.0, 1.0, 2.0, -3.0], [0.0, -0.0]][trial % 3]
        n = int(rng.integers(1, 60))
        V = rng.choice(pool, size=(n, 3)).astype(dtype) if trial % 4 else rng.normal(size=(n, 3)).astype(dtype)
        lo, hi = box_bounds.row_bounds(V)
        assert same(lo, V.min(0)) and same(hi, V.max(0)), trial
        G = rng.integers(0, n, size=(int(rng.integers(1, 40)), 3))
        used = V[np.unique(G)]
        lo, hi = box_bounds.used_bounds(V, G)
        assert same(lo, used.min(0)) and same(hi, used.max(0)), trial
        T = V[G]
        assert same(box_bounds.face_boxes(V, G), np.concatenate([T.min(1), T.max(1)], 1)), trial
        if dtype == np.float64 and trial % 4 == 0:  # the grid's edge lengths, likewise
            from qemjax._mesh.grid_nearest import edge_lengths

            W = V * 10.0 ** (trial % 7 - 3)
            want = np.sqrt(np.sum((W[G[:, [1, 2, 0]]] - W[G]) ** 2, axis=2)).ravel()
            assert np.array_equal(edge_lengths(W, G), want), trial


def test_grid_listing_is_every_cube_each_triangle_meets_in_triangle_order():
    """`grid_nearest._build` (filled from each cube's end, no scratch) against a plain listing: for every
    cube, the triangles whose bounding box meets it, ascending; int32 where the values fit."""
    from qemjax._mesh import grid_nearest as gn

    rng = np.random.default_rng(11)
    X = rng.normal(size=(300, 3))
    G = np.array([rng.choice(len(X), 3, replace=False) for _ in range(500)])
    *_, lo, h, dims, start, faces, mark = gn.grid(X, G)
    assert start.dtype == np.int32 and faces.dtype == np.int32 and len(mark) == len(G) + 1
    want = [[] for _ in range(int(np.prod(dims)))]
    for f, tri in enumerate(G):
        a, b = X[tri].min(0), X[tri].max(0)
        i0 = np.clip(np.floor((a - lo) / h).astype(int), 0, dims - 1)
        i1 = np.clip(np.floor((b - lo) / h).astype(int), 0, dims - 1)
        for i in range(i0[0], i1[0] + 1):
            for j in range(i0[1], i1[1] + 1):
                for k in range(i0[2], i1[2] + 1):
                    want[(i * dims[1] + j) * dims[2] + k].append(f)
    got = [faces[start[c]:start[c + 1]].tolist() for c in range(len(want))]
    assert got == want and start[-1] == len(faces)


def test_a_kept_index_answers_every_query_as_a_new_one(monkeypatch):
    """The index's marks are made once and each query point takes stamps of its own (`grid_nearest.stamps`):
    many queries of one index, of one point, on this thread or in blocks on threads, with and without seeds,
    give the answers of a fresh search each time, and no two queries share a stamp."""
    from qemjax._mesh import grid_nearest as gn
    from qemjax._mesh import threads

    rng = np.random.default_rng(12)
    X = rng.normal(size=(400, 3))
    G = np.array([rng.choice(len(X), 3, replace=False) for _ in range(700)])
    index = gn.grid(X, G)
    monkeypatch.setattr(threads, "count", lambda: 2)
    monkeypatch.setattr(gn, "MIN_BLOCK", 100)
    before = int(index[-1][-1])
    for trial in range(30):
        P = rng.normal(size=(int(rng.integers(1, 400)), 3)) * 2
        seed = rng.integers(-1, len(G), len(P)).astype(np.int32) if trial % 2 else np.zeros(0, np.int32)
        want_f, want_d = gn.nearest(X, G, P)
        f, d = gn.search(X, G, index, P, seed)
        assert np.array_equal(f, want_f) and np.array_equal(d, want_d)
        f1, d2 = gn.query_here(X, G, index, P, seed)
        assert np.array_equal(f1, want_f) and np.array_equal(np.sqrt(d2), want_d)
        before, after = before + 2 * len(P), int(index[-1][-1])
        assert after == before  # each point's stamps once, never again
