"""The shape term of the parallel round's ranking (``quality_threshold``, `qemjax._schedulers.shape`): its
kernels against float64 references on random inputs, the round's candidates it chooses, and what a run with it
promises (the target, a valid mesh, fewer slivers, the same bits on every path and in a batch, the greedy
queue's warning, bad values refused)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers import shape
from conftest import assert_valid
from test_min_angle import _quality
from test_round_glue import glue_runs
from test_round_loops import _assert_same, _run


def _slivers(res, degrees=10.0) -> int:
    """Faces whose smallest angle is under ``degrees``."""
    c = np.asarray(res.vertices, np.float64)[np.asarray(res.faces)]
    smallest = np.full(len(c), np.inf)
    for i in range(3):
        u, v = c[:, (i + 1) % 3] - c[:, i], c[:, (i + 2) % 3] - c[:, i]
        cos = (u * v).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        smallest = np.minimum(smallest, np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return int(np.count_nonzero(smallest < degrees))


def _simplify(mesh, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return qemjax.simplify(mesh, **kw)


def _random_case(seed: int):
    """A jittered sphere's positions (float32), faces and face lists, its edges, and placements near them."""
    rng = np.random.default_rng(seed)
    V, F = shapes.bumpy_sphere(2)
    V = (np.asarray(V) + rng.normal(scale=0.02, size=V.shape)).astype(np.float32)
    F = np.asarray(F, np.int64)
    lists = FaceLists(F.astype(np.int32), len(V))
    E = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0)
    t = rng.uniform(-0.2, 1.2, size=(len(E), 1))
    X = (V[E[:, 0]] * (1 - t) + V[E[:, 1]] * t + rng.normal(scale=0.05, size=(len(E), 3))).astype(np.float32)
    return V, F, lists, E.astype(np.int32), X


def _kept_quality_reference(V, F, a, b, x, least) -> float:
    """float64: the smallest quality of the faces at a or b without both, their a or b corner at x, among
    those that end lower than they were and were at least ``least`` before."""
    best = 1.0
    one = np.array([[0, 1, 2]])
    for f in F:
        if (a in f) == (b in f):  # both (the pair's own faces) or neither
            continue
        c = np.asarray(V, np.float64)[f]
        before = _quality(c, one)[0]
        c[list(f).index(a if a in f else b)] = x
        q = _quality(c, one)[0]
        if q < before and before >= least:
            best = min(best, q)
    return best


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("least", [0.0, 0.75])
def test_kept_quality_is_the_float64_reference(seed, least):
    V, F, lists, E, X = _random_case(seed)
    rng = np.random.default_rng(seed)
    got, want, every = [], [], []
    for i in rng.choice(len(E), 40, replace=False):
        a, b = int(E[i, 0]), int(E[i, 1])
        got.append(shape.kept_quality(V, lists.F, lists.alive, lists.off, lists.cnt, lists.pool, a, b, X[i],
                                      np.float32(least)))
        want.append(_kept_quality_reference(V, F, a, b, X[i], least))
        every.append(_kept_quality_reference(V, F, a, b, X[i], 0.0))
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-6)
    assert np.count_nonzero(np.array(want) < 1) > 10  # the check can fail: many pairs have a face that counts
    if least:  # ... and the faces under ``least`` before are left out for some
        assert np.count_nonzero(np.array(want) != np.array(every)) > 3


