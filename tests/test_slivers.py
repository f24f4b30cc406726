"""Sliver moves after the polish (a method's ``sliver_moves``, `qemjax._pipeline.slivers`): the compiled
helpers against float64 references on random triangles; on random meshes, every run they change has fewer
slivers, a largest distance over the polish's samples (all pairs) no larger than the polish left, a two-way
rms within the slack of the re-fit's, the same faces and a valid mesh; fixed vertices stay; a batch gives
simplify's bits; bad values are refused; the compiled trial of a move answers as the numpy steps."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_valid
from test_polish import _reference, _turn

import qemjax
from qemjax._pipeline import moves as _moves
from qemjax._pipeline import refit as _refit
from qemjax._pipeline import slivers as _slivers
from qemjax.metrics import triangle_quality


def _angles(T):
    """(n,3) interior angles (radians) of triangles T (n,3,3), float64."""
    out = []
    for k in range(3):
        u = T[:, (k + 1) % 3] - T[:, k]
        v = T[:, (k + 2) % 3] - T[:, k]
        c = np.sum(u * v, 1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        out.append(np.arccos(np.clip(c, -1, 1)))
    return np.stack(out, 1)


@pytest.mark.parametrize("seed", [0, 1])
def test_ring_is_the_sorted_faces_at_the_vertices(seed):
    """The moves' compiled ring: every face at any of the vertices, sorted, each once."""
    rng = np.random.default_rng(seed)
    G = np.stack([rng.choice(60, 3, replace=False) for _ in range(200)])
    order = np.argsort(G.reshape(-1), kind="stable")
    start = np.searchsorted(G.reshape(-1)[order], np.arange(61))
    face = order // 3
    for _ in range(30):
        verts = rng.choice(60, rng.integers(1, 5), replace=False)
        want = np.flatnonzero(np.isin(G, verts).any(1))
        np.testing.assert_array_equal(_moves._ring(start, face, verts.astype(np.int64)), want)
    assert len(_moves._ring(start, face, np.zeros(0, np.int64))) == 0


def _random_triangles(n, seed):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(3 * n, 3))
    X[2::3] = X[0::3] + rng.uniform(0.0, 1.0, (n, 1)) * (X[1::3] - X[0::3]) + 0.05 * rng.normal(size=(n, 3))
    return X, np.arange(3 * n).reshape(n, 3)  # thin ones among them: the third corner near the first edge


