"""``simplify(refit=N)`` (`qemjax._pipeline.refit`): the output's positions re-fitted to the input surface lower the
distance to it, change nothing but the positions, never turn a face by the flip angle, and bad values are
refused."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_valid

import qemjax
from qemjax._pipeline import fit_rules as _rules
from qemjax._pipeline import refit as _refit
from qemjax import shapes
from qemjax._mesh.arrays import face_normals
from qemjax.metrics import point_triangle_distance, surface_distance


@pytest.fixture(scope="module")
def bumpy():
    return shapes.bumpy_sphere(4)


def test_closest_barycentric_gives_the_exact_distance():
    rng = np.random.default_rng(0)
    p, a, b, c = (rng.normal(size=(2000, 3)) for _ in range(4))
    c[:200] = a[:200] + 1e-3 * rng.normal(size=(200, 3))  # thin triangles too
    b[200:300] = a[200:300]  # segments: two corners at one point, each pair of them
    c[300:400] = a[300:400]
    c[400:500] = b[400:500]
    b[500:550] = c[500:550] = a[500:550]  # a point
    c[550:600] = a[550:600] + 0.3 * (b[550:600] - a[550:600])  # collinear corners
    c[600:650] = a[600:650] + 1.7 * (b[600:650] - a[600:650])
    B = _rules.closest_barycentric(p, a, b, c)
    assert np.all(B >= -1e-12) and np.allclose(B.sum(1), 1.0)
    x = B[:, :1] * a + B[:, 1:2] * b + B[:, 2:] * c
    np.testing.assert_allclose(np.linalg.norm(p - x, axis=1), point_triangle_distance(p, a, b, c),
                               rtol=1e-7, atol=1e-9)



def _dot3(x, y):
    """Row dot products summed (x0·y0 + x2·y2) + x1·y1: the order numpy 2.4's einsum("ij,ij->i") took on
    C-ordered (q,3) rows, which made the golden outputs; written out, so the reference does not depend on a
    numpy build's einsum."""
    return (x[:, 0] * y[:, 0] + x[:, 2] * y[:, 2]) + x[:, 1] * y[:, 1]


