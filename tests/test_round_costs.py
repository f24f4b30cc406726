"""The parallel scheduler's per-round costs cut without changing outputs: a round's merge and device row
update in pieces sized to the mesh (`parallel.merge_size`), and kernel settings and the flip threshold
copied to the device once per run (`device.on_device`). Each must give the same bits as before."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import qemjax
from qemjax._kernels.batching import set_rows
from qemjax._schedulers import device, parallel

MODELS = [qemjax.QEM(), qemjax.QEM(placement="rank"), qemjax.QEM(memoryless=True), qemjax.ProbabilisticQEM(),
          qemjax.LineQEM()]


def _rows(model, rng, n=4096):
    """Random device rows [position, state] and 300 vertex-disjoint pairs with new positions."""
    VS = rng.normal(size=(n, 3 + model.width)).astype(np.float32)
    P = rng.permutation(n)[:600].reshape(-1, 2).astype(np.int32)
    x = rng.normal(size=(len(P), 3)).astype(np.float32)
    return VS, P, x


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__ + str(getattr(m, "placement", "")))
def test_merge_bits_do_not_depend_on_the_piece_shape(model):
    """A row merged in a 256-row piece equals the same row merged in a 4096-row piece, bit for bit (the
    scheduler now picks the piece shape from the mesh's size)."""
    VS, P, x = _rows(model, np.random.default_rng(0))
    VSd, params = jnp.asarray(VS), model.kernel_params()
    small = device.start_merge(model, VSd, P, x, params, size=parallel.SMALL_CHUNK)()
    large = device.start_merge(model, VSd, P, x, params, size=parallel.MERGE_CHUNK)()
    assert small.shape == (len(P), model.width)
    assert np.array_equal(small, large, equal_nan=True)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__ + str(getattr(m, "placement", "")))
def test_settings_on_the_device_price_as_numpy_settings(model):
    """`device.on_device` keeps each setting's dtype and shape: the same kernel, the same prices."""
    if model.uses_ring:
        pytest.skip("ring models price through the faces")
    VS, P, _ = _rows(model, np.random.default_rng(1))
    VSd, params = jnp.asarray(VS), model.kernel_params()
    dev = device.on_device(params)
    assert all(np.asarray(dev[k]).dtype == np.asarray(v).dtype and np.shape(dev[k]) == np.shape(v)
               for k, v in params.items())
    a, b = device.start_price(model, VSd, P, params)(), device.start_price(model, VSd, P, dev)()
    for u, v in zip(a, b):
        assert np.array_equal(u, v, equal_nan=True)


def test_pricing_no_pairs_calls_no_kernel(monkeypatch):
    """`device.start_price` of no pairs (a round after one that only rejected: nothing is stale) gives an
    empty price without a device call (its one piece would have priced padding alone)."""
    model = MODELS[0]
    VS, P, _ = _rows(model, np.random.default_rng(2))
    calls = []
    price = type(model).price
    monkeypatch.setattr(type(model), "price", lambda self, *a, **k: calls.append(1) or price(self, *a, **k))
    pr = device.start_price(model, jnp.asarray(VS), P[:0], model.kernel_params())()
    assert not calls
    assert pr.x.shape == (0, 3) and pr.cost.shape == (0,) and pr.branch.shape == (0,) and pr.branch.dtype == np.int8
    assert pr.parts.shape == (len(model.parts), 0)
    device.start_price(model, jnp.asarray(VS), P[:3], model.kernel_params())()
    assert calls  # (the spy sees real calls)