@pytest.mark.parametrize("seed", range(3))
def test_min_cos_is_the_smallest_angles_cosine(seed):
    X, G = _random_triangles(500, seed)
    got = _slivers._min_cos(X, G, np.arange(len(G)))
    np.testing.assert_allclose(got, np.cos(_angles(X[G]).min(1)), rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_apex_makes_an_equilateral_triangle_in_the_faces_plane(seed):
    X, G = _random_triangles(200, seed)
    for g in range(len(G)):
        v, p, q = G[g]
        Y = X.copy()
        Y[v] = X[v] + _slivers._apex(X, G, g, v)
        e = np.linalg.norm(X[q] - X[p])
        np.testing.assert_allclose([np.linalg.norm(Y[v] - X[p]), np.linalg.norm(Y[v] - X[q])], [e, e], rtol=1e-9)
        n = np.cross(X[p] - X[v], X[q] - X[v])
        assert abs(np.dot(Y[v] - X[v], n)) <= 1e-9 * np.linalg.norm(n) * (1 + e)  # in the face's plane
        # on v's side of the edge pq: the face keeps its orientation
        assert np.dot(np.cross(X[p] - Y[v], X[q] - Y[v]), n) > 0


def test_tangential_is_the_neighbours_mean_in_the_normals_plane():
    rng = np.random.default_rng(5)
    m = qemjax.shapes.bumpy_sphere(2, seed=1)
    X, G = np.array(m.vertices, float), np.array(m.faces)
    X += 0.01 * rng.normal(size=X.shape)
    for v in rng.choice(len(X), 20, replace=False):
        R = np.flatnonzero(np.any(G == v, axis=1))
        others = G[R][G[R] != v]
        n = np.cross(X[G[R, 1]] - X[G[R, 0]], X[G[R, 2]] - X[G[R, 0]]).sum(0)
        n /= np.linalg.norm(n)
        d = X[others].mean(0) - X[v]
        np.testing.assert_allclose(_slivers._tangential(X, G, R, v), d - np.dot(d, n) * n, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_fix_step_is_the_least_step_that_reaches_the_target_angle(seed):
    X, G = _random_triangles(300, seed)
    for g in range(len(G)):
        v = G[g, 0]
        delta = _slivers._apex(X, G, g, v)
        t = _slivers._fix_step(X, G, g, v, delta, _slivers.COS_TARGET)
        Y = X.copy()
        target = np.radians(_slivers.TARGET_DEG)
        if t == 0:
            Y[v] = X[v] + delta
            assert _angles(Y[G[g]][None]).min() < target + 1e-9
            continue
        Y[v] = X[v] + t * delta
        assert _angles(Y[G[g]][None]).min() >= target - 1e-6
        if t > 1e-6:  # a step a little shorter stays short of the target (the angle rises along the way)
            Y[v] = X[v] + (t - 1e-6) * delta
            assert _angles(Y[G[g]][None]).min() <= target + 1e-6


def _mesh(seed):
    """Where slivers form: a torus with noise (even seeds) or a bumpy sphere (odd ones)."""
    rng = np.random.default_rng(seed)
    if seed % 2 == 0:
        m = qemjax.shapes.torus()
        return np.array(m.vertices, float) + 0.005 * rng.normal(size=(len(m.vertices), 3)), np.array(m.faces)
    m = qemjax.shapes.bumpy_sphere(4, amplitude=0.15, seed=seed)
    return np.array(m.vertices, float), np.array(m.faces)


def _run(V, F, target, moves):
    return qemjax.simplify((V, F), target_faces=target, quality_threshold=0.0, sliver_moves=moves)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("target", [150, 400])
def test_sliver_moves_lower_the_slivers_and_keep_the_distance(seed, target):
    V, F = _mesh(seed)
    plain = _run(V, F, target, 0)
    done = _run(V, F, target, 4096)
    assert np.array_equal(done.faces, plain.faces)
    assert_valid(done, target, V, F)
    assert np.all(_turn(plain.vertices, done.vertices, done.faces) < 90.0)
    s0 = triangle_quality(plain)["sliver_fraction"]
    s1 = triangle_quality(done)["sliver_fraction"]
    moved = np.any(done.vertices != plain.vertices, axis=1)
    assert done.stats["sliver_moves"] >= 1 or not moved.any()
    if moved.any():
        assert s1 < s0
    h0, _ = _reference(V, F, plain.vertices, plain.faces)
    h1, r1 = _reference(V, F, done.vertices, done.faces)
    _, r_fit = _reference(V, F, *_refit_only(V, F, target))
    assert h1 <= h0 * (1 + 1e-9)
    assert r1 <= r_fit * (1 + _slivers.RMS_SLACK) * (1 + 1e-9)


def _refit_only(V, F, target):
    r = qemjax.simplify((V, F), target_faces=target, quality_threshold=0.0, polish=0, sliver_moves=0)
    return r.vertices, r.faces


def test_sliver_moves_fix_most_slivers_of_random_meshes():
    """Over noisy tori and bumpy spheres, at least half of the slivers the polish leaves are fixed."""
    before = after = 0
    for seed in range(4):
        V, F = _mesh(seed)
        for target in (150, 400):
            before += round(triangle_quality(_run(V, F, target, 0))["sliver_fraction"] * target)
            after += round(triangle_quality(_run(V, F, target, 4096))["sliver_fraction"] * target)
    assert before >= 5 and after <= before / 2


def test_fixed_vertices_stay_bit_for_bit():
    V, F = _mesh(0)
    r = qemjax.simplify((V, F), target_faces=400, refit=0, quality_threshold=0.0)
    X, G = r.vertices, r.faces
    free = _refit.refit(V, F, X, G, 1, 0.0, sliver_moves=500)
    fit = _refit.refit(V, F, X, G, 1, 0.0)
    slid = np.flatnonzero(np.any(free != fit, axis=1))  # the vertices the sliver moves move here
    assert len(slid) >= 2
    fixed = np.zeros(len(X), bool)
    fixed[np.flatnonzero(np.any(free != X, axis=1))[::2]] = True
    fixed[slid[::2]] = True  # some of those the moves would take, so the test can fail
    report = {}
    held = _refit.refit(V, F, X, G, 1, 0.0, fixed=fixed, sliver_moves=500, report=report)
    np.testing.assert_array_equal(held[fixed], X[fixed])
    assert report["polish_moves"] == 0 and report["sliver_moves"] >= 1


def test_the_default_moves_slivers():
    """The default (its shape term and sliver moves) leaves fewer slivers on these meshes than with both off."""
    assert qemjax.QEM.default().sliver_moves > 0 and qemjax.QEM().sliver_moves == 0
    on = off = moved = 0
    for seed, target in [(0, 800), (1, 250)]:  # where the shape term alone leaves a sliver to move
        V, F = _mesh(seed)
        a = qemjax.simplify((V, F), target_faces=target)
        b = qemjax.simplify((V, F), target_faces=target, sliver_moves=0, quality_threshold=0.0)
        assert b.stats["sliver_moves"] == 0
        moved += a.stats["sliver_moves"]
        on += triangle_quality(a)["sliver_fraction"]
        off += triangle_quality(b)["sliver_fraction"]
    assert on < off and moved >= 1  # the moves ran, not only the shape term


def test_bad_values_are_refused_and_a_batch_equals_simplify():
    V, F = _mesh(2)
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(ValueError, match="sliver_moves"):
            qemjax.simplify((V, F), target_faces=100, sliver_moves=bad)
    alone = qemjax.simplify((V, F), target_faces=400, sliver_moves=300, quality_threshold=0.0)
    assert alone.stats["sliver_moves"] >= 1
    both = qemjax.simplify_batch((V, F), [dict(target_faces=400, sliver_moves=300, quality_threshold=0.0),
                                          dict(target_faces=400, quality_threshold=0.0)])
    assert np.array_equal(both[0].vertices, alone.vertices) and np.array_equal(both[0].faces, alone.faces)
    assert both[0].stats["sliver_moves"] == alone.stats["sliver_moves"]


def _attempt_reference(m, move, H, lim, shape=None):
    """`moves.Moves.attempt` as numpy expressions, one step after another (the compiled `_trial` stands for
    them): the same answer and the same state after it, bit for bit."""
    X, G, P, w, out, d, e, qw = m.X, m.G, m.P, m.w, m.out, m.d, m.e, m.qw
    verts = np.array(sorted(move), np.int64)
    R = m.ring(verts)
    old = X[verts].copy()
    for v, dv in move.items():
        X[v] = X[v] + dv
    if shape is not None:
        mc = _slivers._min_cos(X, G, R)
        count, worst = int(np.sum(mc > _slivers.COS_SLIVER)), mc.max()
        better = (count < shape[0] and worst <= shape[1]) if shape[2] else (count <= shape[0] and worst < shape[1])
    if (shape is not None and not better) or _moves._refused(X, G, R, m.n0, m.cos_max, m.agreed,
                                                             m.source_normals, m.q0, m.min_quality):
        X[verts] = old
        return False
    _moves._boxes_at(X, G, R, out.B, out.flat)
    m.hit[R] = True
    A = m.by_face.on(m.fa, m.hit, R)
    m.hit[R] = False
    fA = m.fa[A]
    d2A = _moves._own_d2(P, A, X, G, out.flat, fA)
    far = np.flatnonzero(d2A >= H * H)
    below = True
    if len(far):
        f1, e1 = fA[far], d2A[far]
        below = _moves._nearer(P[A[far]], X, G, out.B, out.flat, m.ring(np.unique(G[R])), f1, e1, H)
        fA[far], d2A[far] = f1, e1
    dA = np.sqrt(d2A)
    if below and dA.max(initial=0.0) < H:
        at = m.vrow[verts]
        rows = np.concatenate([at[at >= 0], len(m.used) + (m.nb * R[:, None] + np.arange(m.nb)).reshape(-1)])
        nv = len(rows) - m.nb * len(R)
        QR = np.concatenate([X[m.row_vertex(rows[:nv])], _moves._face_points(X, G, R, _moves.BARY)])
        gR, eR = m.to_input(QR, rows)
        wR = np.concatenate([np.zeros(nv), m.face_weights(R)])
        s_in1 = m.s_in + (_moves._wsum2(w[A], dA) - _moves._wsum2(w[A], d[A]))
        s_out1 = m.s_out + (_moves._wsum2(wR, eR) - _moves._wsum2(qw[rows], e[rows]))
        sq1 = m.sq + (_moves._wsum2(wR, np.ones(len(wR))) - _moves._wsum2(qw[rows], np.ones(len(rows))))
        if eR.max(initial=0.0) < H and sq1 > 0 and s_in1 / m.sw + s_out1 / sq1 <= lim:
            m.made += 1
            m.fa[A], d[A], m.version[A] = fA, dA, -1
            m.by_face.set(m.fa, A)
            m.Q[rows], m.ga[rows], e[rows], qw[rows] = QR, gR, eR, wR
            m.s_in, m.s_out, m.sq = s_in1, s_out1, sq1
            out.mark(X, R)
            return True
    X[verts] = old
    _moves._boxes_at(X, G, R, out.B, out.flat)
    return False


def _captured_moves(monkeypatch, V, F, target):
    """The `Moves` a run's sliver moves start from."""
    import copy

    got = []
    monkeypatch.setattr(_slivers, "lift_slivers", lambda m, moves: got.append(copy.deepcopy(m)) or 0)
    qemjax.simplify((V, F), target_faces=target, quality_threshold=0.0)
    return got[0]


@pytest.mark.parametrize("seed", range(3))
def test_the_compiled_move_trial_answers_as_the_numpy_steps(monkeypatch, seed):
    """`Moves.attempt` (one compiled trial, `moves._trial`) against the numpy steps it replaced: random moves
    of one or two vertices, small and large, with and without the sliver test, accepted and refused; the
    answer and every kept array after each move, bit for bit, through the output structure's rebuilds."""
    import copy

    V, F = _mesh(seed)
    m = _captured_moves(monkeypatch, V, F, 200)
    assert m.ok
    monkeypatch.setattr(m.out, "limit", 4)  # built again every few moves
    ref = copy.deepcopy(m)
    rng = np.random.default_rng(seed)
    scale = np.median(np.linalg.norm(m.X[m.G[:, 1]] - m.X[m.G[:, 0]], axis=1))
    H = m.worst()[2]
    ref.worst()
    lim = m.limit(0.05)
    answers = []
    for _ in range(300):
        free = np.flatnonzero(m.free)
        verts = rng.choice(free, int(rng.integers(1, 3)), replace=False)
        move = {int(v): rng.normal(size=3) * scale * rng.choice([0.01, 0.1, 0.5]) for v in verts}
        shape = None
        if rng.random() < 0.5:
            R = m.ring(np.array(sorted(move)))
            mc = _slivers._min_cos(m.X, m.G, R)
            shape = (int(np.sum(mc > _slivers.COS_SLIVER)) + int(rng.integers(0, 2)), mc.max() + 0.05,
                     bool(rng.random() < 0.5))
        h = H * rng.choice([0.5, 1.0, 2.0])
        want = _attempt_reference(ref, {v: s.copy() for v, s in move.items()}, h, lim, shape)
        got = m.attempt({v: s.copy() for v, s in move.items()}, h, lim, shape)
        answers.append(got)
        assert got == want
        for name in ("X", "fa", "d", "version", "Q", "ga", "e", "qw"):
            assert getattr(m, name).tobytes() == getattr(ref, name).tobytes(), name
        assert (m.s_in, m.s_out, m.sq, m.made) == (ref.s_in, ref.s_out, ref.sq, ref.made)
        assert m.out.B.tobytes() == ref.out.B.tobytes() and m.out.flat.tobytes() == ref.out.flat.tobytes()
    assert 10 <= sum(answers) <= 290  # both answers seen often
    # the input point nearest a step (`moves._onto`) against the numpy path it replaced
    for x in m.X[rng.choice(len(m.X), 50)] + rng.normal(size=(50, 3)) * scale:
        g, _ = _moves.query_here(m.V, m.F, m.into, x[None], m.no_seed)
        b = _moves._barycentric_at(x[None], m.V, m.F, g.astype(np.int32), m.into[1])[0]
        t = m.F[g[0]]
        assert m.onto_input(x).tobytes() == ((b[0] * m.V[t[0]] + b[1] * m.V[t[1]]) + b[2] * m.V[t[2]]).tobytes()


def _candidates_reference(m, g):
    """The sliver moves' candidates as Python built them before `slivers._candidates` was compiled."""
    X, G = m.X, m.G
    out, rings = [], {}
    for v in G[g]:
        if not m.free[v]:
            continue
        R = rings[int(v)] = m.ring([v])
        for delta, weak in ((_slivers._apex(X, G, g, v), _slivers.WEAK_STEPS[0]),
                            (_slivers._tangential(X, G, R, v), _slivers.WEAK_STEPS[1])):
            t = _slivers._fix_step(X, G, g, v, delta, _slivers.COS_TARGET)
            if t > 0:
                out.append((t * np.sqrt((delta[0] * delta[0] + delta[1] * delta[1]) + delta[2] * delta[2]),
                            int(v), t * delta, True))
            out += [(np.inf, int(v), s * delta, False) for s in weak]
    out.sort(key=lambda c: (not c[3], c[0]))
    return out, rings


def _lift_reference(m, moves):
    """`slivers.lift_slivers` as a Python loop of `Moves.attempt`, one try at a time (before its tries were
    compiled, `slivers._try_sliver`)."""
    X, G = m.X, m.G
    start = m.made
    H = m.worst()[2]
    lim = m.limit(_slivers.RMS_SLACK)
    stamp = np.full(len(X), -1, np.int64)
    tried = np.full(len(G), -2, np.int64)
    for _ in range(_slivers.PASSES):
        mc = _slivers._min_cos(X, G, np.arange(len(G)))
        bad = np.flatnonzero(mc > _slivers.COS_SLIVER)
        bad = bad[np.argsort(-mc[bad], kind="stable")]
        before = m.made
        for g in bad:
            if m.made - start >= moves:
                return m.made - start
            if _slivers._min_cos(X, G, np.array([g]))[0] <= _slivers.COS_SLIVER:
                continue
            if stamp[G[m.ring(G[g])]].max() <= tried[g]:
                continue
            tried[g] = m.made
            tries, rings = _candidates_reference(m, g)
            for _, v, step, strict in tries[:_slivers.TRIES]:
                x1 = m.onto_input(X[v] + step)
                if m.attempt({v: x1 - X[v]}, H, lim, (*_moves.shape_of(X, G, rings[v]), strict), rings[v]):
                    stamp[v] = m.made
                    break
        if m.made == before:
            break
    return m.made - start


@pytest.mark.parametrize("seed", range(3))
def test_the_compiled_sliver_tries_move_as_the_python_loop(monkeypatch, seed):
    """`lift_slivers` (each sliver's tries compiled: `slivers._try_sliver`, its candidates `_candidates`)
    against the Python loop of `Moves.attempt` it replaced: the same moves made, every kept array the same
    bits, through the output structure's rebuilds; the candidates themselves alike on every sliver."""
    import copy

    lift = _slivers.lift_slivers  # before `_captured_moves` patches it
    V, F = _mesh(seed)
    m = _captured_moves(monkeypatch, V, F, 200)
    assert m.ok
    monkeypatch.setattr(m.out, "limit", 4)  # built again every few moves
    bad = np.flatnonzero(_slivers._min_cos(m.X, m.G, np.arange(len(m.G))) > _slivers.COS_SLIVER)
    assert len(bad) >= 1
    for g in bad:
        want, _ = _candidates_reference(m, g)
        corner, step, strict = _slivers._candidates(m.X, m.G, g, m.free, m.ring_start, m.ring_face)
        assert [(v, s) for _, v, _, s in want] == list(zip(corner.tolist(), strict.tolist()))
        assert np.array([c[2] for c in want]).reshape(-1, 3).tobytes() == step.tobytes()
    ref = copy.deepcopy(m)
    made = lift(m, 10_000)
    assert made == _lift_reference(ref, 10_000) and made >= 1
    for name in ("X", "fa", "d", "version", "Q", "ga", "e", "qw"):
        assert getattr(m, name).tobytes() == getattr(ref, name).tobytes(), name
    assert (m.s_in, m.s_out, m.sq, m.made) == (ref.s_in, ref.s_out, ref.sq, ref.made)
