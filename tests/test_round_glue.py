"""The round's compiled glue (`_schedulers.glue`) answers as the numpy code it replaces in
`parallel.LoopRound`, bit for bit, on random inputs: the carried prices and candidates, the gate with numpy's
promotion of its scalars, the order and face target, the contraction with its device inputs, and the one-piece
device call. Whole runs against the numpy rounds: tests/test_round_loops.py and tests/test_round_step.py."""
from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import qemjax
from qemjax import Schedule, shapes
from qemjax._costs import build, resolve
from qemjax._kernels.batching import chunks, pad_rows
from qemjax._mesh.arrays import put_rows
from qemjax._mesh.incidence import FaceLists
from qemjax._schedulers import device, parallel
from qemjax._schedulers.parallel import contraction, glue
from qemjax._schedulers.parallel import driver
from qemjax._schedulers.outcome import LOCKED
from qemjax._schedulers.select import fits_target, sort_keys
from test_attributes import atlas_sphere
from test_greedy_compiled import _two_spheres
from test_round_loops import _assert_same, _selected_pairs


def _carry_numpy(kept, d, out, x0, cost0, branch0, parts0, bad0, E, ecount, n, limit, need, manifold, locked):
    """`Round.update`, `Round.cost` (the fused path) and `Round.candidates`, as numpy runs them."""
    idx = np.flatnonzero(kept)
    x, cost, branch, parts, bad = (np.take(a, idx, axis=0) for a in (x0, cost0, branch0, parts0, bad0))
    put_rows(x, d, out[:3, : len(d)].T)
    cost[d], branch[d] = out[3, : len(d)], out[4, : len(d)].astype(np.int8)
    if parts.shape[1]:
        put_rows(parts, d, np.ascontiguousarray(out[5:, : len(d)].T))
    if len(locked):  # pairs of two locked vertices (`locks.both_locked`)
        bad[locked[E[:, 0]] & locked[E[:, 1]]] = LOCKED
    bvert = np.zeros(n, bool)
    bvert[E[ecount == 1].reshape(-1)] = True
    valid = (cost <= limit) & (bad == 0) & (ecount <= need)
    if manifold:
        valid &= (ecount >= 1) & (ecount <= 2)
    return x, cost, branch, parts, bad, bvert, valid