def _numpy_regions(p, a, b, c):
    """Ericson's regions in numpy's whole-array arithmetic (np.select, np.nan_to_num): the re-fit's
    coordinates as they were made before they were compiled."""
    ab, ac = b - a, c - a
    d1, d2 = _dot3(ab, p - a), _dot3(ac, p - a)
    d3, d4 = _dot3(ab, p - b), _dot3(ac, p - b)
    d5, d6 = _dot3(ab, p - c), _dot3(ac, p - c)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    regions = [(d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (d6 >= 0) & (d5 <= d6),
               (vc <= 0) & (d1 >= 0) & (d3 <= 0), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
               (va <= 0) & (d4 >= d3) & (d5 >= d6)]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = np.nan_to_num(d1 / (d1 - d3))
        t_ac = np.nan_to_num(d2 / (d2 - d6))
        t_bc = np.nan_to_num((d4 - d3) / ((d4 - d3) + (d5 - d6)))
        den = va + vb + vc
        den = np.where(den != 0, den, 1.0)
        v, w = vb / den, vc / den
    return np.stack([np.select(regions, [1.0, 0.0, 0.0, 1 - t_ab, 1 - t_ac, 0.0], 1 - v - w),
                     np.select(regions, [0.0, 1.0, 0.0, t_ab, 0.0, 1 - t_bc], v),
                     np.select(regions, [0.0, 0.0, 1.0, 0.0, t_ac, t_bc], w)], 1)


@pytest.mark.parametrize("seed", range(3))
def test_the_compiled_regions_are_numpys_arithmetic_bit_for_bit(seed):
    """`refit_system.regions` against numpy's whole-array arithmetic (float64): every bit, signed zeros
    included, on random faces with repeated corners, points at corners and coordinates on a coarse grid
    (exact ties and zeros)."""
    from qemjax._pipeline.refit_system import regions

    rng = np.random.default_rng(seed)
    q, k, j = 50_000, 800, 1500
    X = rng.normal(size=(k, 3)) * 10.0 ** rng.uniform(-3, 3)
    G = rng.integers(0, k, size=(j, 3))  # some faces repeat a corner: the guards against 0/0
    f = rng.integers(0, j, q)
    P = rng.normal(size=(q, 3)) * X.std()
    P[:2000] = X[G[f[:2000], 0]]
    P[2000:4000] = X[G[f[2000:4000], 1]]
    if seed == 1:
        X, P = np.round(X, 1), np.round(P, 1)
    tri = G[f]
    want = _numpy_regions(P, X[tri[:, 0]], X[tri[:, 1]], X[tri[:, 2]])
    got = np.empty((q, 3))
    regions(P, X, G, f, got)
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def _reference_system(Ps, sw, X, G, f, free, lam):
    """The re-fit's normal equations N = AᵀA + λI and R = Aᵀt in plain numpy, every entry's terms added in
    sample order (np.add.at adds in index order; the indices run sample by sample), as scipy's sparse products
    added them before: A's rows are the samples' weighted barycentric coordinates in their face's corners'
    columns, t the samples times their weights, less the locked corners' share (in ascending vertex order).
    N as CSR: the off-diagonal entries that summed to exactly zero left out."""
    q = len(Ps)
    tri = G[f]
    B = _rules.closest_barycentric(Ps, X[tri[:, 0]], X[tri[:, 1]], X[tri[:, 2]]) * sw[:, None]
    col = np.where(free, np.cumsum(free) - 1, -1)
    k = int(free.sum())
    target = Ps * sw[:, None]
    order = np.argsort(tri, axis=1, kind="stable")
    shift = np.zeros((q, 3))
    for v, b in zip(np.take_along_axis(tri, order, 1).T, np.take_along_axis(B, order, 1).T):
        held = ~free[v]
        shift[held] += b[held, None] * X[v[held]]
    target = target - shift
    rows, cols = np.broadcast_to(col[tri][:, :, None], (q, 3, 3)), np.broadcast_to(col[tri][:, None, :], (q, 3, 3))
    vals = B[:, :, None] * B[:, None, :]
    keep = (rows >= 0) & (cols >= 0)
    N = np.zeros((k, k))
    np.add.at(N, (rows[keep], cols[keep]), vals[keep])
    R = np.zeros((k, 3))
    at = col[tri] >= 0
    np.add.at(R, col[tri][at], (B[:, :, None] * target[:, None, :])[at])
    N[np.arange(k), np.arange(k)] += lam
    present = (N != 0) | np.eye(k, dtype=bool)
    indptr = np.concatenate([[0], np.cumsum(present.sum(1))])
    return indptr, np.nonzero(present)[1], N[present], R


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_normal_equations_are_the_sums_in_sample_order_bit_for_bit(seed):
    """`refit_system` against AᵀA + λI and Aᵀt summed in sample order in numpy (float64, random samples on a
    random mesh with vertices in no face, some vertices fixed in two of the cases, blocks of 7 rows): the same
    entries, columns and bits."""
    from qemjax._pipeline.refit_system import layout

    rng = np.random.default_rng(seed)
    k, j, q = 300, 500, 4000
    X = rng.normal(size=(k, 3))
    G = np.array([rng.choice(k - 5, 3, replace=False) for _ in range(j)])  # the last 5 vertices in no face
    f = rng.integers(0, j, q)
    Ps = rng.normal(size=(q, 3))
    Ps[:300] = X[G[f[:300], 0]]  # samples at a corner: zeros among the coordinates
    sw = rng.uniform(0.1, 2.0, q)
    free = np.ones(k, bool) if seed < 2 else rng.random(k) > 0.2
    lam = 1e-3
    want_indptr, want_indices, want_data, want_rhs = _reference_system(Ps, sw, X, G, f, free, lam)
    col = np.where(free, np.cumsum(free) - 1, -1)
    lay = layout(G, col, int(free.sum()))
    rows = _refit._ROWS
    try:
        _refit._ROWS = 7
        N, rhs = _refit._system(Ps, sw, X, G, f, col, lay, lam)
    finally:
        _refit._ROWS = rows
    indptr, indices, data = N
    np.testing.assert_array_equal(indptr, want_indptr)
    np.testing.assert_array_equal(indices, want_indices)
    np.testing.assert_array_equal(data.view(np.int64), want_data.view(np.int64))
    np.testing.assert_array_equal(rhs.view(np.int64), want_rhs.view(np.int64))


@pytest.mark.parametrize("target", [24, 200])
def test_refit_lowers_the_distance_and_keeps_the_connectivity(bumpy, target):
    plain = qemjax.simplify(bumpy, target_faces=target, refit=0)
    fit = qemjax.simplify(bumpy, target_faces=target, refit=3)
    assert np.array_equal(fit.faces, plain.faces) and np.array_equal(fit.source_vertices, plain.source_vertices)
    assert np.array_equal(fit.history.positions, plain.history.positions)
    assert np.array_equal(fit.vertex_error, plain.vertex_error)
    assert not np.array_equal(fit.vertices, plain.vertices)
    assert fit.stats["refit"] == 3 and plain.stats["refit"] == 0
    assert fit.stats["refit_s"] > 0 and plain.stats["refit_s"] == 0
    assert_valid(fit, target, *bumpy)
    d0, d1 = surface_distance(bumpy, (plain.vertices, plain.faces)), surface_distance(bumpy, (fit.vertices, fit.faces))
    assert d1["rms"] < 0.9 * d0["rms"]


def _turn(X0, X1, G):
    """Degrees each face's normal turns from positions X0 to X1."""
    n0, n1 = face_normals(X0, G), face_normals(X1, G)
    cos = np.einsum("ij,ij->i", n0, n1) / (np.linalg.norm(n0, axis=1) * np.linalg.norm(n1, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def test_refit_never_turns_a_face_by_the_flip_angle(bumpy):
    r = qemjax.simplify(bumpy, target_faces=24, refit=0)
    free = _refit.refit(*bumpy, r.vertices, r.faces, 1, cos_max=-2.0)  # no limit
    assert np.count_nonzero(_turn(r.vertices, free, r.faces) >= 3.0) > 0  # so the limit below binds
    held = _refit.refit(*bumpy, r.vertices, r.faces, 1, cos_max=float(np.cos(np.radians(3.0))))
    assert np.all(_turn(r.vertices, held, r.faces) < 3.0)
    assert not np.array_equal(held, r.vertices)  # halved moves, not all undone


@pytest.mark.parametrize("seed", range(4))
def test_samples_are_numpys_arithmetic_bit_for_bit(seed):
    """The compiled samples against numpy's whole-array arithmetic (float64): points, weights, parts."""
    rng = np.random.default_rng(seed)
    n, m = 500, 1200
    V = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-30, 30)
    F = rng.integers(0, n, size=(m, 3))
    F[:100, 1] = F[:100, 0]  # zero areas: those centroids go
    part = rng.integers(0, 4, n).astype(np.int32)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    w = np.concatenate([np.bincount(F.ravel(), weights=np.repeat(area / 3, 3), minlength=n), area])
    P = np.concatenate([V, V[F].sum(1) / 3])
    lab = np.concatenate([part, part[F[:, 0]]])
    keep = w > 0
    got = _refit.samples(V, F, part)
    for have, want in zip(got, (P[keep], w[keep] / w[keep].mean(), lab[keep])):
        np.testing.assert_array_equal(have, want)
        assert have.dtype == want.dtype


def test_samples_attach_to_faces_of_their_own_part():
    """A sample lying on a face of another part is attached to its own part's nearest face (the truck's
    parts pulled each other), and a sample of a part without faces to none."""
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    G = np.array([[0, 1, 2], [3, 4, 5]])
    P = np.array([[0.2, 0.2, 0.0], [0.2, 0.2, 0.95], [0.2, 0.2, 0.5]])
    f = _refit._attach(X, G, np.array([0, 1]), P, np.array([1, 0, 2]))
    assert list(f) == [1, 0, -1]


def test_refit_zero_is_the_plain_run_and_bad_values_are_refused(bumpy):
    """The default with refit=0, no memoryless last stretch, no shape term and classic's two field values is classic (QEM(),
    which has neither); the default's own area_power and boundary_weight give another mesh."""
    a, b = qemjax.simplify(bumpy, ratio=0.1, method="classic"), qemjax.simplify(bumpy, ratio=0.1, refit=0)
    assert not np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.vertices, qemjax.simplify(bumpy, ratio=0.1, area_power=1.0, boundary_weight=100.0,
                                                      refit=0, late_memoryless=0, quality_threshold=0.0).vertices)
    for bad in (-1, 1.5, True, "3"):
        with pytest.raises(ValueError, match="refit"):
            qemjax.simplify(bumpy, ratio=0.1, refit=bad)


def test_refit_in_a_batch_equals_simplify(bumpy):
    alone = qemjax.simplify(bumpy, ratio=0.05, refit=2)
    both = qemjax.simplify_batch(bumpy, [dict(ratio=0.05, refit=2), dict(ratio=0.05)])
    assert np.array_equal(both[0].vertices, alone.vertices) and np.array_equal(both[0].faces, alone.faces)


def test_a_batchs_refits_run_side_by_side_with_the_same_bits(bumpy, monkeypatch):
    """`simplify_cells` leaves each cell's re-fit to `stages.refit_all`, which runs them on a pool of
    threads (with two or more cores): every result equals its `simplify` alone bit for bit, with its own
    ``refit_s``, and the re-fits ran off the calling thread; re-fits of large inputs run one at a time on
    the calling thread, with the same bits. Re-fits to one input share what is made of it alone
    (`refit.InputSide`)."""
    import os
    import threading

    from qemjax._pipeline import stages

    cfgs = [dict(ratio=r) for r in (0.03, 0.05, 0.1, 0.2)] + [dict(ratio=0.05, refit=0)]
    alone = [qemjax.simplify(bumpy, **c) for c in cfgs]
    ran_on, sides, call = [], [], stages.RefitTask.__call__
    monkeypatch.setattr(stages.RefitTask, "__call__", lambda task: (ran_on.append(threading.get_ident()),
                                                                    sides.append(task.side), call(task))[2])
    together = qemjax.simplify_batch(bumpy, cfgs)
    assert together[0].stats["batch"]["size"] == 5 and len(ran_on) == 4  # refit=0: no task
    # one input, one side: its samples and search structure made once for the four
    assert sides[0] is not None and all(side is sides[0] for side in sides)
    for a, b in zip(alone, together):
        assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert all(r.stats["refit_s"] > 0 for r in together[:4]) and together[4].stats["refit_s"] == 0
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    if cores >= 2:
        assert threading.get_ident() not in ran_on
    # re-fits of large inputs run one at a time on the calling thread, with the same bits
    monkeypatch.setattr(stages, "_REFIT_ALONE", 0)
    ran_on.clear()
    again = qemjax.simplify_batch(bumpy, cfgs)
    assert ran_on == [threading.get_ident()] * 4
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(alone, again))