@pytest.mark.parametrize("per_pair_floor", [False, True])
def test_shaped_keys_are_the_formula(per_pair_floor):
    V, F, lists, E, X = _random_case(3)
    rng = np.random.default_rng(3)
    P = len(E)
    key = rng.exponential(1e-4, P).astype(np.float32)
    key[rng.random(P) < 0.2] = 0.0  # flat pairs: the floor ranks them
    which = rng.random(P) < 0.7
    floor = (rng.uniform(1e-6, 1e-5, P) if per_pair_floor else np.array([3e-6])).astype(np.float32)
    s = np.float32(0.5)
    got = shape.shaped_keys(key, which, floor, E, X, V, lists.F, lists.alive, lists.off, lists.cnt, lists.pool, s)
    least = s * np.float32(shape.NEAR_DEGENERATE)
    q = np.array([shape.kept_quality(V, lists.F, lists.alive, lists.off, lists.cnt, lists.pool, E[i, 0], E[i, 1], X[i],
                                     least) for i in range(P)], np.float64)
    lo = floor if per_pair_floor else np.full(P, floor[0])
    want = np.where(which & (q < s), np.maximum(key, lo) * s / np.maximum(q, s * 1e-6), key)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert np.all(got >= key) and np.array_equal(got[~which], key[~which])
    assert np.count_nonzero(got != key) > P // 10  # the check can fail: many pairs are lifted


@pytest.mark.parametrize("n", [2, 3])
def test_shaped_keys_on_threads_are_the_same_bits(monkeypatch, n):
    """Blocks of pairs on threads (`_mesh.threads`) against one block on this thread."""
    from qemjax._mesh import threads

    V, F, lists, E, X = _random_case(4)
    rng = np.random.default_rng(4)
    key = rng.exponential(1e-4, len(E)).astype(np.float32)
    which = rng.random(len(E)) < 0.6
    args = (key, which, np.array([3e-6], np.float32), E, X, V, lists.F, lists.alive, lists.off, lists.cnt,
            lists.pool, np.float32(0.5))
    one = shape.shaped_keys(*args)
    calls = []
    rows = shape._shape_rows
    monkeypatch.setattr(shape, "_shape_rows", lambda *a: calls.append(len(a[2])) or rows(*a))
    monkeypatch.setattr(threads, "count", lambda: n)
    monkeypatch.setattr(shape, "MIN_BLOCK", 10)
    assert np.array_equal(shape.shaped_keys(*args), one) and np.count_nonzero(one != key) > 10
    assert len(calls) == n and sum(calls) == np.count_nonzero(which)


def _round(seed, P_gate=0.1):
    """A round's keys, valid pairs and candidates under a gate (the cheapest P_gate of the valid ones)."""
    V, F, lists, E, X = _random_case(seed)
    rng = np.random.default_rng(seed)
    key = rng.exponential(1e-4, len(E)).astype(np.float32)
    valid = rng.random(len(E)) < 0.9
    thr = np.quantile(key[valid], P_gate)
    return V, lists, E, X, key, valid, valid & (key <= thr)


def test_rerank_takes_as_many_candidates_from_the_cheapest_pairs():
    V, lists, E, X, key, valid, cand = _round(4)
    shaped, out = shape.rerank(key, valid, cand, 1e-9, E, X, V, lists, 0.5)
    n = np.count_nonzero(cand)
    assert np.count_nonzero(out) == n  # (no ties among random keys)
    assert not np.any(out & ~valid)
    widest = np.sort(key[valid])[shape.SPAN * n - 1]
    assert np.all(key[out] <= widest)  # from the SPAN·n cheapest valid pairs
    assert np.any(out & ~cand) and np.any(cand & ~out)  # (it can fail:) lifted pairs gave their place
    assert np.all(shaped[out].max() <= shaped[(key <= widest) & valid & ~out])


@pytest.mark.parametrize("per_pair_free", [False, True])
def test_rerank_with_a_threshold_nothing_reaches_changes_nothing(per_pair_free):
    """Nothing lifted, the candidates are the gate's, also where each pair has its own free cost (parts of
    several sizes: then the candidates are not the cheapest pairs, and a cut by key alone would change them)."""
    V, lists, E, X, key, valid, cand = _round(5)
    free = 1e-9
    if per_pair_free:
        rng = np.random.default_rng(5)
        free = np.where(rng.random(len(E)) < 0.5, 3e-4, 1e-9).astype(np.float32)
        thr = np.quantile(key[valid], 0.05)
        cand = valid & (key <= np.maximum(thr, free))
        assert np.any(cand & (key > np.sort(key[valid])[np.count_nonzero(cand) - 1]))  # not the cheapest
    shaped, out = shape.rerank(key, valid, cand, free, E, X, V, lists, 1e-12)
    np.testing.assert_array_equal(shaped, key)
    np.testing.assert_array_equal(out, cand)