@pytest.mark.parametrize("locks", [False, True])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("limit", [np.inf, 0.1, np.float64(0.1), 1e300])
def test_carry_is_the_numpy_update_cost_and_candidates(seed, limit, locks):
    rng = np.random.default_rng(seed)
    n, P0, p = 300, 900, seed % 3  # models with 0, 1 and 2 cost parts
    kept = rng.random(P0) < 0.8
    P = int(kept.sum())
    E = np.sort(rng.integers(0, n, (P, 2)), axis=1).astype(np.int32)
    ecount = rng.integers(0, 4, P).astype(np.int32)
    d = np.sort(rng.choice(P, P // 3, replace=False))
    out = rng.random((5 + p, len(d) + 7)).astype(np.float32)  # padded columns past the stale pairs
    out[4] = rng.integers(0, 4, out.shape[1])
    out[3, ::5] = np.float32(0.1)  # costs at the bound: numpy compares a Python float in float32
    x0 = rng.random((P0, 3)).astype(np.float32)
    cost0 = rng.random(P0).astype(np.float32) * 0.2
    cost0[::7] = np.float32(0.1)
    branch0 = rng.integers(0, 4, P0).astype(np.int8)
    parts0 = rng.random((P0, p)).astype(np.float32)
    bad0 = np.where(rng.random(P0) < 0.2, rng.integers(1, 6, P0), 0).astype(np.int8)
    locked = rng.random(n) < 0.4 if locks else np.zeros(0, bool)
    for manifold in (True, False):
        args = (kept, d, out, x0, cost0, branch0, parts0, bad0, E, ecount, n)
        with np.errstate(over="ignore"):  # (1e300 in float32)
            want = _carry_numpy(*args, limit, 2, manifold, locked)
        got = glue.carry(kept, d, out, (x0, cost0, branch0, parts0, bad0), E, ecount, n,
                         (glue.bound(limit, np.float32), 2, manifold), locked)
        for w, g, name in zip(want, got, ("x", "cost", "branch", "parts", "bad", "bvert", "valid")):
            assert g.dtype == w.dtype and np.array_equal(g, w), name
        assert got[7] == want[6].sum()
        if locks:
            assert (got[4] == LOCKED).any()


@pytest.mark.parametrize("gate", [1.2, 2, np.float64(1.2), np.float32(1.7)])
@pytest.mark.parametrize("free", ["one part", "float64 parts", "float32 parts"])
def test_under_gate_is_numpys_threshold(gate, free):
    """The candidates under gate × k-th (or the free cost), with the scalars promoted as numpy promotes
    them: a Python number is weak, a numpy scalar keeps its precision."""
    rng = np.random.default_rng(7)
    n, P = 200, 2000
    E = np.sort(rng.integers(0, n, (P, 2)), axis=1).astype(np.int32)
    key = (rng.random(P) * 1e-9).astype(np.float32)
    key[::3] = key[0]  # ties
    valid = rng.random(P) < 0.7
    free_cost = 3e-10
    kth = np.partition(key.compress(valid), 40)[40]
    thr = gate * kth
    if free == "one part":
        free_at = np.zeros(0)
        ref = valid & (key <= np.maximum(thr, free_cost))
        thr = np.maximum(thr, free_cost)
    else:
        scale = rng.random(n).astype(np.float64 if free == "float64 parts" else np.float32)
        free_at = free_cost * scale
        ref = valid & (key <= np.maximum(thr, free_cost * scale[E[:, 0]]))
    got = glue.under_gate(key, valid, thr, E, free_at)
    assert np.array_equal(got, ref) and 0 < ref.sum() < valid.sum()
    if free != "one part":  # a NaN threshold: np.maximum is NaN, and nothing passes
        nan = np.float32(np.nan) * np.float32(gate)
        ref = valid & (key <= np.maximum(nan, free_cost * scale[E[:, 0]]))
        assert np.array_equal(glue.under_gate(key, valid, nan, E, free_at), ref) and not ref.any()


def test_the_gates_kth_is_numpys_partition_as_a_float32():
    """The gate's k-th smallest valid key as `LoopRound.select` takes it (`segments.kth`, one copy, the rank
    capped by the valid pairs as `select.gate_rank` caps it), as np.partition gives it: ties, zeros,
    infinities and NaNs (last), ranks past the valid count; a float32, so that gate × k-th is promoted as
    numpy promotes it."""
    from qemjax._schedulers import segments

    rng = np.random.default_rng(12)
    for trial in range(300):
        P = int(rng.integers(1, 60))
        key = rng.choice(np.array([0.0, 1e-9, 2e-9, np.inf, np.nan, 5e-10], np.float32), P)
        key = np.where(rng.random(P) < 0.5, (rng.random(P) * 1e-8).astype(np.float32), key)
        valid = rng.random(P) < 0.7
        valid[rng.integers(P)] = True
        k = int(rng.integers(1, P + 3))
        m = np.count_nonzero(valid)
        want = np.partition(key.compress(valid), min(k, m) - 1)[min(k, m) - 1]
        got = segments.kth(key, valid, np.array([0, P], np.int64), np.array([min(k, m)], np.int64))[0]
        assert got == want or (np.isnan(got) and np.isnan(want)), trial
        assert type(1.2 * got) is type(1.2 * want) is np.float32


@pytest.mark.parametrize("need", [0, 3, 40, 10**6])
def test_order_fit_is_sort_keys_and_fits_target(need):
    rng = np.random.default_rng(need)
    n, P = 500, 3000
    E = np.sort(rng.integers(0, n, (P, 2)), axis=1).astype(np.int32)
    ecount = rng.integers(1, 3, P).astype(np.int32)
    key = (rng.random(P) * 1e-6).astype(np.float32)
    key[::4] = 0.0  # flat regions: many ties, broken by the scramble
    acc = rng.choice(P, 200, replace=False).astype(np.int64)
    apex = rng.integers(-1, n, (200, 2)).astype(np.int64)
    cnt = rng.integers(0, 9, n)
    salt = (17 * 7919) & 0xFFFFFFFF
    order = np.argsort(sort_keys(key, acc, 17 * 7919), kind="stable")
    fit = fits_target(ecount[acc[order]], need)
    got, got_apex, room = glue.order_fit(acc, apex, key, ecount, salt, need, cnt, E)
    want = acc[order[fit]]
    assert np.array_equal(got, want) and np.array_equal(got_apex, apex[order[fit]])
    assert room == cnt[E[want, 0]].sum() + cnt[E[want, 1]].sum()


@pytest.mark.parametrize("seed", [0, 1])
def test_contract_is_the_compiled_loops_and_the_padded_step_inputs(seed):
    """One call against its parts in `LoopRound.contract`'s order: `clear_bad`, `contract_faces`,
    `contract_edges`, the positions, the stale rows, and the device inputs padded as `chunks` pads them."""
    V, F = shapes.bumpy_sphere(2)
    n = len(V)
    E, ecount, deg, P, apex = _selected_pairs(F, n, seed)
    E, ecount = E.astype(np.int32), ecount.astype(np.int32)
    rng = np.random.default_rng(seed)
    row = {tuple(e): i for i, e in enumerate(E)}
    acc = np.array([row[tuple(p)] for p in P])  # the accepted pairs' rows, in P's order
    x = rng.random((len(E), 3)).astype(np.float32)
    cost = rng.random(len(E)).astype(np.float32)
    branch = rng.integers(0, 4, len(E)).astype(np.int8)
    bad = np.where(rng.random(len(E)) < 0.3, 2, 0).astype(np.int8)
    touched = rng.random(n) < 0.5
    V3 = rng.random((n + 5, 3)).astype(np.float32)
    VQ = rng.random((n + 5, 13)).astype(np.float32)

    ref_bad, ref_V3, ref_VQ, ref_faces = bad.copy(), V3.copy(), VQ.copy(), FaceLists(F, n)
    a, b = E[acc, 0], E[acc, 1]
    room = int(ref_faces.cnt[a].sum() + ref_faces.cnt[b].sum())
    ref_faces.reserve(room)
    contraction.clear_bad(E, ref_bad, touched)
    end, dead = contraction.contract_faces(a, b, ref_faces.F, ref_faces.alive, ref_faces.cnt, ref_faces.off,
                                         ref_faces.pool, ref_faces.end)
    want_edges = contraction.contract_edges(E, ecount, deg, a, b, apex.astype(np.int64), np.full(n, -1, np.int32))
    put_rows(ref_V3, a, x[acc])
    ref_VQ[a, :3] = x[acc]
    d = np.flatnonzero(want_edges[4])

    faces, counts, label = FaceLists(F, n), np.zeros(4, np.int64), np.full(n, -1, np.int32)
    faces.reserve(room)
    lists = (faces.F, faces.alive, faces.cnt, faces.off, faces.pool)
    got = glue.contract((E, ecount, deg, bad, x, cost, branch), lists, faces.end, (V3, VQ),
                        (touched, acc, apex.astype(np.int64)), counts, label, (4096, 256, 1024))
    ga, gb, gx, gc, top, gend, gdead, gedges, gd, (rows, pp, xx, qq) = got
    assert np.array_equal(bad, ref_bad) and np.array_equal(V3, ref_V3) and np.array_equal(VQ, ref_VQ)
    assert np.array_equal(ga, a) and np.array_equal(gb, b) and np.array_equal(gx, x[acc])
    assert np.array_equal(gc, cost[acc].astype(np.float64)) and top == float(cost[acc].max())
    assert np.array_equal(counts, np.bincount(branch[acc], minlength=4))
    assert gend == end and np.array_equal(gdead, dead) and np.array_equal(gd, d)
    for name in ("F", "alive", "cnt", "off"):
        assert np.array_equal(getattr(faces, name), getattr(ref_faces, name)), name
    assert np.array_equal(faces.pool[:end], ref_faces.pool[:end])  # (past the end: room not yet written)
    for w, g in zip(want_edges, gedges):
        assert np.array_equal(g, w)
    assert (label == -1).all()
    Pi = np.stack([a, b], 1).astype(np.int32)
    assert np.array_equal(pp, next(chunks(Pi, size=256))[1]) and np.array_equal(xx, next(chunks(x[acc], size=256))[1])
    assert np.array_equal(rows, next(chunks(Pi[:, 0], fill=4096, size=256))[1])
    assert np.array_equal(qq, pad_rows(want_edges[0][d].astype(np.int32), 1024))
    # more contractions than one piece holds: no padded inputs (the caller takes `start_step`)
    faces = FaceLists(F, n)
    faces.reserve(room)
    lists = (faces.F, faces.alive, faces.cnt, faces.off, faces.pool)
    more = glue.contract((E, ecount, deg, bad.copy(), x, cost, branch), lists, faces.end, (V3.copy(), VQ.copy()),
                         (touched, acc, apex.astype(np.int64)), counts, np.full(n, -1, np.int32),
                         (4096, len(acc) - 1, 1024))[-1]
    assert all(len(t) == 0 for t in more)


@pytest.mark.parametrize("method", ["classic", "default", "line"])
def test_step_one_is_start_step(method):
    """The one-piece device call on inputs the glue padded gives `start_step`'s rows, merges and price."""
    rng = np.random.default_rng(5)
    model = build(resolve(method))
    n, K, J = 3000, 90, 700
    rows = np.zeros((4096, 3 + model.width), np.float32)
    rows[:n] = rng.normal(size=(n, 3 + model.width)).astype(np.float32)
    verts = rng.permutation(n)
    P = np.stack([verts[:K], verts[K:2 * K]], 1).astype(np.int32)
    x = rng.normal(size=(K, 3)).astype(np.float32)
    Pn = np.sort(rng.integers(0, n, (J, 2)), axis=1).astype(np.int32)
    params = device.on_device(model.kernel_params())
    VS, merged, priced = device.start_step(model, jnp.asarray(rows), P, x, Pn, params, 256, 1024)
    ref_VS, ref_merged, ref = np.asarray(VS), merged(), priced()
    VS1, merged1, raw = device.step_one(model, jnp.asarray(rows), pad_rows(P[:, 0], 256, 4096), pad_rows(P, 256),
                                        pad_rows(x, 256), pad_rows(Pn, 1024), params, K)
    out = raw()[:, :J]
    assert np.array_equal(np.asarray(VS1), ref_VS) and np.array_equal(merged1(), ref_merged)
    assert np.array_equal(out[:3].T, ref.x) and np.array_equal(out[3], ref.cost, equal_nan=True)
    assert np.array_equal(out[4].astype(np.int8), ref.branch) and np.array_equal(out[5:], ref.parts, equal_nan=True)


RUNS = {
    "default": (lambda: shapes.bumpy_sphere(4), {"ratio": 0.02, "method": "default"}),
    "max-error": (lambda: shapes.bumpy_sphere(4), {"max_error": 0.003, "method": "classic"}),
    "two-parts": (lambda: _two_spheres(), {"ratio": 0.05, "method": "classic"}),
    "numpy-gate": (lambda: shapes.torus(n_major=30, n_minor=14),
                   {"ratio": 0.1, "scheduler": Schedule(gate=np.float64(1.5), free_cost=np.float32(1e-9))}),
    "line-boundary": (lambda: shapes.grid(30, hole=True), {"ratio": 0.05, "method": "line"}),
    # kept UVs: the seam placement of the carried prices, the wedges before the faces are relinked
    "uv-seams": (lambda: atlas_sphere(3)[0], {"ratio": 0.05, "attributes": "uv", "method": "default"}),
}


def glue_runs(mesh, kw, monkeypatch):
    """``simplify(mesh, **kw)`` on the compiled glue and with the glue in numpy (the compiled loops with the one
    device call): (that run, this one, per round implementation chosen: True where it is the one asked for)."""
    seen = []
    choose = driver.choose

    def fast_off(run, glue=True):  # the compiled loops with the one device call, the glue in numpy
        rnd = choose(run, glue=False)
        seen.append(isinstance(rnd, parallel.LoopRound) and isinstance(rnd.device, parallel.OneCall))
        return rnd

    def recording(run, glue=True):
        rnd = choose(run, glue)
        seen.append(isinstance(rnd, parallel.GlueRound))
        return rnd
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with monkeypatch.context() as m:
            m.setattr(driver, "choose", recording)
            new = qemjax.simplify(mesh, **kw)
        with monkeypatch.context() as m:
            m.setattr(driver, "choose", fast_off)
            old = qemjax.simplify(mesh, **kw)
    return new, old, seen


@pytest.mark.parametrize("case", list(RUNS))
def test_runs_with_the_compiled_glue_give_the_numpy_glues_result(case, monkeypatch):
    make, kw = RUNS[case]
    new, old, seen = glue_runs(make(), kw, monkeypatch)
    # the default's memoryless last stretch (`_schedulers.late`) is a second run, never on the glue
    late = kw.get("method", "default") == "default" and "attributes" not in kw  # (with UVs it stays summed)
    assert seen == ([True, False] if late else [True]) * 2
    _assert_same(new, old)
    assert new.stats["rounds"] > 2
    if "uv" in case:
        assert np.array_equal(new.uv, old.uv) and new.stats["rejected_by"]["seam"] > 0
