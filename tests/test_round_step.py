"""A round's device work in one call (`device.start_step`: the merge, the row update and the next round's
price together) gives what the separate calls give: the same values on random rows, and whole runs
(alone and batched, small and large meshes, several cost models) bit for bit."""
from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import qemjax
from qemjax import shapes
from qemjax._costs import build, resolve
from qemjax._kernels.batching import set_rows
from qemjax._schedulers import device, parallel
from qemjax._schedulers.parallel import compiled, driver, stages
from test_attributes import atlas_sphere
from test_round_loops import _assert_same


def _unfused(monkeypatch):
    monkeypatch.setattr(driver, "fuses", lambda model: False)


def _spy(monkeypatch):
    """Record each round's device call, (contractions, stale pairs, merge piece, price shape): `start_step`,
    or `step_one` where the compiled glue padded one piece (its padding pairs are (0, 0))."""
    calls = []
    step, one = device.start_step, device.step_one

    def spy(model, VSd, P, x, Pn, params, size, price_size, **kw):
        calls.append((len(P), len(Pn), size, price_size))
        return step(model, VSd, P, x, Pn, params, size, price_size, **kw)

    def spy_one(model, VSd, rows_at, P, x, Pn, params, K, **kw):
        calls.append((K, int(np.count_nonzero(Pn[:, 0] != Pn[:, 1])), len(P), len(Pn)))
        return one(model, VSd, rows_at, P, x, Pn, params, K, **kw)
    for module in (stages, compiled):
        monkeypatch.setattr(module, "start_step", spy)
    monkeypatch.setattr(compiled, "step_one", spy_one)
    return calls