def test_rerank_per_copy_is_each_copy_alone():
    """Two copies side by side (a batch's layout: the second copy's vertices and pairs after the first's)
    get the keys and candidates each gets alone."""
    V, lists, E, X, key, valid, cand = _round(6)
    V2, lists2, E2, X2, key2, valid2, cand2 = _round(7, P_gate=0.05)
    n1, m1 = len(V), len(lists.F)
    Fb = np.concatenate([lists.F[: lists.alive.size][lists.alive], lists2.F[lists2.alive] + n1]).astype(np.int32)
    Vb = np.concatenate([V, V2])
    listsb = FaceLists(Fb, len(Vb))
    assert m1 == np.count_nonzero(lists.alive)
    Eb = np.concatenate([E, E2 + n1]).astype(np.int32)
    cat = lambda a, b: np.concatenate([a, b])  # noqa: E731
    shaped_b, out_b = shape.rerank(cat(key, key2), cat(valid, valid2), cat(cand, cand2), 1e-9, Eb, cat(X, X2), Vb,
                                   listsb, 0.4, starts=np.array([0, len(E), len(E) + len(E2)]))
    for (V_, l_, E_, X_, k_, v_, c_), sl in (((V, lists, E, X, key, valid, cand), slice(0, len(E))),
                                              ((V2, lists2, E2, X2, key2, valid2, cand2), slice(len(E), None))):
        s1, o1 = shape.rerank(k_, v_, c_, 1e-9, E_, X_, V_, l_, 0.4)
        np.testing.assert_array_equal(shaped_b[sl], s1)
        np.testing.assert_array_equal(out_b[sl], o1)


def _rerank_reference(key, valid, cand, free, E, X, V, lists, s, starts):
    """`shape.rerank` as numpy steps, copy by copy: the k-th smallest by np.partition, the shaping by
    `shape.shaped_keys`."""
    widest = np.full(len(key), np.nan, np.float32)
    n = []
    for a, b in zip(starts[:-1], starts[1:]):
        nc, nv = np.count_nonzero(cand[a:b]), np.count_nonzero(valid[a:b])
        n.append(nc)
        if nc and nv:
            k = min(shape.SPAN * nc, nv)
            widest[a:b] = np.partition(key[a:b][valid[a:b]], k - 1)[k - 1]
    which = valid & ((key <= widest) | cand)
    floor = np.atleast_1d(np.asarray(free, np.float32))
    shaped = shape.shaped_keys(key, which, floor, E, X, V, lists.F, lists.alive, lists.off, lists.cnt, lists.pool,
                               np.float32(s))
    out = cand & (shaped == key) & (key <= (floor if len(floor) > 1 else floor[0]))
    others = which & ~out
    for c, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
        rest = n[c] - np.count_nonzero(out[a:b])
        if rest >= 1:
            cut = np.partition(shaped[a:b][others[a:b]], rest - 1)[rest - 1]
            out[a:b] |= others[a:b] & (shaped[a:b] <= cut)
    return shaped, out


