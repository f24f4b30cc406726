"""Kernel checks against float64 numpy references on random inputs (kernels run under enable_x64)."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from qemjax._kernels import flips, placement

import reference_rules
from qemjax._kernels import quadrics as qd
from qemjax._kernels.batching import DTYPE
from qemjax._costs.qem import QEM, initial_quadrics

rng = np.random.default_rng(0)


def brute_quadric_cost(x, planes, w):
    """Σ w (n·x + d)² for planes (k,4) = [n, d]."""
    return np.sum(w * (planes[:, :3] @ x + planes[:, 3]) ** 2)


def test_pack_unpack_roundtrip():
    with jax.enable_x64(True):
        A = rng.normal(size=(5, 3, 3))
        A = A + np.swapaxes(A, 1, 2)
        b, c = rng.normal(size=(5, 3)), rng.normal(size=5)
        A2, b2, c2 = qd.unpack(qd.pack(jnp.asarray(A), jnp.asarray(b), jnp.asarray(c)))
        np.testing.assert_allclose(A2, A, rtol=0, atol=0)
        np.testing.assert_allclose(b2, b)
        np.testing.assert_allclose(c2, c)


def test_translate_and_evaluate_match_brute_force():
    with jax.enable_x64(True):
        n = rng.normal(size=(7, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p0 = rng.normal(size=3)  # frame origin
        pts = rng.normal(size=(7, 3))  # a point on each plane
        d = -np.sum(n * pts, 1)
        w = rng.uniform(0.5, 2.0, 7)
        # quadric of each plane in the frame of p0: plane n·u + (n·p0 + d)
        A = np.einsum("k,ki,kj->ij", w, n, n)
        dl = n @ p0 + d
        q = qd.pack(jnp.asarray(A), jnp.asarray(np.sum(w[:, None] * dl[:, None] * n, 0)),
                    jnp.asarray(np.sum(w * dl * dl)))
        planes = np.concatenate([n, d[:, None]], 1)
        for _ in range(5):
            x = rng.normal(size=3)
            ref = brute_quadric_cost(x, planes, w)
            np.testing.assert_allclose(qd.evaluate(q, jnp.asarray(x - p0)), ref, rtol=1e-10)
            shift = rng.normal(size=3)
            q2 = qd.translate(q, jnp.asarray(shift))
            np.testing.assert_allclose(qd.evaluate(q2, jnp.asarray(x - p0 - shift)), ref, rtol=1e-10)


@pytest.mark.parametrize("power", [1.0, 0.5])
def test_vertex_quadrics_match_brute_force(power):
    """Sum over incident faces of (area / mean area)^power-weighted squared plane distances, boundary
    planes included (weighted by (|e|² / mean |e|²)^power)."""
    from qemjax.shapes import grid

    V, F = grid(4)
    V = V + np.c_[np.zeros((len(V), 2)), 0.1 * rng.normal(size=len(V))]  # bumpy: non-trivial planes
    Q = initial_quadrics(V.astype(DTYPE), F, area_weighted=True, boundary_weight=3.0, feature_edges=None,
                         area_power=power)
    p = V[F]
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = np.linalg.norm(cr, axis=1) / 2
    nrm = cr / (2 * area[:, None])
    w = (area / area.mean()) ** power
    from qemjax._mesh import topology as topo

    be, bf = topo.boundary_edges(F, len(V))
    ed = np.concatenate([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]])
    mean_e2 = np.mean(np.sum(ed**2, 1))
    for v in [0, 7, 12]:
        x = V[v] + rng.normal(size=3) * 0.1
        ref = 0.0
        for f in np.flatnonzero((F == v).any(1)):
            ref += w[f] * (nrm[f] @ (x - p[f, 0])) ** 2
        for (a, b), f in zip(be, bf):
            if v in (a, b):
                e = V[b] - V[a]
                m = np.cross(e, nrm[f])
                m /= np.linalg.norm(m)
                ref += 3.0 * (e @ e / mean_e2) ** power * (m @ (x - V[a])) ** 2
        got = float(qd.evaluate(jnp.asarray(Q[v], jnp.float32), jnp.asarray(x - V[v], jnp.float32)))
        np.testing.assert_allclose(got, ref, rtol=2e-4, atol=1e-7)


def test_area_power_zero_and_one_are_the_unit_and_area_weights_exactly():
    from qemjax.shapes import bumpy_sphere

    V, F = bumpy_sphere(2)
    V = V.astype(DTYPE)

    def q(**kw):
        return initial_quadrics(V, F, boundary_weight=3.0, feature_edges=None, **kw)
    assert np.array_equal(q(area_weighted=True, area_power=0.0), q(area_weighted=False))
    assert np.array_equal(q(area_weighted=True, area_power=1.0), q(area_weighted=True))
    assert not np.array_equal(q(area_weighted=True, area_power=0.5), q(area_weighted=True))


def _sphere_quadrics(center, radius, n_planes=40):
    """Tangent planes of a sphere around a point: a well-conditioned quadric, minimum near the center."""
    d = rng.normal(size=(n_planes, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = center + radius * d
    return d, pts


def _quadric_in_frame(normals, points, origin, w=None):
    w = np.ones(len(normals)) if w is None else w
    dl = np.sum(normals * (origin - points), 1)
    A = np.einsum("k,ki,kj->ij", w, normals, normals)
    b = np.sum(w[:, None] * dl[:, None] * normals, 0)
    return np.concatenate([A[0], A[1, 1:], A[2, 2:], b, [np.sum(w * dl * dl)]])


def _place64(q1, q2, p1, p2, endpoints=False, rank=False, rank_eps=1e-3):
    """Float64 placement; ``rank``: the truncated solve (placement='rank')."""
    with jax.enable_x64(True):
        fn, eps = (placement.place_rank, rank_eps) if rank else (placement.place, 1e-5)
        out = fn(jnp.asarray(q1), jnp.asarray(q2), jnp.asarray(p1), jnp.asarray(p2), jnp.asarray(endpoints),
                 jnp.asarray(eps), jnp.asarray(2.0))
        return [np.asarray(o) for o in out]


def test_solve_branch_matches_direct_solve():
    for _ in range(10):
        n1, pt1 = _sphere_quadrics(rng.normal(size=3) * 0.01, 0.3)
        n2, pt2 = _sphere_quadrics(rng.normal(size=3) * 0.01, 0.3)
        p1, p2 = rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.05 + 0.1  # optimum within reach
        q1, q2 = _quadric_in_frame(n1, pt1, p1), _quadric_in_frame(n2, pt2, p2)
        x, cost, branch, qsum = _place64(q1, q2, p1, p2)
        # direct float64 solve of the summed quadric in world coordinates
        nn = np.concatenate([n1, n2])
        pp = np.concatenate([pt1, pt2])
        A = nn.T @ nn
        bvec = -nn.T @ np.sum(nn * pp, 1)
        xref = np.linalg.solve(A, -bvec)
        planes = np.concatenate([nn, -np.sum(nn * pp, 1)[:, None]], 1)
        assert branch == placement.SOLVE
        np.testing.assert_allclose(x, xref, atol=1e-9)
        np.testing.assert_allclose(cost, brute_quadric_cost(xref, planes, np.ones(len(nn))), rtol=1e-8)
        # the merged quadric is expressed in x's frame: Q(0) = cost
        np.testing.assert_allclose(qsum[9], cost, rtol=1e-8)


def test_flat_patch_is_singular_and_stays_on_segment():
    nrm = np.tile([[0.0, 0.0, 1.0]], (6, 1))
    pts = np.c_[rng.uniform(-1, 1, (6, 2)), np.zeros(6)]
    p1, p2 = np.array([0.0, 0.0, 0.0]), np.array([0.2, 0.1, 0.0])
    x, cost, branch, _ = _place64(_quadric_in_frame(nrm, pts, p1), _quadric_in_frame(nrm, pts, p2), p1, p2)
    assert branch != placement.SOLVE
    assert cost < 1e-20
    t = np.dot(x - p1, p2 - p1) / np.dot(p2 - p1, p2 - p1)
    np.testing.assert_allclose(x, p1 + t * (p2 - p1), atol=1e-12)
    assert -1e-12 <= t <= 1 + 1e-12


def test_crease_gives_best_point_on_segment():
    """Two planes z=0 and x=0 meet in the y axis (rank-2 quadric): the pair straddling the crease lands
    on it, through the segment branch, at zero cost."""
    nrm = np.array([[0.0, 0, 1]] * 3 + [[1.0, 0, 0]] * 3)
    pts = np.zeros((6, 3))
    p1, p2 = np.array([0.3, 0.2, 0.0]), np.array([-0.2, 0.4, 0.0])  # crosses the y axis at t = 0.6
    x, cost, branch, _ = _place64(_quadric_in_frame(nrm, pts, p1), _quadric_in_frame(nrm, pts, p2), p1, p2)
    assert branch == placement.SEGMENT
    assert cost < 1e-14
    assert abs(x[0]) < 1e-12 and abs(x[2]) < 1e-12
    # reference: minimise along the segment by dense search
    ts = np.linspace(0, 1, 10001)
    seg = p1 + ts[:, None] * (p2 - p1)
    best = seg[np.argmin(seg[:, 0] ** 2 + seg[:, 2] ** 2)]
    np.testing.assert_allclose(x, best, atol=1e-4)


def test_flat_patch_keeps_the_midpoint_in_the_plane():
    """A flat patch has a rank-1 quadric: the truncated solve moves only across the plane (here not at all),
    so the pair lands on its midpoint at zero cost."""
    nrm = np.tile([[0.0, 0.0, 1.0]], (6, 1))
    pts = np.c_[rng.uniform(-1, 1, (6, 2)), np.zeros(6)]
    p1, p2 = np.array([0.0, 0.0, 0.0]), np.array([0.2, 0.1, 0.0])
    x, cost, branch, _ = _place64(_quadric_in_frame(nrm, pts, p1), _quadric_in_frame(nrm, pts, p2), p1, p2,
                                  rank=True)
    assert branch == placement.TRUNCATED
    assert cost < 1e-20
    np.testing.assert_allclose(x, 0.5 * (p1 + p2), atol=1e-12)
    lifted = p1 + [0, 0, 0.05], p2 + [0, 0, 0.03]  # off the plane: back onto it, straight across
    x, cost, branch, _ = _place64(_quadric_in_frame(nrm, pts, lifted[0]), _quadric_in_frame(nrm, pts, lifted[1]),
                                  *lifted, rank=True)
    assert branch == placement.TRUNCATED and cost < 1e-14
    np.testing.assert_allclose(x, [0.1, 0.05, 0.0], atol=1e-12)


def test_crease_lands_on_the_crease_nearest_the_midpoint():
    """Two planes z=0 and x=0 meet in the y axis (rank-2 quadric): the pair straddling the crease lands
    on the point of the crease nearest its midpoint (the free direction keeps the midpoint's y), at zero
    cost, off the segment (the segment's point on the crease has another y)."""
    nrm = np.array([[0.0, 0, 1]] * 3 + [[1.0, 0, 0]] * 3)
    pts = np.zeros((6, 3))
    p1, p2 = np.array([0.3, 0.2, 0.0]), np.array([-0.2, 0.4, 0.0])  # crosses the y axis at t = 0.6
    x, cost, branch, _ = _place64(_quadric_in_frame(nrm, pts, p1), _quadric_in_frame(nrm, pts, p2), p1, p2,
                                  rank=True)
    assert branch == placement.TRUNCATED
    assert cost < 1e-14
    np.testing.assert_allclose(x, [0.0, 0.3, 0.0], atol=1e-12)


def test_far_solution_falls_back_to_the_segment():
    """A well-conditioned quadric whose minimum lies far from a short pair: the best point on the segment."""
    n1, pt1 = _sphere_quadrics(np.array([1.0, 1.0, 1.0]), 0.3)
    p1, p2 = np.array([0.0, 0.0, 0.0]), np.array([0.05, 0.0, 0.0])
    q1, q2 = _quadric_in_frame(n1, pt1, p1), _quadric_in_frame(n1, pt1, p2)
    for rank in (False, True):
        x, cost, branch, _ = _place64(q1, q2, p1, p2, rank=rank)
        assert branch == placement.SEGMENT
    planes = np.concatenate([np.concatenate([n1, n1]), -np.sum(np.concatenate([n1 * pt1] * 2), 1)[:, None]], 1)
    ts = np.linspace(0, 1, 20001)
    costs = [brute_quadric_cost(p1 + t * (p2 - p1), planes, np.ones(len(planes))) for t in ts]
    np.testing.assert_allclose(x, p1 + ts[int(np.argmin(costs))] * (p2 - p1), atol=1e-4)  # both agree


def test_endpoints_placement_picks_best_of_three():
    for _ in range(10):
        n1, pt1 = _sphere_quadrics(rng.normal(size=3) * 0.1, 0.3, 10)
        p1, p2 = rng.normal(size=3) * 0.2, rng.normal(size=3) * 0.2
        q1, q2 = _quadric_in_frame(n1, pt1, p1), _quadric_in_frame(n1[:5], pt1[:5], p2)
        x, cost, branch, _ = _place64(q1, q2, p1, p2, endpoints=True)
        assert branch == placement.ENDPOINT
        planes = np.concatenate([np.concatenate([n1, n1[:5]]),
                                 -np.sum(np.concatenate([n1 * pt1, n1[:5] * pt1[:5]]), 1)[:, None]], 1)
        cands = [p1, p2, 0.5 * (p1 + p2)]
        costs = [brute_quadric_cost(c, planes, np.ones(len(planes))) for c in cands]
        np.testing.assert_allclose(cost, min(costs), rtol=1e-9)
        np.testing.assert_allclose(x, cands[int(np.argmin(costs))], atol=1e-12)


def test_float32_kernel_close_to_float64():
    n1, pt1 = _sphere_quadrics(np.zeros(3), 0.3)
    p1, p2 = np.array([0.01, 0.0, 0.0]), np.array([0.0, 0.02, 0.0])
    q1, q2 = _quadric_in_frame(n1, pt1, p1), _quadric_in_frame(n1, pt1, p2)
    x64, c64, _, _ = _place64(q1, q2, p1, p2)
    params = QEM().kernel_params()
    x32, c32, _, _ = placement.place(q1[None].astype(DTYPE), q2[None].astype(DTYPE), p1[None].astype(DTYPE),
                                    p2[None].astype(DTYPE), params["endpoints_only"], params["cond_eps"],
                                    params["max_shift"])
    x32, c32 = np.asarray(x32), np.asarray(c32)
    np.testing.assert_allclose(x32[0], x64, atol=1e-5)
    np.testing.assert_allclose(c32[0], c64, rtol=1e-3)


def test_flip_kernel_matches_numpy_reference():
    with jax.enable_x64(True):
        K = 200
        p = rng.normal(size=(K, 3, 3))
        k = rng.integers(0, 3, K)
        x = rng.normal(size=(K, 3))
        got = np.asarray(flips.moved_corner_flips(jnp.asarray(p), jnp.asarray(k), jnp.asarray(x),
                                                  jnp.asarray(0.0)))
        q = p.copy()
        q[np.arange(K), k] = x
        n0 = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        n1 = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
        assert np.array_equal(got, np.sum(n0 * n1, 1) <= 0)
        assert 0 < got.sum() < K  # both outcomes exercised


def test_face_flips_on_a_fan():
    """Moving the centre of a hexagonal fan past its rim flips faces; a small move does not; moving it onto
    a rim edge's line leaves a zero-area face, which counts as flipped (sliver guard)."""
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]
    V = np.r_[[[0.0, 0, 0]], np.c_[np.cos(ang), np.sin(ang), np.zeros(6)]].astype(np.float32)
    F = np.array([[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)])
    p = V[F]
    k = np.zeros(6, np.int32)
    ref = np.tile(np.float32([[0, 0, 1]]), (6, 1))
    mask = np.ones(6, bool)

    def flipped(x):
        xs = np.tile(np.float32(x), (6, 1))
        return np.asarray(flips.face_flips(p, k, xs, mask, ref, np.float32(0.0)))

    assert flipped([2.0, 0.0, 0.0]).any()
    assert not flipped([0.1, 0.05, 0.0]).any()
    on_rim = 0.5 * (V[1] + V[2])  # on the line of face 0's far edge
    assert flipped(on_rim)[0]


def _random_quadrics(k):
    """k random positive semi-definite packed quadrics (sums of a few random planes, random frames)."""
    out = []
    for _ in range(k):
        nrm = rng.normal(size=(4, 3))
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        out.append(_quadric_in_frame(nrm, rng.normal(size=(4, 3)), rng.normal(size=3)))
    return np.array(out)


def test_indexed_placement_matches_per_pair_placement():
    """place_pairs (gathers rows of VQ, one stacked output) equals `place` on the gathered inputs, and
    merged_quadrics equals Q1 + Q2 re-expressed at x: Q(0) = Q1(x − p1) + Q2(x − p2)."""
    with jax.enable_x64(True):
        n, K = 40, 64
        V, Q = rng.normal(size=(n, 3)), _random_quadrics(n)
        VQ = np.concatenate([V, Q], 1)
        P = rng.integers(0, n, (K, 2))
        modes = [(placement.place_pairs_rank, placement.place_rank, 1e-3),
                 (placement.place_pairs, placement.place, 1e-5)]  # the thresholded last: x is checked below
        for pairs_fn, place_fn, eps in modes:
            args = (np.asarray(False), np.asarray(eps), np.asarray(2.0))
            out = np.asarray(pairs_fn(jnp.asarray(VQ), jnp.asarray(P), *args))
            x, cost, branch, _ = (np.asarray(o) for o in place_fn(
                Q[P[:, 0]], Q[P[:, 1]], V[P[:, 0]], V[P[:, 1]], *args))
            np.testing.assert_allclose(out[:3].T, x, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(out[3], cost, rtol=1e-12, atol=1e-12)
            assert np.array_equal(out[4].astype(int), branch)
            assert len(set(branch.tolist())) > 1  # several branches exercised
        qm = np.asarray(placement.merged_quadrics(jnp.asarray(VQ), jnp.asarray(P), jnp.asarray(x)))
        for i in range(K):
            a, b = P[i]
            ref = (qd.evaluate(jnp.asarray(Q[a]), jnp.asarray(x[i] - V[a]))
                   + qd.evaluate(jnp.asarray(Q[b]), jnp.asarray(x[i] - V[b])))
            np.testing.assert_allclose(qm[i, 9], ref, rtol=1e-9, atol=1e-12)
            u = rng.normal(size=3)  # and anywhere else
            ref_u = (qd.evaluate(jnp.asarray(Q[a]), jnp.asarray(x[i] + u - V[a]))
                     + qd.evaluate(jnp.asarray(Q[b]), jnp.asarray(x[i] + u - V[b])))
            np.testing.assert_allclose(qd.evaluate(jnp.asarray(qm[i]), jnp.asarray(u)), ref_u, rtol=1e-9)


def test_indexed_flips_match_numpy_reference():
    """face_flips_at (corners and reference normals gathered in the kernel) against numpy in float64."""
    with jax.enable_x64(True):
        n, K = 30, 300
        V = np.concatenate([rng.normal(size=(n, 3)), rng.normal(size=(n, 10))], 1)  # extra columns ignored
        faces = np.array([rng.choice(n, 3, replace=False) for _ in range(K)])
        k = rng.integers(0, 3, K)
        x = rng.normal(size=(K, 3))
        N0 = rng.normal(size=(50, 3))
        fids = rng.integers(0, 50, K)
        got = np.asarray(flips.face_flips_at(jnp.asarray(V), jnp.asarray(N0), jnp.asarray(faces),
                                             jnp.asarray(fids), jnp.asarray(k), jnp.asarray(x), 0.0))
        p = V[faces][:, :, :3]
        q = p.copy()
        q[np.arange(K), k] = x
        n0 = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        n1 = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
        ref = (np.sum(n0 * n1, 1) <= 0) | (np.sum(N0[fids] * n1, 1) <= 0)
        assert np.array_equal(got, ref)
        assert 0 < got.sum() < K


def test_quality_guard_matches_float64():
    """The quality guard of face_flips_at (flips otherwise allowed) against numpy in float64: a face is
    refused exactly when its 2·area / longest edge² ends below the bound and below what it was (random
    faces, away from ties)."""
    with jax.enable_x64(True):
        n, K = 30, 2000
        V = rng.normal(size=(n, 3))
        faces = np.array([rng.choice(n, 3, replace=False) for _ in range(K)])
        k = rng.integers(0, 3, K)
        x = rng.normal(size=(K, 3))
        N0 = rng.normal(size=(K, 3))

        def quality(c):
            nrm = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
            longest = np.max([((c[:, (i + 1) % 3] - c[:, i]) ** 2).sum(1) for i in range(3)], axis=0)
            return nrm / longest
        p = V[faces]
        q = p.copy()
        q[np.arange(K), k] = x
        q0, q1 = quality(p), quality(q)
        for bound in (0.1, 0.3, 0.6):
            got = np.asarray(flips.face_flips_at(jnp.asarray(V), jnp.asarray(N0), jnp.asarray(faces),
                                                 jnp.asarray(np.arange(K)), jnp.asarray(k), jnp.asarray(x), -2.0,
                                                 bound))
            ref = (q1 < bound) & (q1 < q0)
            clear = (np.abs(q1 - bound) > 1e-9) & (np.abs(q1 - q0) > 1e-9)
            assert np.array_equal(got[clear], ref[clear])
            assert 0 < ref.sum() < K


def test_host_flip_test_agrees_with_the_kernel_in_float32():
    """flips_host (the device kernel's numpy twin, tests/reference_rules.py) decides as face_flips_at does,
    one contraction at a time, on float32 inputs that include near-threshold turns and slivers."""
    n = 40
    V = rng.normal(size=(n, 3)).astype(np.float32)
    N0 = rng.normal(size=(60, 3)).astype(np.float32)
    verdicts = []
    for _ in range(300):
        K = int(rng.integers(1, 9))
        faces = np.array([rng.choice(n, 3, replace=False) for _ in range(K)])
        k = rng.integers(0, 3, K)
        fids = rng.integers(0, 60, K)
        # the moving corner goes to a point near the line through the other two: turns close to 90°
        p = V[faces]
        o1, o2 = p[np.arange(K), (k + 1) % 3], p[np.arange(K), (k + 2) % 3]
        x = (o1[0] + rng.normal() * (o2[0] - o1[0]) + 1e-3 * rng.normal(size=3)).astype(np.float32)
        for cos_max, q in ((0.0, 0.0), (0.5, 0.0), (-2.0, 0.0), (-2.0, 0.3), (0.0, 0.5)):
            want = bool(np.any(np.asarray(flips.face_flips_at(
                jnp.asarray(V), jnp.asarray(N0), jnp.asarray(faces), jnp.asarray(fids.astype(np.int32)),
                jnp.asarray(k.astype(np.int32)), jnp.asarray(np.tile(x, (K, 1))), np.float32(cos_max),
                np.float32(q)))))
            got = reference_rules.flips_host(V, N0, faces, fids, k, x, cos_max, q)
            assert got == want, (faces, k, x, cos_max, q)
            verdicts.append(got)
    assert 0 < sum(verdicts) < len(verdicts)


def test_set_rows_updates_in_place_and_drops_padding():
    from qemjax._kernels.batching import set_rows

    A = jnp.zeros((10, 4), jnp.float32)
    idx = np.array([7, 2])
    rows = np.arange(8, dtype=np.float32).reshape(2, 4)
    A = np.asarray(set_rows(A, idx, rows, size=4))  # two padding rows point past the end
    assert np.array_equal(A[[7, 2]], rows)
    assert np.count_nonzero(A) == 7  # nothing else written (rows has one zero)


def _pinv_reference(q, mid, half, eps, max_shift):
    """Float64 numpy reference of the rank-aware solve: (x, rank) of the truncated pseudo-inverse around the
    midpoint, or None where its solution lies beyond max_shift·|p2 − p1|."""
    A, b, _ = (np.asarray(t) for t in qd.unpack(jnp.asarray(q)))
    lam, vec = np.linalg.eigh(A)
    keep = lam > eps * lam.max()
    u = -vec[:, keep] @ ((vec[:, keep].T @ b) / lam[keep])
    near = np.any(np.abs(lam / (eps * lam.max()) - 1) < 0.01)  # at the threshold: either side is right
    if u @ u > 4 * max_shift ** 2 * (half @ half):
        return None, int(keep.sum()), near
    return mid + u, int(keep.sum()), near


def _low_rank_pair(rank, degenerate=False):
    """Quadrics of planes with `rank` independent normals; when `degenerate`, nearly repeated normals and
    one more plane of weight 1e-7 (an eigenvalue just above zero, far below the threshold)."""
    base = rng.normal(size=(rank, 3))
    nrm = np.concatenate([base, base + (1e-9 if degenerate else 0.0) * rng.normal(size=(rank, 3)),
                          rng.normal(size=(1, 3))])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    w = rng.uniform(0.2, 1.0, len(nrm))
    w[-1] = 1e-7 if degenerate else 0.0
    pts = rng.normal(size=(len(nrm), 3)) * 0.1
    p1 = rng.normal(size=3) * 0.1
    p2 = p1 + rng.normal(size=3) * 0.1
    return _quadric_in_frame(nrm, pts, p1, w), _quadric_in_frame(nrm, pts, p2, w), p1, p2


def test_rank_aware_solve_matches_float64_pseudo_inverse():
    """Random rank-1, rank-2, rank-3 and nearly degenerate quadrics: the kernel's point and branch equal
    the numpy eigh-based truncated pseudo-inverse (or the segment where that lands too far away)."""
    eps, shift = 1e-3, 2.0
    seen, ranks = set(), set()
    for rank in (1, 2, 3):
        for degenerate in (False, True):
            for _ in range(30):
                q1, q2, p1, p2 = _low_rank_pair(rank, degenerate)
                mid, half = 0.5 * (p1 + p2), 0.5 * (p2 - p1)
                with jax.enable_x64(True):
                    q = np.asarray(qd.translate(jnp.asarray(q1), jnp.asarray(half))) + \
                        np.asarray(qd.translate(jnp.asarray(q2), jnp.asarray(-half)))
                    x, cost, branch, _ = _place64(q1, q2, p1, p2, rank=True, rank_eps=eps)
                    xref, kept, near = _pinv_reference(q, mid, half, eps, shift)
                assert kept <= rank  # random normals may be nearly parallel or coplanar
                ranks.add(kept)
                if near:
                    continue
                if xref is None:
                    assert branch in (placement.SEGMENT, placement.ENDPOINT)
                    continue
                assert branch == (placement.SOLVE if kept == 3 else placement.TRUNCATED)
                seen.add(int(branch))
                np.testing.assert_allclose(x, xref, atol=1e-9)
    assert seen == {placement.SOLVE, placement.TRUNCATED} and ranks == {1, 2, 3}


def test_float32_placement_is_finite_on_degenerate_input():
    """Zero quadrics, coincident and tiny pairs, single planes and huge weights: finite output, no NaN."""
    params = QEM().kernel_params()
    zero = np.zeros(10)
    plane = _quadric_in_frame(np.array([[0.0, 0.0, 1.0]]), np.zeros((1, 3)), np.zeros(3))
    n1, pt1 = _sphere_quadrics(np.zeros(3), 0.3)
    sphere = _quadric_in_frame(n1, pt1, np.zeros(3))
    cases = []
    for q in (zero, plane, sphere, plane * 1e20, plane * 1e-30, sphere * 1e-30):
        for d in (0.0, 1e-30, 1e-7, 0.1):
            cases.append((q, q, np.zeros(3), np.array([d, 0.0, 0.0])))
            cases.append((q, zero, np.zeros(3), np.array([d, d, d])))
    q1, q2, p1, p2 = (np.array(c, DTYPE) for c in zip(*cases))
    for fn, eps in ((placement.place, params["cond_eps"]), (placement.place_rank, params["rank_eps"])):
        x, cost, branch, qsum = (np.asarray(o) for o in fn(
            q1, q2, p1, p2, params["endpoints_only"], eps, params["max_shift"]))
        assert np.isfinite(x).all() and np.isfinite(cost).all() and np.isfinite(qsum).all()
        assert set(branch.tolist()) <= {placement.SOLVE, placement.SEGMENT, placement.ENDPOINT,
                                        placement.TRUNCATED}
        assert branch[0] == placement.ENDPOINT and np.array_equal(x[0], p1[0])  # zero quadric: the midpoint


def test_fixed_order_arithmetic_matches_float64_and_ignores_the_batch():
    """`_kernels.fixed`: float64 references on random inputs, and the same bits for a row whatever the
    number of rows it is computed among (what keeps `simplify_batch` equal to `simplify` alone)."""
    import jax
    from qemjax._kernels import fixed
    from qemjax._costs.regularize import shape_term

    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(2, 50, 3))
    v = rng.normal(size=(50, 13))
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(fixed.dot3(a, b)), np.einsum("ij,ij->i", a, b), rtol=1e-14)
        np.testing.assert_allclose(np.asarray(fixed.cross3(a, b)), np.cross(a, b), rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(np.asarray(fixed.norm3(a)), np.linalg.norm(a, axis=1), rtol=1e-14)
        np.testing.assert_allclose(np.asarray(fixed.tree_sum(v)), v.sum(1), rtol=1e-12, atol=1e-14)
    x = rng.normal(size=(300, 3)).astype(np.float32)
    c = rng.normal(size=(300, 16, 3, 3)).astype(np.float32)
    m = rng.random((300, 16)) < 0.6
    f = jax.jit(jax.vmap(shape_term))
    full = np.asarray(f(x, c, m))
    for k in (1, 7, 37, 128, 257):
        assert np.array_equal(np.asarray(f(x[:k], c[:k], m[:k])), full[:k]), k


def test_flips_host_blocks_match_the_component_twin():
    """`reference_rules.flips_host` (numpy on (K,3) blocks, several contractions per pass) gives
    the answers of `_flips` on component lists, face by face, near the thresholds too."""
    rng = np.random.default_rng(5)
    for t in range(400):
        V = rng.normal(size=(12, 3)).astype(np.float32)
        if t % 3 == 0:
            V[:, 2] = 0  # planar: moves in the plane, collapses and slivers
        if t % 5 == 0:
            V = np.round(V * 4) / 4
        K = int(rng.integers(1, 8))
        F = np.array([rng.choice(12, 3, replace=False) for _ in range(K)])
        k = rng.integers(0, 3, K)
        x = V[rng.integers(12)] + (0 if t % 4 == 0 else rng.normal(size=3) * 10.0 ** rng.integers(-7, 0))
        N0 = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]).astype(np.float32) if t % 2 else \
            rng.normal(size=(K, 3)).astype(np.float32)
        cos_max = [0.0, -2.0, 0.7071067811865476, -0.5][t % 4]
        per_face = reference_rules.flips_host_faces(V, N0, F, np.arange(K), k, x.astype(np.float32), cos_max)
        for i in range(K):
            one = reference_rules.flips_host_reference(V, N0, F[i:i + 1], np.arange(K)[i:i + 1], k[i:i + 1],
                                             x.astype(np.float32), cos_max)
            assert bool(per_face[i]) == one, (t, i)