@pytest.mark.parametrize("thread", [False, True])
def test_an_input_side_made_beforehand_gives_the_same_bits(bumpy, thread):
    """`refit.InputSide` (what a partitioned run's last level makes on a thread beside its rounds): the
    re-fit with the polish and sliver moves, its samples and seeds equal those made inside `refit`, bit for
    bit, with one part (a partitioned run's) and with the input's parts (the labels a plain run gives); made
    without the moves' search structure, the moves make their own; an input without extent leaves the
    positions as they are; and an error making it is raised where the re-fit asks for it."""
    V, F = (np.asarray(a) for a in bumpy)
    r = qemjax.simplify((V, F), target_faces=60, refit=0)
    X, G, src = r.vertices, r.faces, r.source_faces
    cos = float(np.cos(np.radians(60.0)))
    labels = (V[:, 0] > 0).astype(np.int32)  # two labels, as parts of the input would give
    for part, source, moves in ((None, None, True), (labels, src, True), (labels, src, False)):
        kw = dict(polish=8, sliver_moves=8, min_quality=0.1)
        want_kept, got_kept = [], []
        want = _refit.refit(V, F, X, G, 2, cos, part, source, sampled=want_kept, **kw)
        side = _refit.InputSide(lambda: (V, F), part=part, moves=moves, thread=thread)
        got = _refit.refit(None, None, X, G, 2, cos, part, source, sampled=got_kept, side=side, **kw)
        assert np.array_equal(got, want) and not np.array_equal(got, X)
        assert len(got_kept) == len(want_kept) == 2
        for a, b in zip(got_kept[0] + (got_kept[1],), want_kept[0] + (want_kept[1],)):
            assert np.array_equal(a, b)
        assert (side.get().into is not None) == moves and side.get().samples is not None

    flat = _refit.InputSide(lambda: (np.zeros_like(V), F), thread=thread)  # no extent: nothing to fit to
    assert np.array_equal(_refit.refit(None, None, X, G, 1, cos, side=flat), X)

    def fails():
        raise OSError("a part file went missing")
    side = _refit.InputSide(fails, thread=thread)
    with pytest.raises(OSError, match="went missing"):
        _refit.refit(None, None, X, G, 1, cos, side=side)