def _simplify(mesh, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return qemjax.simplify(mesh, **({"method": "classic"} | kw))


@pytest.mark.parametrize("method", ["classic", "default", "line", "probabilistic"])
@pytest.mark.parametrize("K, J", [(40, 300), (600, 2000), (256, 0)])
def test_step_gives_the_separate_calls_values(method, K, J):
    """Random rows and pairs: merge pieces of 256 (several when K > 256) and price pieces beyond the
    first 1024 (J = 2000) give the merge, row update and price of `start_merge`, `set_rows` and
    `start_price`, bit for bit."""
    rng = np.random.default_rng(K + J)
    model = build(resolve(method))
    n = 4000
    rows = np.zeros((4096, 3 + model.width), np.float32)
    V = rng.normal(size=(n, 3)).astype(np.float32)
    Fr = rng.integers(0, n, (3 * n, 3))
    Fr = Fr[(Fr[:, 0] != Fr[:, 1]) & (Fr[:, 1] != Fr[:, 2]) & (Fr[:, 0] != Fr[:, 2])]
    from qemjax._costs.base import MeshInput
    from qemjax._mesh import topology as topo
    S = model.init_state(MeshInput(V, Fr, topo.boundary_edges(Fr, n), None))
    rows[:n, :3], rows[:n, 3:] = V, S
    verts = rng.permutation(n)
    P = np.stack([verts[:K], verts[K:2 * K]], 1)  # vertex-disjoint, as a round's contractions are
    x = (0.5 * (V[P[:, 0]] + V[P[:, 1]]) + 0.01 * rng.normal(size=(K, 3))).astype(np.float32)
    Pn = np.sort(rng.integers(0, n, (J, 2)), axis=1)
    params = device.on_device(model.kernel_params())

    merged_ref = device.start_merge(model, jnp.asarray(rows), P, x, params, size=256)()
    VSref = set_rows(jnp.asarray(rows), P[:, 0], np.concatenate([x, merged_ref], 1), size=256)
    priced_ref = device.start_price(model, VSref, Pn, params)()

    VS, merged, priced = device.start_step(model, jnp.asarray(rows), P, x, Pn, params, 256, 1024)
    assert np.array_equal(merged(), merged_ref)
    assert np.array_equal(np.asarray(VS), np.asarray(VSref))
    got = priced()  # (waits once)
    for name in ("x", "cost", "branch", "parts"):
        assert np.array_equal(getattr(got, name), getattr(priced_ref, name), equal_nan=True), name
    # the same price as the kernel's columns (`raw`: what a fast run's carry reads), every piece joined
    _, _, raw = device.start_step(model, jnp.asarray(rows), P, x, Pn, params, 256, 1024, raw=True)
    out = raw()
    assert out.shape == (5 + len(model.parts), J)
    assert np.array_equal(out[:3].T, got.x) and np.array_equal(out[3], got.cost, equal_nan=True)
    assert np.array_equal(out[4].astype(np.int8), got.branch) and np.array_equal(out[5:], got.parts, equal_nan=True)


RUNS = {
    "bumpy-classic": (lambda: shapes.bumpy_sphere(4), {"ratio": 0.05}),
    "bumpy-default": (lambda: shapes.bumpy_sphere(4), {"ratio": 0.02, "method": "default"}),
    "icosphere-rank": (lambda: shapes.icosphere(4), {"target_faces": 300, "placement": "rank"}),
    "grid-line": (lambda: shapes.grid(40, hole=True), {"ratio": 0.1, "method": "line"}),
    "uv-seams": (lambda: atlas_sphere(3)[0], {"ratio": 0.1, "attributes": "uv"}),
    # above `parallel.SMALL_MESH` faces: merge pieces of 4096, prices of 4096 or 16384 in the call
    "large-bumpy": (lambda: shapes.bumpy_sphere(6), {"ratio": 0.02}),
}


@pytest.mark.parametrize("case", list(RUNS))
def test_runs_with_one_call_a_round_give_the_separate_calls_result(case, monkeypatch):
    make, kw = RUNS[case]
    mesh = make()
    with monkeypatch.context() as m:
        calls = _spy(m)
        new = _simplify(mesh, **kw)
    with monkeypatch.context() as m:
        _unfused(m)
        old = _simplify(mesh, **kw)
    _assert_same(new, old)
    if "uv" in case:
        assert np.array_equal(new.uv, old.uv)
    # every round that contracted made its one call (and started the next round's price there), up to the
    # default's memoryless last stretch (`_schedulers.late`), whose rounds price on their own
    switch = new.stats.get("memoryless_from_faces") or 0
    assert len(calls) == sum(f >= switch for f in new.stats["faces_per_round"]) >= 2
    if case == "icosphere-rank":  # a round with more contractions than one merge piece
        assert max(k for k, _, size, _ in calls) > calls[0][2]
    for _, j, _, price_size in calls:  # the smallest of the size class's shapes that holds the stale pairs
        sizes = parallel.STEP_PRICE[calls[0][2]]
        assert price_size == next((s for s in sizes if s >= j), sizes[-1])
    if case == "large-bumpy":
        assert {c[2] for c in calls} == {4096} and {c[3] for c in calls} == {4096, 16384}
        # (pairs beyond one call's piece, calls of their own: `test_step_gives_the_separate_calls_values`)


def test_a_batch_with_one_call_a_round_gives_the_separate_calls_result(monkeypatch):
    """Copies stop at their own targets: the price started for the pairs of a round where a copy stopped
    is dropped and the round prices again without it (`batched`)."""
    mesh = shapes.bumpy_sphere(4)
    configs = [{"ratio": r, "boundary_weight": w} for r in (0.02, 0.1, 0.3) for w in (1.0, 100.0)]
    with monkeypatch.context() as m:
        calls = _spy(m)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            new = qemjax.simplify_batch(mesh, configs)
    with monkeypatch.context() as m:
        _unfused(m)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            old = qemjax.simplify_batch(mesh, configs)
    assert calls
    for a, b in zip(new, old):
        _assert_same(a, b)


def test_models_that_read_more_than_the_pair_are_not_fused():
    """A ring model's price reads the faces around the pair, and a refresh changes rows between the merge
    and the price: those keep the separate calls."""
    assert device.fuses(build(resolve("classic")))
    assert not device.fuses(build(resolve("esqem")))
    assert not device.fuses(build(resolve("area")))
    assert not device.fuses(build(qemjax.QEM(memoryless=True)))
    assert not device.fuses(build(qemjax.QEM(regularize=0.1)))


@pytest.mark.parametrize("kw", [{"ratio": 0.05, "memoryless": True}, {"ratio": 0.02, "method": "default"}])
def test_a_refreshing_model_writes_its_device_rows_once_a_round(kw, monkeypatch):
    """A model that refreshes state (memoryless QEM; the default's memoryless last stretch) writes a round's
    device rows once: the refreshed rows of the kept vertices' rings, the kept vertices among them. The
    result is that of writing the kept vertices' merged rows first as well."""
    mesh = shapes.bumpy_sphere(4)
    writes = []

    def counted(A, idx, rows, size=4096):
        writes.append(len(idx))
        return set_rows(A, idx, rows, size=size)

    with monkeypatch.context() as m:
        m.setattr(stages, "set_rows", counted)
        new = _simplify(mesh, **kw)
    rounds = new.stats["faces_per_round"]
    switch = new.stats.get("memoryless_from_faces")
    refreshing = len(rounds) if switch is None else sum(f < switch for f in rounds)
    assert refreshing >= 2 and len(writes) == refreshing

    def both(self, rnd, st, a, P, xs, merged):  # the kept vertices' rows written as well, then the rings'
        run = rnd.run
        rows = np.concatenate([xs, merged()], 1)
        stages.put_rows(run.VQ, a, rows)
        run.VQd = set_rows(run.VQd, a, rows, size=run.merge_chunk)

    with monkeypatch.context() as m:
        m.setattr(stages.SeparateCalls, "finish", both)
        old = _simplify(mesh, **kw)
    _assert_same(new, old)


@pytest.mark.parametrize("kw", [{"ratio": 0.05, "memoryless": True}, {"ratio": 0.02, "method": "default"}])
def test_a_round_prices_its_stale_pairs_on_their_own_in_one_call(kw, monkeypatch):
    """A round that prices its stale pairs in a call of their own (a model that does not fuse: memoryless QEM,
    the default's memoryless last stretch) sends more than a smallest piece's worth, up to a middle piece's,
    as one piece of a fused round's price shape (`stages.one_piece`) rather than up to eight of the smallest:
    the result of those pieces."""
    from qemjax._kernels.batching import CHUNKS, piece_sizes
    mesh = shapes.bumpy_sphere(4)
    calls = []
    price = stages.start_price

    def spy(model, VSd, P, params, faces=None, pad=0, at_kept=False, size=None):
        calls.append((len(P), 1 if size else len(piece_sizes(len(P)))))
        return price(model, VSd, P, params, faces, pad, at_kept, size)

    with monkeypatch.context() as m:
        m.setattr(stages, "start_price", spy)
        new = _simplify(mesh, **kw)
    between = [pieces for k, pieces in calls if CHUNKS[0] < k <= CHUNKS[1]]
    assert between and all(p == 1 for p in between)
    with monkeypatch.context() as m:
        m.setattr(stages, "one_piece", lambda run, k: None)
        old = _simplify(mesh, **kw)
    _assert_same(new, old)
