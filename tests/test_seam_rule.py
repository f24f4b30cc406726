"""The compiled seam rule (`qemjax._mesh.seam_rule`) against the Python rule it replaced
(tests/wedges_reference.py, and `_costs.attributes`' float64 host solves): the same bits on random inputs."""
from __future__ import annotations

import numpy as np
import pytest

from qemjax import shapes
from qemjax._costs import attributes as at
from qemjax._mesh import wedges as _wedges
from qemjax._mesh import seam_rule as wj
from qemjax._mesh.incidence import FaceLists

from wedges_reference import ReferenceTracker, _quadric


def same_bits(x, y) -> bool:
    """Equal arrays, bit for bit (NaN equal to itself, -0.0 not equal to 0.0)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    return x.shape == y.shape and np.array_equal(x.view(np.int64), y.view(np.int64))


def random_rows(rng, n, m, zero_alpha=0.2):
    """(n, 3 + 11 + 4m) float32 rows [position, attribute state]; some with α = 0."""
    rows = rng.normal(size=(n, 3 + 11 + 4 * m)) * 10.0 ** rng.integers(-3, 3, size=(n, 1))
    rows[:, 13] = np.abs(rows[:, 13]) * (rng.random(n) > zero_alpha)
    return rows.astype(np.float32)


@pytest.mark.parametrize("m", [1, 2, 3, 4, 9])
def test_host_solves_match_numpy_bit_for_bit(m):
    rng = np.random.default_rng(m)
    VQ = random_rows(rng, 64, m)
    s, W = np.empty(m), np.empty((3, m))
    for _ in range(300):
        a, b = rng.integers(0, len(VQ), 2)
        x = rng.normal(size=3) if rng.random() < 0.5 else VQ[rng.choice([a, b]), :3].astype(np.float64)
        cost, want = at.solve_host(VQ[a], VQ[b], x, m)
        got = wj.solve_host(VQ, a, b, x[0], x[1], x[2], m, s, W)
        assert same_bits(got, cost) and same_bits(s, want)
        wj.optimal_attributes(VQ, a, b, x[0], x[1], x[2], m, s)
        assert same_bits(s, at.optimal_attributes(VQ[[a]], VQ[[b]], x[None], m)[0])
        assert same_bits(wj.quadric(VQ, a, x[0], x[1], x[2]), _quadric(VQ[a], x))
        v = rng.choice([a, b])
        assert same_bits(wj.cost_at(VQ, a, b, v, -1, W), _quadric(VQ[a], VQ[v, :3]) + _quadric(VQ[b], VQ[v, :3]))
        assert same_bits(wj.cost_at(VQ, a, b, v, m, W), at.solve_host(VQ[a], VQ[b], VQ[v, :3], m)[0])


@pytest.mark.parametrize("m", [1, 2, 4])
def test_cost_with_held_attributes(m):
    """`attributes.cost_held_many` (a locked vertex's price: its attribute values held) against the sum
    over the pair's faces of w·Σ_j (g_j·x + d_j − s_j)², each face's linear fields fitted through its corners
    (`face_fields`), in float64; at the optimal values it is `solve_host`'s cost; its translation is
    `_np_translate`'s, bit for bit."""
    rng = np.random.default_rng(20 + m)
    mesh = shapes.icosphere(2)
    V, F = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    S = rng.uniform(-1, 1, (len(F), 3, m))
    w = rng.uniform(0.5, 2.0, len(F))
    rows = np.concatenate([V, at.attribute_state(V, F, S, w)], 1)
    g, d = at.face_fields(V[F], S)
    for a, b in F[rng.choice(len(F), 20), :2]:
        x = V[a] + rng.normal(scale=0.05, size=3)
        s = rng.uniform(-1, 1, m)
        around = np.concatenate([np.flatnonzero((F == a).any(1)), np.flatnonzero((F == b).any(1))])
        r = np.einsum("fjk,k->fj", g[around], x) + d[around] - s
        want = float(np.sum(w[around] * np.sum(r * r, 1)))
        cost = lambda s: at.cost_held_many(rows[[a]], rows[[b]], x[None], s[None], m)[0]  # noqa: E731
        assert np.isclose(cost(s), want, rtol=1e-9, atol=1e-12)
        best, s_opt = at.solve_host(rows[a], rows[b], x, m)
        assert np.isclose(cost(s_opt), best, rtol=1e-9, atol=1e-12) and cost(s) > best
        shift = rng.normal(size=(5, 3))
        assert same_bits(at._translate_many(np.repeat(rows[[a], 3:], 5, 0), shift, m),
                         np.stack([at._np_translate(rows[a, 3:], e, m) for e in shift]))


def test_numpy_conventions():
    """`np.sum`'s pairwise order and `np.clip`'s treatment of NaN and -0.0, as the kernels repeat them."""
    rng = np.random.default_rng(0)
    for n in range(0, 40):
        for _ in range(50):
            v = rng.normal(size=n) * 10.0 ** rng.integers(-8, 8, size=n)
            assert same_bits(wj.numpy_sum(np.r_[v, 7.0], n), np.sum(v))

    @wj.njit
    def clip(t):
        return wj._clip01(t)
    for t in [-0.0, 0.0, -1e-300, 1e-300, 0.25, 1.0, 1.5, np.nan, np.inf, -np.inf, -3.0]:
        assert same_bits(clip(t), np.clip(np.float64(t), 0, 1))
        assert same_bits(clip(t), np.clip(np.array([t]), 0, 1)[0])


def seamed_sphere(rng, k):
    """A bumpy sphere's welded faces, with one wedge per (vertex, chart) (charts: the dominant axis of each
    face's normal, as `test_attributes.atlas_sphere`) holding random values (w, k)."""
    V, F = shapes.bumpy_sphere(2, amplitude=0.05)
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ax = np.argmax(np.abs(nrm), axis=1)
    chart = 2 * ax + (nrm[np.arange(len(F)), ax] < 0)
    uniq, inv = np.unique((F * 6 + chart[:, None]).reshape(-1), return_inverse=True)
    # a fifth of the vertices keep one wedge: seams that end there (maps that are not one to one)
    vert = uniq // 6
    first = np.full(len(V), len(uniq))
    np.minimum.at(first, vert, np.arange(len(uniq)))
    merge = rng.random(len(V)) < 0.2
    wedge = np.where(merge[vert], first[vert], np.arange(len(uniq)))
    return V, F.astype(np.int64), wedge[inv].reshape(-1, 3), rng.normal(size=(len(uniq), k))


def _edges(F):
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(E, axis=0)


def _far_apart(faces, E, rng):
    """Pairs of E, in random order, whose faces share no vertex with another chosen pair's faces."""
    used = np.zeros(faces.cnt.shape[0], bool)
    out = []
    for i in rng.permutation(len(E)):
        _, f = faces.around(E[i])
        ring = np.unique(faces.F[f])
        if len(f) and not used[ring].any():
            used[ring] = True
            out.append(i)
    return np.array(out, np.int64)


@pytest.mark.parametrize("m,solved,frozen", [(-1, None, False), (2, (True, True), False),
                                             (3, (True, False, True), False), (2, (True, True), True)])
def test_tracker_matches_the_python_rule(m, solved, frozen):
    """Rounds of constrain / refused / contract on a mesh with seams: the compiled Tracker and the Python
    one (`ReferenceTracker`) give the same placements, costs, refusals, corner wedges, values and flags;
    ``frozen`` (locked vertices): a wedge a frozen vertex keeps never changes its value."""
    rng = np.random.default_rng(7 + m)
    k = 2 if m < 0 else m
    V, F, corners, values = seamed_sphere(rng, k)
    n = len(V)
    model = None if m < 0 else at.AttributeQEM(channels=m, weights=tuple(rng.uniform(0.1, 2.0, m)))
    lock = rng.random(n) < 0.25 if frozen else None
    args = (corners, values, n, F, model, None if solved is None else np.array(solved), lock)
    new, ref = _wedges.Tracker(*args), ReferenceTracker(*args)
    VQ = random_rows(rng, n, max(m, 0))[:, :3 + (10 if m < 0 else 11 + 4 * m)].copy()
    VQ[:, :3] = V
    VQ[rng.random(n) < 0.3, 3:] = 0  # equal prices at both ends: the tie goes to a
    faces = FaceLists(F, n)
    seen = dict(seam_pairs=0, refused=0, bad=0, seam_contractions=0)
    for rnd in range(12):
        E = _edges(faces.live())
        x = np.stack([VQ[E[:, 0], :3], VQ[E[:, 1], :3], 0.5 * (VQ[E[:, 0], :3] + VQ[E[:, 1], :3]),
                      VQ[E[:, 0], :3] + rng.normal(size=(len(E), 3)).astype(np.float32) * 0.01])
        x = x[rng.integers(0, 4, len(E)), np.arange(len(E))].astype(np.float32)
        cost = rng.random(len(E)).astype(np.float32)
        seen["seam_pairs"] += int((new.multi[E[:, 0]] | new.multi[E[:, 1]]).sum())
        for a, b in E[rng.choice(len(E), 30)]:  # the rule's answer, as maps
            assert new.modes(faces, int(a), int(b)) == ref.modes(faces, int(a), int(b))
            assert np.array_equal(new.multi, ref.multi)
        xn, cn, xr, cr = x.copy(), cost.copy(), x.copy(), cost.copy()
        multi0 = new.multi.copy()
        bad = new.constrain(faces, VQ, E, xn, cn)
        assert np.array_equal(bad, ref.constrain(faces, VQ, E, xr, cr))
        assert same_bits(xn, xr) and same_bits(cn, cr) and np.array_equal(new.multi, ref.multi)
        # the in-place form over some rows d: their placements, costs and refusals, the other rows untouched
        multi1, new.multi[:] = new.multi.copy(), multi0
        d = np.flatnonzero(rng.random(len(E)) < 0.7)
        xd, cd, bd = x.copy(), cost.copy(), np.zeros(len(E), np.int8)
        new.constrain_rows(faces, VQ, E, d, xd, cd, bd, 7)
        rest = np.setdiff1d(np.arange(len(E)), d)
        assert same_bits(xd[d], xn[d]) and same_bits(cd[d], cn[d]) and np.array_equal(bd[d] == 7, bad[d])
        assert same_bits(xd[rest], x[rest]) and same_bits(cd[rest], cost[rest]) and not bd[rest].any()
        new.multi[:] = multi1
        seen["bad"] += int(bad.sum())
        # a round: pairs far apart, placed where constrain put them, refused by the rule or contracted
        pick = _far_apart(faces, E, rng)
        pick = pick[~bad[pick]]
        P, X = E[pick], xn[pick]
        if rnd % 3 == 2:  # some placements off the allowed endpoints: refusals
            X = X + np.float32(1e-3)
        check = rng.random(len(P)) < 0.9
        no = new.refused(faces, VQ, P, X, check)
        want = np.array([bool(c) and not ref.allowed(faces, VQ, int(a), int(b), y)
                         for (a, b), y, c in zip(P, X, check)], bool)
        assert np.array_equal(no, want) and np.array_equal(new.multi, ref.multi)
        seen["refused"] += int(no.sum())
        P, X = P[check & ~no], X[check & ~no]
        seen["seam_contractions"] += int((new.multi[P[:, 0]] | new.multi[P[:, 1]]).sum())
        if rnd % 2:
            new.contract_many(faces, VQ, P, X)
            ref.contract_many(faces, VQ, P, X)
        else:  # the greedy scheduler's call, one pair at a time
            for (a, b), y in zip(P, X):
                new.contract(faces, VQ, int(a), int(b), y)
                ref.contract(faces, VQ, int(a), int(b), y)
        assert np.array_equal(new.C, ref.C) and same_bits(new.val, ref.val)
        assert np.array_equal(new.multi, ref.multi)
        faces.contract(P[:, 0], P[:, 1])
        VQ[P[:, 0], :3] = X
        VQ[P[:, 0], 3:] = VQ[P[:, 0], 3:] + VQ[P[:, 1], 3:]
    assert all(v > 0 for v in seen.values()), seen  # every branch of the rule was exercised
    if frozen:  # the wedges still at the frozen vertex that held them first: their first values
        first_vertex = np.full(len(values), -1)
        first_vertex[np.asarray(corners).reshape(-1)] = F.reshape(-1)
        live = np.flatnonzero(faces.alive)
        at_now = np.full(len(values), -1)
        at_now[new.C[live].reshape(-1)] = faces.F[live].reshape(-1)
        kept = np.flatnonzero((at_now == first_vertex) & (at_now >= 0) & lock[np.maximum(first_vertex, 0)])
        assert len(kept) > 10 and same_bits(new.val[kept], np.asarray(values, np.float64)[kept])
        thawed = np.flatnonzero((at_now == first_vertex) & (at_now >= 0) & ~lock[np.maximum(first_vertex, 0)])
        assert not same_bits(new.val[thawed], np.asarray(values, np.float64)[thawed])  # the others move


def test_broken_seam_rule_is_an_error():
    """Contracting a seam pair where the rule forbids it raises, as the Python rule did."""
    rng = np.random.default_rng(1)
    V, F, corners, values = seamed_sphere(rng, 2)
    tr = _wedges.Tracker(corners, values, len(V), F)
    VQ = np.zeros((len(V), 13), np.float32)
    VQ[:, :3] = V
    faces = FaceLists(F, len(V))
    E = _edges(F)
    seam = E[tr.multi[E[:, 0]] & tr.multi[E[:, 1]]][0]
    with pytest.raises(AssertionError, match="seam rule broken"):
        tr.contract(faces, VQ, int(seam[0]), int(seam[1]), 0.5 * (VQ[seam[0], :3] + VQ[seam[1], :3]) + 1)


@pytest.mark.parametrize("n,m", [(4, 2), (4, 9), (3, 1), (5, 3)])
def test_compiled_solve_matches_fixed_order(n, m):
    """`fixed_order_solve.solve` gives `fixed_order.solve`'s bits: random, near-singular, singular and NaN
    systems, pivots that tie."""
    from qemjax._mesh import fixed_order, fixed_order_solve

    rng = np.random.default_rng(n * 10 + m)
    M = rng.normal(size=(400, n, n)) * 10.0 ** rng.integers(-4, 4, size=(400, 1, 1))
    M[:40, :, 0] = M[:40, :, 1]  # singular
    M[40:80, 1] = M[40:80, 0] * (1 + 1e-15)  # nearly so
    M[80:120] = np.round(M[80:120])  # ties among pivots
    M[120:130, 0, 0] = np.nan
    M[130:140, 2, 0] = np.nan
    rhs = rng.normal(size=(400, n, m))
    with np.errstate(all="ignore"):
        X0, d0 = fixed_order.solve(M, rhs)
    X1, d1 = fixed_order_solve.solve(M, rhs)
    assert same_bits(X0, X1) and same_bits(d0, d1)


def test_face_fields_unchanged_by_the_compiled_solve(monkeypatch):
    """`attributes.face_fields` with the compiled solve: the bits of the numpy solve's fields."""
    from qemjax._mesh import fixed_order

    rng = np.random.default_rng(3)
    V, F = shapes.bumpy_sphere(2)
    P = np.asarray(V, np.float64)[F]
    P[:5, 2] = P[:5, 1]  # degenerate faces: the corners' mean
    S = rng.normal(size=(len(F), 3, 2))
    g, d = at.face_fields(P, S)
    from qemjax._mesh import fixed_order_solve
    monkeypatch.setattr(fixed_order_solve, "solve", fixed_order.solve)  # the numpy solve in its place
    g0, d0 = at.face_fields(P, S)
    assert same_bits(g, g0) and same_bits(d, d0)