def test_a_run_makes_its_input_side_beside_its_rounds_with_the_same_bits(bumpy, monkeypatch):
    """A run that re-fits to its own input makes what the re-fit makes of the input alone (`refit.InputSide`)
    on a thread from the rounds' start (`stages.beside_rounds`), and its re-fit takes it: the same result
    bit for bit, measured distance included, as with the side made inside the re-fit. Not for a run with
    locks, nor one that does not re-fit."""
    from qemjax._pipeline import stages

    made, beside = [], stages.beside_rounds

    def recording(job):
        job = beside(job)
        made.append(job.side)
        return job
    monkeypatch.setattr(stages, "beside_rounds", recording)
    kw = dict(ratio=0.05, method="default")
    new = qemjax.simplify(bumpy, **kw)
    assert len(made) == 1 and made[0] is not None and made[0].get().into is not None  # moves: their index too
    monkeypatch.setattr(stages, "beside_rounds", lambda job: (made.append(None), job)[1])
    old = qemjax.simplify(bumpy, **kw)
    for name in ("vertices", "faces"):
        assert np.array_equal(getattr(new, name), getattr(old, name)), name
    for k in ("distance_max", "distance_rms", "distance_p95", "polish_moves", "sliver_moves"):
        assert new.stats[k] == old.stats[k], k
    assert new.stats["polish_moves"] + new.stats["sliver_moves"] > 0
    monkeypatch.setattr(stages, "beside_rounds", recording)
    made.clear()
    qemjax.simplify(bumpy, ratio=0.05, refit=0)
    qemjax.simplify(bumpy, ratio=0.05, locked=np.arange(5))
    assert made == [None, None]