@pytest.mark.parametrize("jax_flag", [True, False])
def test_a_kernel_called_inside_a_trace_is_inlined(jax_flag, monkeypatch):
    """`_kernels.kernel` compiles a call of its own at the top level and inlines itself inside another
    trace (where its compiler options cannot apply), by JAX's trace flag or, without it, by its arguments."""
    import qemjax._kernels as K

    calls = []

    @K.kernel
    def double(x):
        calls.append(type(x).__name__)
        return 2 * x

    if not jax_flag:  # a JAX without the flag: the wrapper looks at its arguments
        monkeypatch.setattr(K, "_trace_flag", lambda: None)
    x = jnp.arange(3.0)
    assert np.array_equal(double(x), 2 * np.arange(3.0))
    assert np.array_equal(jax.jit(lambda y: double(y) + 1)(x), 2 * np.arange(3.0) + 1)
    assert np.array_equal(jax.jit(lambda: double(jnp.ones(2)))(), [2.0, 2.0])  # a trace, no tracer argument
    for outer in (lambda y: double(y) + 1, lambda y: double(jnp.ones(2))):  # inline: no nested jit call
        prims = {e.primitive.name for e in jax.make_jaxpr(outer)(x).eqns}
        assert "mul" in prims and not prims & {"pjit", "jit"}, prims