def test_small_settings_copies_are_kept_for_the_next_run():
    """`device.on_device` reuses its device copy of a small setting with the same value, dtype and shape (a
    run's set-up made four copies), and never mixes values whose bytes are equal under another dtype."""
    p1 = {"a": np.asarray(0.25, np.float32), "b": np.asarray(False), "c": np.asarray(0, np.int32), "s": "x"}
    p2 = {"a": np.asarray(0.25, np.float32), "b": np.asarray(0, np.int8), "c": np.asarray(0.0, np.float32),
          "s": "x"}
    d1, d2 = device.on_device(p1), device.on_device(p2)
    assert d1["a"] is d2["a"] and d1["s"] == d2["s"] == "x"
    for k in ("b", "c"):  # same bytes, other dtypes: their own copies
        assert d1[k] is not d2[k] and d1[k].dtype == p1[k].dtype and d2[k].dtype == p2[k].dtype
        assert np.array_equal(np.asarray(d2[k]), p2[k])
    big = np.arange(17.0)
    assert device.on_device({"w": big})["w"] is not device.on_device({"w": big})["w"]  # large: copied each time
    f64 = {"e": np.asarray(0.5, np.float64)}  # its device dtype follows x64 mode: a copy per mode
    plain = device.on_device(f64)["e"]
    with jax.enable_x64(True):
        wide = device.on_device(f64)["e"]
    assert plain.dtype == jnp.float32 and wide.dtype == jnp.float64


def test_merge_size_is_two_shapes_and_the_row_update_is_exact():
    assert parallel.merge_size(1) == parallel.merge_size(parallel.SMALL_MESH) == 256
    assert parallel.merge_size(parallel.SMALL_MESH + 1) == parallel.merge_size(10 ** 6) == 4096
    rng = np.random.default_rng(2)
    A = rng.normal(size=(1000, 13)).astype(np.float32)
    idx = rng.permutation(1000)[:300]
    rows = rng.normal(size=(300, 13)).astype(np.float32)
    want = A.copy()
    want[idx] = rows
    for size in (parallel.SMALL_CHUNK, parallel.MERGE_CHUNK):
        assert np.array_equal(np.asarray(set_rows(jnp.asarray(A), idx, rows, size=size)), want)


def test_flip_threshold_on_the_device_gives_the_host_thresholds_answers():
    """start_flips with the threshold as a device scalar answers as with the Python float."""
    rng = np.random.default_rng(4)
    V = rng.normal(size=(64, 13)).astype(np.float32)
    F = np.array([rng.permutation(64)[:3] for _ in range(200)], np.int32)
    N0 = rng.normal(size=(200, 3)).astype(np.float32)
    owner = np.sort(rng.integers(0, 40, 200))
    corner = rng.integers(0, 3, 200)
    x = rng.normal(size=(40, 3)).astype(np.float32)
    Vd, N0d = jnp.asarray(V), jnp.asarray(N0)
    for cos_max in (0.0, 0.3, -1.0):
        a = device.start_flips(Vd, N0d, F, np.arange(200), corner, owner, x, 40, cos_max)()
        b = device.start_flips(Vd, N0d, F, np.arange(200), corner, owner, x, 40,
                               jnp.asarray(np.float32(cos_max)))()
        assert np.array_equal(a, b) and (a.sum() > 0) == (cos_max >= 0) and a.sum() < 40


def test_coincidence_count_finds_each_coincident_face_in_any_corner_order():
    """`topo.coincidence_count` (one hash pass over all corners) counts, per pair, the faces that
    `topo.coincident_removals` drops: same-orientation twins (one dropped) and opposite twins (both)."""
    from qemjax._mesh import topology as topo

    rng = np.random.default_rng(5)
    G = np.array([rng.permutation(3000)[:3] for _ in range(400)], np.int32)
    owner = np.sort(rng.integers(0, 50, 400))
    assert not topo.coincidence_count(G, owner, 50).any()
    G[10] = G[200][[1, 2, 0]]  # the same face, rotated: one of the two goes
    G[20] = G[300][[2, 1, 0]]  # opposite orientation: both go
    want = np.bincount(owner[np.flatnonzero(topo.coincident_removals(G))], minlength=50)
    assert want.sum() == 3
    assert np.array_equal(topo.coincidence_count(G, owner, 50), want)