def test_the_record_keeps_the_contractions_positions(bumpy):
    """A replay rebuilds the contraction phase: its last level is the run without the re-fit."""
    plain = qemjax.simplify(bumpy, target_faces=200, refit=0)
    fit = qemjax.simplify(bumpy, target_faces=200, refit=1)
    last = fit.replay(contractions=len(fit.history.pairs))
    assert np.array_equal(last.faces, fit.faces)
    assert np.array_equal(last.vertices, plain.vertices) and not np.array_equal(last.vertices, fit.vertices)


def test_the_layout_of_a_fans_hub_lists_each_neighbour_once_in_order():
    """`refit_system.layout` on a closed fan of 200 faces around one hub (its row is longer than
    `SHORT_ROW`: numpy's sort, the other rows by insertion) and a locked rim vertex: every row holds itself
    and the free vertices it shares a face with, ascending, once; each face's corner pairs point at their
    entries."""
    from qemjax._pipeline.refit_system import SHORT_ROW, layout

    n = 200
    G = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)])
    free = np.ones(n + 1, bool)
    free[7] = False
    col = np.where(free, np.cumsum(free) - 1, -1)
    indptr, indices, pos = layout(G, col, int(free.sum()))
    assert 3 * n > SHORT_ROW
    for v in range(n + 1):
        if not free[v]:
            continue
        want = {v} | {int(u) for g in G if v in g for u in g if free[u]}
        row = indices[indptr[col[v]]:indptr[col[v] + 1]]
        np.testing.assert_array_equal(row, sorted(col[u] for u in want))
    for g in range(n):
        for x in range(3):
            for y in range(3):
                a, b = G[g, x], G[g, y]
                if free[a] and free[b]:
                    assert indices[pos[g, x, y]] == col[b] and indptr[col[a]] <= pos[g, x, y] < indptr[col[a] + 1]
                else:
                    assert pos[g, x, y] == -1