def test_a_kernels_first_call_from_two_threads(monkeypatch):
    """Two threads making a kernel's first call together both get its result (the wrapper publishes its
    compiled call and its trace test at once)."""
    import threading
    import time as _time

    import qemjax._kernels as K

    real = K._trace_flag

    def slow():  # widen the window between compiling and publishing
        _time.sleep(0.05)
        return real()
    monkeypatch.setattr(K, "_trace_flag", slow)

    @K.kernel
    def triple(x):
        return 3 * x

    out, errors = [], []

    def call():
        try:
            out.append(np.asarray(triple(jnp.arange(4.0))))
        except Exception as exc:  # noqa: BLE001 (any failure is the finding)
            errors.append(repr(exc))
    threads = [threading.Thread(target=call) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(out) == 2 and all(np.array_equal(o, 3 * np.arange(4.0)) for o in out)


def test_to_host_polls_then_gives_the_array(monkeypatch):
    """`_kernels.host.to_host`: the values of np.asarray (device arrays, numpy arrays); a result not yet
    ready is polled until it is, and past `SPIN_S` the wait blocks (no more polls)."""
    from qemjax._kernels import host

    x = jnp.arange(12.0, dtype=jnp.float32).reshape(3, 4) * 0.1
    assert np.array_equal(host.to_host(x), np.asarray(x)) and host.to_host(x).dtype == np.float32
    a = np.arange(5)
    assert host.to_host(a) is a

    class Pending:
        def __init__(self, polls, size=3):
            self.polls, self.left, self.size = 0, polls, size

        def is_ready(self):
            self.polls += 1
            self.left -= 1
            return self.left < 0

        def __array__(self, dtype=None, copy=None):
            self.read_after = self.polls
            return np.ones(3)

    p = Pending(50)
    assert np.array_equal(host.to_host(p), np.ones(3)) and p.read_after == 51  # read once ready
    p = Pending(50, size=host.POLL_SIZE + 1)
    assert np.array_equal(host.to_host(p), np.ones(3)) and p.read_after == 0  # large: not polled
    monkeypatch.setattr(host, "SPIN_S", 0.0)
    p = Pending(10 ** 9)
    assert np.array_equal(host.to_host(p), np.ones(3)) and p.read_after <= 2  # no time to poll: read (blocks)
