"""Memoryless quadrics (``simplify(memoryless=True)``, `qemjax._costs.memoryless`): the rebuilt state
against float64 references, the volume term's kernel against a float64 evaluation, end-to-end validity,
no recompilation for new numbers, and clear errors for bad options."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_valid

import qemjax
from qemjax._kernels import compilation as _compilation
from qemjax import shapes
from qemjax._mesh import topology as topo
from qemjax._costs import memoryless as ml
from qemjax._costs.base import MeshInput, MeshView
from qemjax._costs.qem import QEM
from qemjax._mesh.incidence import FaceLists


def random_mesh(seed: int):
    """A jittered grid with holes (boundaries, irregular stars) at unit extent, and a closed bumpy sphere."""
    rng = np.random.default_rng(seed)
    V, F = shapes.grid(12, hole=True)
    V = V + rng.normal(scale=0.02, size=V.shape) * [1, 1, 3]
    S, G = shapes.icosphere(2)
    S = S * (1 + 0.1 * rng.random((len(S), 1)))
    V = np.concatenate([V, S * 0.3 + 2.0])
    F = np.concatenate([F, G + len(V) - len(S)])
    V = (V - V.min(0)) / np.max(V.max(0) - V.min(0))
    return V, F


def reference_rows(V, F, alive, verts, *, area_power, boundary_weight, mean_area, mean_e2):
    """Float64, one vertex and one face at a time: each vertex's quadric as a function (a list of weighted
    planes n·(x − v) = 0 with unit n), and g(v). Boundary edges: edges in one live face of the whole mesh."""
    live = F[alive]
    count = {}
    for f in live:
        for j in range(3):
            e = tuple(sorted((int(f[j]), int(f[(j + 1) % 3]))))
            count[e] = count.get(e, 0) + 1
    out = []
    for v in verts:
        planes, g = [], np.zeros(3)
        for f in live:
            if v not in f:
                continue
            j = list(f).index(v)
            a, b, c = V[f[j]], V[f[(j + 1) % 3]], V[f[(j + 2) % 3]]
            cr = np.cross(b - a, c - a)
            area = 0.5 * np.linalg.norm(cr)
            g += 0.5 * cr
            if area == 0:
                continue
            n = cr / (2 * area)
            planes.append((n, (area / mean_area) ** area_power))
            for other in (f[(j + 1) % 3], f[(j + 2) % 3]):
                if boundary_weight > 0 and count[tuple(sorted((int(v), int(other))))] == 1:
                    e = V[other] - a
                    m = np.cross(e, n)
                    planes.append((m / np.linalg.norm(m), boundary_weight * (e @ e / mean_e2) ** area_power))
        out.append((planes, g))
    return out


def evaluate_packed(q, u):
    a00, a01, a02, a11, a12, a22, b0, b1, b2, c = q
    A = np.array([[a00, a01, a02], [a01, a11, a12], [a02, a12, a22]])
    return u @ A @ u + 2 * u @ np.array([b0, b1, b2]) + c


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("area_power,boundary_weight", [(1.0, 100.0), (0.0, 1.0), (0.5, 0.0), (2.0, 10.0)])
def test_refresh_matches_a_float64_reference(seed, area_power, boundary_weight):
    """After faces die, `refresh` rebuilds the quadric of each vertex from its live faces: its value at
    random points equals the weighted squared distances to the reference's planes, and g matches."""
    V, F = random_mesh(seed)
    rng = np.random.default_rng(100 + seed)
    faces = FaceLists(F, len(V))
    dead = rng.choice(len(F), size=len(F) // 5, replace=False)
    faces.remove(dead)
    alive = np.ones(len(F), bool)
    alive[dead] = False
    mean_area, mean_e2 = 0.003, 0.005
    model = QEM(memoryless=True, area_power=area_power, boundary_weight=boundary_weight)
    rows = np.zeros((len(V), 3 + ml.WIDTH), np.float32)
    rows[:, :3] = V
    rows[:, 3:13] = rng.random((len(V), 10))  # history quadrics: kept as they are
    rows[:, 13:23] = -1.0  # a stale current quadric: rebuilt
    rows[:, ml.MCOLS[0]:] = [mean_area, mean_e2]
    verts = rng.choice(len(V), size=60, replace=False)
    got = np.asarray(model.refresh(MeshView(faces, rows), verts), np.float64)
    assert got.shape == (60, ml.WIDTH)
    np.testing.assert_array_equal(got[:, :10], rows[verts, 3:13])
    np.testing.assert_allclose(got[:, 23:], np.tile([mean_area, mean_e2], (60, 1)), rtol=1e-6)
    ref = reference_rows(rows[:, :3].astype(np.float64), F, alive, verts, area_power=area_power,
                         boundary_weight=boundary_weight, mean_area=mean_area, mean_e2=mean_e2)
    for row, (planes, g) in zip(got, ref):
        np.testing.assert_allclose(row[20:23], g, rtol=1e-5, atol=1e-9)
        for _ in range(3):
            u = rng.normal(size=3) * 0.05
            want = sum(w * (n @ u) ** 2 for n, w in planes)
            assert evaluate_packed(row[10:20], u) == pytest.approx(want, rel=1e-4, abs=1e-12)  # float32 storage


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("area_power,boundary_weight", [(1.0, 100.0), (0.0, 1.0), (0.6, 10.0), (0.37, 0.0)])
def test_compiled_rebuild_is_the_numpy_one_bit_for_bit(seed, area_power, boundary_weight):
    """`current_quadrics` (compiled, `current_sums.rebuild`) gives its numpy twin's bits
    (tests/reference_memoryless.py) after faces die and vertices are contracted, with vertices named twice,
    vertices with no live face and one vertex with more faces than the compiled ring buffer starts with."""
    from reference_memoryless import current_quadrics_numpy

    V, F = random_mesh(seed)
    rng = np.random.default_rng(200 + seed)
    # a fan of 80 faces around one extra vertex (more than the ring buffer's first 64)
    t = np.linspace(0, 2 * np.pi, 81)[:-1]
    fan = np.c_[np.cos(t), np.sin(t), 0.1 * rng.random(80)] * 0.2 + [3.0, 0.0, 0.0]
    hub = len(V) + len(fan)
    ring = np.arange(len(V), len(V) + len(fan))
    F = np.concatenate([F, np.c_[ring, np.roll(ring, -1), np.full(80, hub)]])
    V = np.concatenate([V, fan, [[3.0, 0.0, 0.05]]]) * (1 + 1e-3 * rng.normal(size=(len(V) + 81, 3)))
    faces = FaceLists(F, len(V))
    faces.remove(rng.choice(len(F) - 80, size=len(F) // 6, replace=False))
    live = faces.live()
    near = [set() for _ in range(len(V))]  # each vertex's neighbours
    for f in live:
        for i in range(3):
            near[f[i]].update(int(x) for x in f)
    used, a, b = set(), [], []
    for f in live[::7]:  # pairs no face joins to another pair: their endpoints' neighbourhoods disjoint
        u, w = int(f[0]), int(f[1])
        if u == hub or w == hub or (near[u] | near[w]) & used:
            continue
        used |= near[u] | near[w]
        a.append(u)
        b.append(w)
    a, b = np.array(a, np.int64), np.array(b, np.int64)
    faces.contract(a, b)
    verts = np.r_[rng.choice(len(V), size=120, replace=False), hub, hub, b[:2]].astype(np.int64)
    kw = dict(area_power=area_power, boundary_weight=boundary_weight, mean_area=0.003 * (1 + seed),
              mean_e2=0.005)
    got = ml.current_quadrics(V, faces, verts, **kw)
    want = current_quadrics_numpy(V, faces, verts, **kw)
    assert got.shape == want.shape == (len(verts), 13)
    assert got.tobytes() == want.tobytes()


def test_rows_of_several_runs_in_one_pass_are_each_runs_own():
    """`refresh_rows_each` (a batch's copies side by side) gives, for vertices of copies with different
    weights and input means, the bytes each copy's own model's `refresh` gives its vertices."""
    V, F = random_mesh(4)
    rng = np.random.default_rng(7)
    faces = FaceLists(F, len(V))
    faces.remove(rng.choice(len(F), size=len(F) // 5, replace=False))
    models = [QEM(memoryless=True, area_power=0.6, boundary_weight=1.0),
              QEM(memoryless=True, area_power=1.0, boundary_weight=0.0),
              QEM(memoryless=True, area_weighted=False, boundary_weight=100.0)]
    copy = rng.integers(0, len(models), len(V))  # each vertex's copy
    rows = np.zeros((len(V), 3 + ml.WIDTH), np.float32)
    rows[:, :3] = V
    rows[:, 3:13] = rng.random((len(V), 10))
    rows[:, ml.MCOLS[0]:] = np.array([[0.003, 0.005], [0.002, 0.004], [0.01, 0.02]], np.float32)[copy]
    view = MeshView(faces, rows)
    verts = rng.permutation(len(V))[:90]
    w = np.array([ml.weights(m) for m in models]).T
    got = ml.refresh_rows_each(w[0][copy[verts]], w[1][copy[verts]], view, verts)
    for c, m in enumerate(models):
        mine = copy[verts] == c
        assert mine.any() and got[mine].tobytes() == m.refresh(view, verts[mine]).tobytes()
    assert ml.refresh_rows_each(w[0][:0], w[1][:0], view, verts[:0]).shape == (0, ml.WIDTH)


def test_initial_state_is_the_default_quadrics_plus_g_and_means():
    """The memoryless start (a rebuild at every vertex, float64 on the host) agrees with the default's
    initial quadrics (the float32 kernel), as history and as current quadric, and carries g and the
    input means."""
    V, F = random_mesh(3)
    V = V.astype(np.float32)
    means = (0.004, 0.006)
    mesh = MeshInput(V, F.astype(np.int64), topo.boundary_edges(F, len(V)), None, means)
    base = QEM().init_state(mesh)
    rows = QEM(memoryless=True).init_state(mesh)
    assert rows.shape == (len(V), ml.WIDTH) and rows.dtype == np.float32
    scale = np.abs(base).max()
    np.testing.assert_allclose(rows[:, :10], base, atol=1e-5 * scale)
    np.testing.assert_array_equal(rows[:, 10:20], rows[:, :10])
    assert np.all(rows[:, 23:] == np.float32(means))
    ref = reference_rows(V.astype(np.float64), F, np.ones(len(F), bool), range(5), area_power=1.0,
                         boundary_weight=100.0, mean_area=means[0], mean_e2=means[1])
    np.testing.assert_allclose(rows[:5, 20:23], [g for _, g in ref], rtol=1e-5, atol=1e-9)
    with pytest.raises(ValueError, match="feature"):
        QEM(memoryless=True).init_state(mesh._replace(feature_edges=np.array([[0, 1]])))


def random_rows(rng, k):
    """k pairs of memoryless rows: positions, positive semi-definite history and current quadrics (sums of
    planes; the history with b, c of planes off the vertex), g, means."""
    rows = np.zeros((2 * k, 3 + ml.WIDTH))
    rows[:, :3] = rng.normal(size=(2 * k, 3))
    rows[k:, :3] = rows[:k, :3] + 0.1 * rng.normal(size=(k, 3))
    for i in range(2 * k):
        for col, off in ((3, 0.1), (13, 0.0)):
            A, b, c = np.zeros((3, 3)), np.zeros(3), 0.0
            for n, w in zip(rng.normal(size=(4, 3)), rng.random(4)):
                n = n / np.linalg.norm(n)
                d = off * rng.normal()  # plane n·u = d
                A, b, c = A + w * np.outer(n, n), b - w * d * n, c + w * d * d
            rows[i, col:col + 6] = A[np.triu_indices(3)]
            rows[i, col + 6:col + 9], rows[i, col + 9] = b, c
    rows[:, 23:26] = 0.3 * rng.normal(size=(2 * k, 3))
    rows[:, 26:] = [0.05, 0.1]
    return rows.astype(np.float32), np.stack([np.arange(k), np.arange(k) + k], 1).astype(np.int32)


@pytest.mark.parametrize("placement", ["optimal", "rank"])
def test_volume_term_kernel_against_float64(placement):
    """The memoryless price: its cost at its x equals, in float64, C1(x − p1) + C2(x − p2) + μ·(H1(x − p1)
    + H2(x − p2)) + λ·((g1·(x − p1) + g2·(x − p2)) / mean area)² (C current, H history quadrics), and
    where it solved, x minimises that in float64. With λ = μ = 0 it places exactly as the plain QEM
    kernel does on rows [position, current quadric] (to float32 rounding: the kernels fuse differently)."""
    rng = np.random.default_rng(7)
    VS, pairs = random_rows(rng, 64)
    lam, mu = 0.7, 0.3
    model = QEM(memoryless=True, volume_weight=lam, memory_weight=mu, placement=placement)
    out = np.asarray(model.price(VS, pairs, model.kernel_params()), np.float64)
    R = VS.astype(np.float64)
    n_solved = 0
    for k, (i, j) in enumerate(pairs):
        x = out[:3, k]
        p1, p2, g1, g2, ma = R[i, :3], R[j, :3], R[i, 23:26], R[j, 23:26], R[i, 26]

        def f(y):
            s = (g1 @ (y - p1) + g2 @ (y - p2)) / ma
            return (evaluate_packed(R[i, 13:23], y - p1) + evaluate_packed(R[j, 13:23], y - p2)
                    + mu * (evaluate_packed(R[i, 3:13], y - p1) + evaluate_packed(R[j, 3:13], y - p2))
                    + lam * s * s)

        assert out[3, k] == pytest.approx(f(x), rel=2e-3, abs=1e-6)
        if out[4, k] == 0:  # the full solve: f is minimal there (f is quadratic: solve its gradient)
            n_solved += 1
            e = np.eye(3)
            f0 = f(p1)
            grad = np.array([(f(p1 + e[a]) - f(p1 - e[a])) / 2 for a in range(3)])
            H = np.array([[f(p1 + e[a] + e[b]) - f(p1 + e[a]) - f(p1 + e[b]) + f0 for b in range(3)]
                          for a in range(3)])
            x64 = p1 - np.linalg.solve(H, grad)
            assert f(x) <= f(x64) * (1 + 1e-3) + 1e-7
    assert n_solved > 10
    plain = QEM(placement=placement)
    zero = QEM(memoryless=True, placement=placement)
    a = np.asarray(zero.price(VS, pairs, zero.kernel_params()))
    b = np.asarray(plain.price(np.ascontiguousarray(np.concatenate([VS[:, :3], VS[:, 13:23]], 1)), pairs,
                               plain.kernel_params()))
    assert np.mean(a[4] == b[4]) > 0.95  # the same branches (up to float32 rounding at a threshold)
    same = a[4] == b[4]
    np.testing.assert_allclose(a[:4, same], b[:4, same], rtol=1e-4, atol=1e-6)  # other fusions: other roundings
    assert not np.allclose(out[:3], a[:3])  # the terms move the placements


@pytest.mark.parametrize("scheduler", ["parallel", "greedy"])
@pytest.mark.parametrize("make,target,differs", [(lambda: shapes.bumpy_sphere(3), 300, True),
                                                 (lambda: shapes.grid(16, hole=True), 150, False)])
def test_memoryless_runs_differ_and_stay_valid(make, target, differs, scheduler):
    """Valid results with the exact face count, both schedulers; on a curved surface another result than
    the default's (a flat grid with a hole has zero costs inside either way, so only validity there)."""
    V, F = make()
    base = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler)
    for kw in (dict(memoryless=True), dict(memoryless=True, volume_weight=0.5, placement="rank"),
               dict(memoryless=True, memory_weight=0.3)):
        r = qemjax.simplify((V, F), target_faces=target, scheduler=scheduler, **kw)
        assert_valid(r, target, V, F)
        assert r.stats["model"]["memoryless"] is True
        assert r.vertex_error.shape == (len(r.vertices),) and np.all(r.vertex_error >= 0)
        if differs:
            assert len(r.vertices) != len(base.vertices) or not np.array_equal(r.vertices, base.vertices)


def test_memoryless_keeps_a_grid_flat_and_its_border():
    """On a flat grid every memoryless quadric is a plane through the grid (and the border planes): the
    result stays flat and the border's outline stays a square."""
    V, F = shapes.grid(20)
    r = qemjax.simplify((V, F), target_faces=60, memoryless=True)
    assert_valid(r, 60, V, F)
    assert np.all(np.abs(r.vertices[:, 2]) < 1e-6)
    np.testing.assert_allclose(r.vertices[:, :2].min(0), V[:, :2].min(0), atol=1e-6)
    np.testing.assert_allclose(r.vertices[:, :2].max(0), V[:, :2].max(0), atol=1e-6)


def test_new_numbers_do_not_recompile():
    """After one memoryless run, other volume_weight, boundary_weight and area_power values compile
    nothing (they are arrays or host numbers)."""
    V, F = shapes.bumpy_sphere(3)
    qemjax.simplify((V, F), target_faces=400, memoryless=True, volume_weight=0.1)
    r = qemjax.simplify((V, F), target_faces=400, memoryless=True, volume_weight=3.0, boundary_weight=7.0,
                        area_power=0.5, memory_weight=0.2)
    assert r.stats["compilations"] == 0, r.stats["compilations"]
    c0, _ = _compilation.snapshot()
    VS, pairs = np.zeros((64, 3 + ml.WIDTH), np.float32), np.zeros((256, 2), np.int32)
    for lam in (0.0, 2.0):
        m = QEM(memoryless=True, volume_weight=lam)
        m.price(VS, pairs, m.kernel_params())
    c1, _ = _compilation.snapshot()
    m = QEM(memoryless=True, volume_weight=5.0, memory_weight=1.0)
    m.price(VS, pairs, m.kernel_params())
    assert _compilation.snapshot()[0] == c1 >= c0


@pytest.mark.parametrize("kw,match", [
    (dict(memoryless="yes"), "memoryless must be True or False"),
    (dict(memoryless=True, volume_weight=-1.0), "volume_weight must be finite"),
    (dict(memoryless=True, volume_weight=float("nan")), "volume_weight must be finite"),
    (dict(volume_weight=1.0, late_memoryless=0), "needs memoryless=True"),
    (dict(memory_weight=1.0), "needs memoryless=True"),
    (dict(memoryless=True, memory_weight=-0.5), "memory_weight must be finite"),
    (dict(memoryless=True, method="area"), "memoryless is not a setting of method 'area'"),
    (dict(memoryless=True, method="esqem"), "method='qem' only"),
    (dict(memoryless=True, regularize=0.5), "method='qem' only"),
    (dict(memoryless=True, feature_edges=np.array([[0, 1]])), "feature"),
    # the placement's limits (they were taken as given: NaN sent every pair to an endpoint)
    (dict(cond_eps=float("nan")), "cond_eps must be finite"),
    (dict(cond_eps=-1.0), "cond_eps must be finite"),
    (dict(placement="rank", rank_eps=float("inf")), "rank_eps must be finite"),
    (dict(max_shift=-1.0), "max_shift must be finite"),
    (dict(method="esqem", max_shift=float("nan")), "max_shift must be finite"),
])
def test_bad_options_raise(kw, match):
    V, F = shapes.icosphere(2)
    with pytest.raises(ValueError, match=match):
        qemjax.simplify((V, F), target_faces=100, **kw)


def test_default_model_is_unchanged():
    """memoryless=False keeps QEM as it was: 10 state floats, pair support, no refresh, no volume param."""
    m = QEM()
    assert m.width == 10 and m.support == "pair" and m.refresh is None
    assert "volume_weight" not in m.kernel_params() and "memory_weight" not in m.kernel_params()
    q = QEM(memoryless=True)
    assert q.width == ml.WIDTH and q.support == "ring" and q.refresh is not None