@pytest.mark.parametrize("threaded", [False, True])
def test_rerank_is_its_numpy_steps(monkeypatch, threaded):
    """The compiled passes of `shape.rerank` (in one call for a round of fewer than MIN_BLOCK pairs, else
    around the threaded shaping) give the numpy steps' keys and candidates, bit for bit: keys with many ties
    and zeros (flat pairs at the floor), a floor per pair or one, copies without candidates or valid pairs."""
    V, F, lists, E, X = _random_case(8)
    if threaded:
        monkeypatch.setattr(shape, "MIN_BLOCK", 16)
    rng = np.random.default_rng(8)
    P = len(E)
    for trial in range(40):
        key = rng.choice(rng.exponential(1e-4, 40), P).astype(np.float32)  # ties
        key[rng.random(P) < 0.2] = 0.0
        valid = rng.random(P) < rng.uniform(0.3, 1.0)
        cand = valid & (key <= np.quantile(key, rng.uniform(0.0, 0.3)))
        cuts = np.sort(rng.choice(np.arange(1, P), rng.integers(0, 4), replace=False))
        starts = np.concatenate([[0], cuts, [P]]).astype(np.int64)
        if trial % 5 == 0 and len(starts) > 2:  # a copy with nothing valid
            valid[starts[0]:starts[1]] = cand[starts[0]:starts[1]] = False
        free = (rng.uniform(0, 2e-5, P).astype(np.float32) if trial % 2 else 1e-5)
        s = float(rng.choice([0.2, 0.4, 0.6]))
        got = shape.rerank(key, valid, cand, free, E, X, V, lists, s, starts)
        want = _rerank_reference(key, valid, cand, free, E, X, V, lists, s, starts)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert np.any(want[0] != key)  # (it can fail:) the last trial lifted some pairs


@pytest.mark.parametrize("method", ["default", "classic"])
def test_a_run_with_it_reaches_the_target_valid_with_fewer_slivers(method):
    """The term never refuses: the exact target, a valid mesh; and it does what it is for (the faces under
    10° and those under quality 0.2 fall, and the worst face's quality rises)."""
    mesh = shapes.bumpy_sphere(4)
    target = len(mesh[1]) // 20
    off = _simplify(mesh, target_faces=target, method=method, quality_threshold=0.0, sliver_moves=0)
    on = _simplify(mesh, target_faces=target, method=method, quality_threshold=0.5, sliver_moves=0)
    for res in (off, on):
        assert len(res.faces) == target
        assert_valid(res, target, *mesh)
    assert _slivers(off) > 0
    assert _slivers(on) < _slivers(off)
    q_on, q_off = _quality(on.vertices, on.faces), _quality(off.vertices, off.faces)
    assert q_on.min() > 1.5 * q_off.min()
    assert np.mean(q_on < 0.2) < np.mean(q_off < 0.2)


def test_the_compiled_glue_decides_as_the_numpy_glue(monkeypatch):
    new, old, seen = glue_runs(shapes.bumpy_sphere(3), dict(ratio=0.05, quality_threshold=0.4, late_memoryless=0),
                               monkeypatch)
    assert seen == [True, True]
    _assert_same(new, old)


def _two_parts():
    """A sphere and a smaller, finer one beside it: two parts of different sizes (each its own free cost)."""
    V1, F1 = shapes.bumpy_sphere(3)
    V2, F2 = shapes.bumpy_sphere(2)
    V2 = np.asarray(V2) * 0.3 + [3.0, 0.0, 0.0]
    return np.concatenate([V1, V2]), np.concatenate([F1, np.asarray(F2) + len(V1)])


@pytest.mark.parametrize("make", [lambda: shapes.bumpy_sphere(3), _two_parts], ids=["one part", "two parts"])
def test_a_batch_runs_each_copy_as_alone(make):
    """Copies of one batch (the same threshold, other targets and boundary weights; the batch's rounds rank
    each copy by shape on its own pairs) give what each `simplify` gives alone; a config without the term runs
    in a batch of its own and differs."""
    mesh = make()
    configs = [dict(ratio=0.1, quality_threshold=0.5), dict(ratio=0.2, quality_threshold=0.5),
               dict(ratio=0.1, quality_threshold=0.5, boundary_weight=3.0), dict(ratio=0.1)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = qemjax.simplify_batch(mesh, configs)
    for res, cfg in zip(got, configs):
        want = _simplify(mesh, **cfg)
        np.testing.assert_array_equal(res.vertices, want.vertices)
        np.testing.assert_array_equal(res.faces, want.faces)
    assert got[0].stats["batch"]["copies"] == 2  # (the boundary weight changes nothing on closed surfaces: one run)
    assert not np.array_equal(got[0].faces, got[3].faces)


@pytest.mark.parametrize("make, kw, runs", [
    (lambda: shapes.bumpy_sphere(3), dict(ratio=0.05, quality_threshold=0.4), 1),
    # the default's memoryless last stretch: a second run, on the compiled loops or the numpy stages
    (lambda: shapes.bumpy_sphere(3), dict(ratio=0.05, quality_threshold=0.6, method="default"), 2),
    (_two_parts, dict(ratio=0.05, quality_threshold=0.5, method="default"), 2),
], ids=["classic", "default", "two parts"])
def test_the_numpy_stages_decide_as_the_compiled_loops(make, kw, runs, monkeypatch):
    new, seen = _run(make(), kw, monkeypatch, True)
    old, seen_old = _run(make(), kw, monkeypatch, False)
    assert seen == [True] * runs and seen_old == [False] * runs
    _assert_same(new, old)
    without = kw | {"quality_threshold": 0.0}
    assert not np.array_equal(new.faces, _run(make(), without, monkeypatch, True)[0].faces)
    if runs == 2:
        assert new.stats["memoryless_from_faces"] > 0


def test_the_greedy_queue_says_it_ranks_by_cost_alone():
    mesh = shapes.bumpy_sphere(2)
    with pytest.warns(UserWarning, match="quality_threshold is not applied: the greedy queue"):
        on = qemjax.simplify(mesh, ratio=0.1, scheduler="greedy", quality_threshold=0.5)
    off = _simplify(mesh, ratio=0.1, scheduler="greedy")
    assert on.stats["quality_threshold_off"] == "the greedy queue ranks by cost alone"
    np.testing.assert_array_equal(on.faces, off.faces)
    np.testing.assert_array_equal(on.vertices, off.vertices)


def test_max_distance_holds_with_it():
    mesh = shapes.bumpy_sphere(3)
    res = _simplify(mesh, max_distance_rel=0.01, quality_threshold=0.5)
    assert res.stats["distance_max_rel"] <= 0.01
    assert len(res.faces) < len(mesh[1])
    without = _simplify(mesh, max_distance_rel=0.01)
    assert len(res.faces) != len(without.faces) or not np.array_equal(res.faces, without.faces)


@pytest.mark.parametrize("value", [-0.1, math.sqrt(3) / 2, 1.0, float("nan"), float("inf"), True, "high"])
def test_a_bad_threshold_is_named(value):
    with pytest.raises(ValueError, match="quality_threshold"):
        qemjax.simplify(shapes.bumpy_sphere(1), ratio=0.5, quality_threshold=value)


def test_the_command_line_takes_it(tmp_path):
    from qemjax._cli import main

    src, out = tmp_path / "in.ply", tmp_path / "out.ply"
    V, F = shapes.bumpy_sphere(2)
    import trimesh
    trimesh.Trimesh(V, F, process=False).export(src)
    assert main(["simplify", str(src), str(out), "--ratio", "0.2", "--quality-threshold", "0.5", "--quiet"]) == 0
    got = trimesh.load(out, process=False)
    want = _simplify(str(src), ratio=0.2, quality_threshold=0.5)
    np.testing.assert_array_equal(got.faces, want.faces)
    assert not np.array_equal(got.faces, _simplify(str(src), ratio=0.2).faces)


def test_the_defaults_own_threshold_is_off_under_greedy_and_said_in_the_stats():
    """The default's shape term is the preset's, not the call's: under the greedy queue it is off, the stats
    say so, and no warning is raised (one is when the call sets it: above)."""
    assert qemjax.QEM.default().quality_threshold > 0
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        res = qemjax.simplify(shapes.bumpy_sphere(2), ratio=0.1, scheduler="greedy")
    assert not [w for w in seen if "quality_threshold" in str(w.message)]
    assert res.stats["quality_threshold_off"] == "the greedy queue ranks by cost alone"


def test_each_copys_order_statistics_are_numpys():
    """`segments.sums` and `segments.kth` (a batch's per-copy gates and the shape term's cuts in one
    compiled pass) give what numpy gives copy by copy: the k-th smallest of the masked rows as np.partition
    has it (ties, NaNs last, infinities, both zeros), copies with no rows, ranks of 0 (no value)."""
    from qemjax._schedulers import segments

    rng = np.random.default_rng(11)
    for trial in range(200):
        sizes = rng.integers(0, 40, rng.integers(1, 7))
        starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        P = int(starts[-1])
        values = rng.choice(np.array([0.0, -0.0, 1.0, 2.0, np.inf, -np.inf, np.nan, 3.5], np.float32), P)
        values = np.where(rng.random(P) < 0.5, rng.standard_normal(P).astype(np.float32), values)
        mask = rng.random(P) < 0.7
        want_n = np.array([np.count_nonzero(mask[a:b]) for a, b in zip(starts[:-1], starts[1:])])
        np.testing.assert_array_equal(segments.sums(mask, starts), want_n)
        ks = np.array([rng.integers(0, n + 1) for n in want_n], np.int64)
        _assert_kth_is_numpys(values, mask, starts, ks, trial)
        copies = np.arange(len(sizes))
        np.testing.assert_array_equal(segments.per_row(copies, starts), np.repeat(copies, sizes))


@pytest.mark.parametrize("seed", range(3))
def test_a_large_copys_kth_by_radix_passes_is_numpys(seed):
    """Copies of `segments.RADIX_FROM` rows or more take the k-th smallest by radix passes over the float32
    bits: the value np.partition gives, over keys with heavy ties (the first and second passes' bins hold
    many rows), both zeros, denormals, negatives, infinities and NaNs of either sign (last), ranks from the
    first to the last, beside small copies that keep the partition."""
    from qemjax._schedulers import segments

    rng = np.random.default_rng(seed)
    big = segments.RADIX_FROM
    sizes = np.array([big + 17, 500, 2 * big, 0, big], np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    P = int(starts[-1])
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-40, -1e-40, 1.0, 1.0 + 2**-23], np.float32)
    values = (rng.random(P) ** 4 * 1e-6).astype(np.float32)  # costs: many exponents
    values[rng.random(P) < 0.3] = np.float32(3e-7)  # one value many times
    pick = rng.random(P) < 0.1
    values[pick] = rng.choice(special, int(pick.sum()))
    values[rng.random(P) < 0.05] *= -1
    values[rng.integers(P, size=20)] = np.array([0xFFC00001], np.uint32).view(np.float32)[0]  # a negative NaN
    mask = rng.random(P) < 0.7
    counts = segments.sums(mask, starts)
    for ranks in (np.ones_like(counts), counts, np.maximum(counts // 3, 1), np.maximum(counts - 25, 1),
                  rng.integers(1, np.maximum(counts, 1) + 1)):
        ks = np.where(counts > 0, ranks, 0).astype(np.int64)
        _assert_kth_is_numpys(values, mask, starts, ks, seed)


def _assert_kth_is_numpys(values, mask, starts, ks, case):
    """`segments.kth` of each copy is np.partition's k-th of its masked rows (NaN where the rank is 0)."""
    from qemjax._schedulers import segments

    got = segments.kth(values, mask, starts, ks)
    for c, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
        if ks[c] < 1:
            assert np.isnan(got[c])
            continue
        want = np.partition(values[a:b][mask[a:b]], ks[c] - 1)[ks[c] - 1]
        assert got[c] == want or (np.isnan(want) and np.isnan(got[c])), (case, c, ks[c], got[c], want)
